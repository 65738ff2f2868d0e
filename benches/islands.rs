//! Solve time of captured contact islands (`solver::solve_island` on each
//! task of a folder, as the simulator would solve it).
//!
//! A capture is a folder of files, one `IslandTask` each, bincode
//! (`bincode::config::standard()`, serde). `RIGIDSIM_CAPTURE_ISLANDS=DIR`
//! makes a run write every island of `CAPTURE_MIN_ROWS` rows or more it
//! solves there (see `step::capture`); `tests/data/islands/` holds a few.
//!
//! Run: `cargo bench --bench islands -- [DIR]` (default `tests/data/islands`);
//! prints a line per size class and the totals. With `ISLANDS_CSV=1`, also
//! a line per island on stderr: `csv,contacts,rows,seconds,iterative
//! solves,unconverged,sweeps,lcp solves,pivots,compliant,failed,worst
//! violation` (the island's two solves, impact and resting, together).

use std::time::Instant;

use rigidsim::contact::solver::{IslandTask, SolveStats, solve_island};

fn main() {
    let dir = std::env::args()
        .skip(1)
        .find(|a| !a.starts_with("--"))
        .unwrap_or_else(|| "tests/data/islands".into());
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{dir}: {e}"))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "bin"))
        .collect();
    files.sort();
    let tasks: Vec<IslandTask> = files
        .iter()
        .map(|p| {
            let bytes = std::fs::read(p).unwrap();
            bincode::serde::decode_from_slice(&bytes, bincode::config::standard())
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
                .0
        })
        .collect();
    // Size classes by contacts (a contact with friction is three rows).
    let classes = [
        (0, 50),
        (50, 100),
        (100, 200),
        (200, 400),
        (400, usize::MAX),
    ];
    let mut seconds = vec![0.0; classes.len()];
    let mut count = vec![0usize; classes.len()];
    let mut total = SolveStats::default();
    // Islands whose answer misses the LCP conditions by more than the
    // iterative tolerance's floor (1e-8 m/s).
    let mut missed = 0;
    let start = Instant::now();
    for task in &tasks {
        let t = Instant::now();
        let r = std::hint::black_box(solve_island(task));
        let s = t.elapsed().as_secs_f64();
        let k = classes
            .iter()
            .position(|&(lo, hi)| (lo..hi).contains(&task.contacts.len()))
            .unwrap();
        seconds[k] += s;
        count[k] += 1;
        if std::env::var_os("ISLANDS_CSV").is_some() {
            let st = &r.stats;
            eprintln!(
                "csv,{},{},{s:.6},{},{},{},{},{},{},{},{:.3e}",
                task.contacts.len(),
                st.largest_rows,
                st.iterative_solves,
                st.iterative_unconverged,
                st.iterative_sweeps,
                st.lcp_solves,
                st.pivots,
                st.compliant_solves,
                st.failed,
                st.worst_violation
            );
        }
        missed += usize::from(r.stats.worst_violation > 1e-8);
        total.add(&r.stats);
    }
    let wall = start.elapsed().as_secs_f64();
    println!("{} islands from {dir}", tasks.len());
    println!("{:>12} {:>8} {:>10}", "contacts", "islands", "seconds");
    for (k, &(lo, hi)) in classes.iter().enumerate() {
        let hi = if hi == usize::MAX {
            "".into()
        } else {
            hi.to_string()
        };
        println!(
            "{:>12} {:>8} {:>10.3}",
            format!("{lo}-{hi}"),
            count[k],
            seconds[k]
        );
    }
    println!(
        "total {wall:.3} s; rows solved {}, largest {}, pivots {}, \
         compliant {}, iterative {} ({} sweeps, {} unconverged), failed {}; \
         worst violation {:.1e} m/s, {missed} islands above 1e-8 m/s",
        total.rows,
        total.largest_rows,
        total.pivots,
        total.compliant_solves,
        total.iterative_solves,
        total.iterative_sweeps,
        total.iterative_unconverged,
        total.failed,
        total.worst_violation
    );
}
