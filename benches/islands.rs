//! Solve time of captured contact islands (`solver::solve_island` on each
//! task of a folder, as the simulator would solve it).
//!
//! A capture is a folder of files, one `IslandTask` each, bincode
//! (`bincode::config::standard()`, serde). `rigidsim --capture-islands DIR`
//! makes a run write every island of `--capture-min-rows` rows or more it
//! solves there (see `output::capture`); `tests/data/islands/` holds a few.
//!
//! Run: `cargo bench --bench islands -- [DIR]` (default `tests/data/islands`);
//! prints a line per size class, the totals, and a line per path the
//! solves took (`PATHS`: which solver decided, and whether it met the LCP's
//! conditions), with its share of the time. With `ISLANDS_CSV=1`, also
//! a line per island on stderr: `csv,contacts,rows,seconds,iterative
//! solves,unconverged,sweeps,lcp solves,pivots,compliant,failed,worst
//! violation` (the island's two solves, impact and resting, together).
//! With `ISLAND_BLOCKS=N`, every island is solved cut in N blocks
//! (`IslandTask::island_blocks`; 1: whole) whatever it was captured with.

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
    let blocks: Option<u32> = std::env::var("ISLAND_BLOCKS")
        .ok()
        .map(|v| v.parse().expect("ISLAND_BLOCKS: a whole number"));
    let tasks: Vec<IslandTask> = files
        .iter()
        .map(|p| {
            let bytes = std::fs::read(p).unwrap();
            let mut task: IslandTask =
                bincode::serde::decode_from_slice(&bytes, bincode::config::standard())
                    .unwrap_or_else(|e| panic!("{}: {e}", p.display()))
                    .0;
            task.island_blocks = blocks.unwrap_or(task.island_blocks);
            task
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
    // Per path (`PATHS`): islands, seconds, their stats.
    let mut by_path: Vec<(usize, f64, SolveStats)> = PATHS
        .iter()
        .map(|_| (0, 0.0, SolveStats::default()))
        .collect();
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
        let p = path_of(&r.stats);
        by_path[p].0 += 1;
        by_path[p].1 += s;
        by_path[p].2.add(&r.stats);
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
         worst violation {:.1e} m/s, {missed} islands above 1e-8 m/s; \
         interior point {} met, {} missed, {} Newton steps",
        total.rows,
        total.largest_rows,
        total.pivots,
        total.compliant_solves,
        total.iterative_solves,
        total.iterative_sweeps,
        total.iterative_unconverged,
        total.failed,
        total.worst_violation,
        total.interior_solves,
        total.interior_missed,
        total.interior_steps
    );
    let seconds: f64 = by_path.iter().map(|p| p.1).sum();
    println!(
        "{:<56} {:>8} {:>10} {:>6} {:>9} {:>8}",
        "what decided the island (impact and resting solve together)",
        "islands",
        "seconds",
        "share",
        "pivots",
        "sweeps"
    );
    for (name, (n, s, st)) in PATHS.iter().zip(&by_path) {
        if *n > 0 {
            println!(
                "{name:<56} {n:>8} {s:>10.3} {:>5.0}% {:>9} {:>8}",
                100.0 * s / seconds.max(1e-300),
                st.pivots,
                st.iterative_sweeps
            );
        }
    }
}

/// The paths an island's solves can take (`solve_phase`), most telling
/// first: an island is counted under the first that applies to either of
/// its two solves.
const PATHS: [&str; 9] = [
    "failed (fallback answer)",
    "interior point missed, then as below",
    "interior point (met)",
    "sequential impulses unconverged, then Dantzig",
    "sequential impulses unconverged, kept (400 rows and more)",
    "sequential impulses converged",
    "Dantzig failed, sweeps or interior point met",
    "Dantzig after its compliant retry",
    "Dantzig's method only",
];

fn path_of(st: &SolveStats) -> usize {
    if st.failed > 0 {
        0
    } else if st.interior_missed > 0 {
        1
    } else if st.interior_solves > 0 && st.lcp_solves == 0 && st.iterative_solves == 0 {
        2
    } else if st.iterative_solves > 0 && st.lcp_solves > 0 {
        3
    } else if st.iterative_unconverged > 0 {
        4
    } else if st.iterative_solves > 0 {
        5
    } else if st.iterative_rescues > 0 {
        6
    } else if st.compliant_solves > 0 {
        7
    } else {
        8
    }
}
