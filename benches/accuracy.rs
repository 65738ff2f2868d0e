//! Run time against error (issue 7 §1): every exact case, swept over the time
//! step and over rigidsim's accuracy options, single rank, release build.
//!
//! `cargo bench --bench accuracy [-- --tiny] [-- --reps N] [-- --dts 1e-3,1e-2]
//! [-- --cases projectile,bouncing_cube] [-- --out DIR]`, or `scripts/bench_accuracy.sh`.
//! Writes `accuracy.csv`, `accuracy.md` (tables) and `accuracy_<case>.png`
//! (log-log error against real-time factor, and error against step) under
//! `bench/results/<machine>/` (`$BENCH_MACHINE`, else the host name).
//! `--tiny` (or TINY=1) runs a few steps of each case into `target/bench-tiny/`,
//! so CI can check that the benchmark still runs. `--replot` redraws the PNGs
//! from an existing `accuracy.csv` without measuring.
//!
//! rigidsim has no integrator or solver-tolerance switch: translation is exact
//! for constant force, rotation is a fixed fourth-order symplectic splitting,
//! contacts are one exact (pivoting) LCP. Its accuracy knobs are the step and
//! resting systems (on by default; off with `--no-sleep`): the two
//! configurations here.

#[path = "../bench/common/harness.rs"]
mod harness;
#[path = "../bench/common/plot.rs"]
mod plot;

use harness::{Case, Engine, Point, Rigidsim};
use std::fmt::Write as _;
use std::path::PathBuf;

struct Args {
    tiny: bool,
    reps: usize,
    dts: Vec<f64>,
    cases: Option<Vec<String>>,
    out: Option<PathBuf>,
    replot: bool,
}

fn parse_args() -> Args {
    let mut a = Args {
        tiny: std::env::var("TINY").is_ok_and(|v| v == "1"),
        reps: 5,
        dts: vec![1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 1e-1],
        cases: None,
        out: None,
        replot: false,
    };
    let mut it = std::env::args().skip(1);
    let list = |s: Option<String>| -> Vec<String> {
        s.unwrap_or_default()
            .split(',')
            .filter(|x| !x.is_empty())
            .map(str::to_string)
            .collect()
    };
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--tiny" => a.tiny = true,
            "--reps" => a.reps = it.next().and_then(|s| s.parse().ok()).expect("--reps N"),
            "--dts" => {
                a.dts = list(it.next())
                    .iter()
                    .map(|s| s.parse().expect("--dts 1e-3,1e-2"))
                    .collect()
            }
            "--cases" => a.cases = Some(list(it.next())),
            "--out" => a.out = it.next().map(PathBuf::from),
            "--replot" => a.replot = true,
            // cargo bench passes --bench; ignore it and anything else.
            _ => {}
        }
    }
    a
}

fn main() {
    let args = parse_args();
    let machine = harness::machine_name();
    let out = args.out.clone().unwrap_or_else(|| {
        if args.tiny {
            PathBuf::from("target/bench-tiny").join(&machine)
        } else {
            PathBuf::from("bench/results").join(&machine)
        }
    });
    std::fs::create_dir_all(&out).expect("cannot create the results folder");
    let (dts, reps) = if args.tiny {
        (vec![1e-2], 1)
    } else {
        (args.dts.clone(), args.reps.max(1))
    };
    let mut cases: Vec<Case> = harness::cases()
        .into_iter()
        .filter(|c| {
            args.cases
                .as_ref()
                .is_none_or(|l| l.iter().any(|n| n == c.name))
        })
        .collect();
    if args.tiny {
        for c in &mut cases {
            c.duration = c.duration.min(0.05);
        }
    }
    let configs: [(&str, bool); 2] = [("rigidsim", true), ("rigidsim_no_resting", false)];

    let started = std::time::Instant::now();
    let mut points: Vec<Point> = Vec::new();
    if args.replot {
        // Redraw the figures from the CSV of an earlier run; measure nothing.
        let path = out.join("accuracy.csv");
        let text = std::fs::read_to_string(&path)
            .unwrap_or_else(|e| panic!("--replot needs {}: {e}", path.display()));
        points = harness::read_csv(&text);
        cases.retain(|c| points.iter().any(|p| p.case == c.name));
    }
    for case in cases.iter().filter(|_| !args.replot) {
        for &(config, resting) in &configs {
            for &dt in &dts {
                let p = harness::measure(case, config, dt, reps, &mut |scene| {
                    Box::new(Rigidsim::new(scene, resting)) as Box<dyn Engine>
                });
                eprintln!(
                    "accuracy: {:<18} {:<20} dt {:<7e} RTF {:>10.2} {}{}",
                    case.name,
                    config,
                    dt,
                    p.realtime_factor(),
                    p.metrics
                        .iter()
                        .map(|(n, _, v)| format!("{n} {v:.2e}"))
                        .collect::<Vec<_>>()
                        .join(", "),
                    p.failure
                        .as_ref()
                        .map_or(String::new(), |f| format!(" FAILED: {f}"))
                );
                points.push(p);
            }
        }
    }

    if !args.replot {
        let csv = format!("{}\n{}", harness::CSV_HEADER, harness::csv_rows(&points));
        std::fs::write(out.join("accuracy.csv"), csv).expect("write accuracy.csv");
        std::fs::write(out.join("accuracy.md"), tables(&cases, &points, reps))
            .expect("write accuracy.md");
        std::fs::write(
            out.join("machine.txt"),
            format!("{}\n", harness::machine_description()),
        )
        .expect("write machine.txt");
    }
    for case in &cases {
        let panels = panels(case, &points);
        let path = out.join(format!("accuracy_{}.png", case.name));
        if let Err(e) = plot::draw(&path, case.title, &panels, 2) {
            eprintln!("accuracy: plot failed: {e}");
        }
    }
    // One overview: each case's first error against the real-time factor.
    let overview: Vec<plot::Panel> = cases
        .iter()
        .map(|c| {
            let mut p = panels(c, &points).swap_remove(0);
            p.title = c.title.to_string();
            p
        })
        .collect();
    if let Err(e) = plot::draw(
        &out.join("accuracy_overview.png"),
        "rigidsim: error against real-time factor (one point per step size)",
        &overview,
        3,
    ) {
        eprintln!("accuracy: plot failed: {e}");
    }
    eprintln!(
        "accuracy: {} points in {:.1} s; results in {}",
        points.len(),
        started.elapsed().as_secs_f64(),
        out.display()
    );
}

/// Per metric: error against real-time factor, and error against step.
fn panels(case: &Case, points: &[Point]) -> Vec<plot::Panel> {
    let configs: Vec<String> = {
        let mut c: Vec<String> = points
            .iter()
            .filter(|p| p.case == case.name)
            .map(|p| p.config.clone())
            .collect();
        c.dedup();
        c
    };
    let mut out = Vec::new();
    for &(metric, unit) in case.metrics {
        let series = |x_of: &dyn Fn(&Point) -> f64| -> Vec<plot::Series> {
            configs
                .iter()
                .map(|c| plot::Series {
                    label: c.clone(),
                    points: points
                        .iter()
                        .filter(|p| p.case == case.name && &p.config == c)
                        .map(|p| (x_of(p), harness::floor_zero(p.metric(metric))))
                        .collect(),
                    thin: false,
                })
                .collect()
        };
        out.push(plot::Panel {
            title: format!("{metric} against speed"),
            x_label: "real-time factor (simulated s / wall s)".into(),
            y_label: format!("{metric} [{unit}]"),
            x_log: true,
            y_log: true,
            series: series(&|p| p.realtime_factor()),
            vlines: vec![(1.0, "real time".into())],
            hlines: vec![],
        });
        out.push(plot::Panel {
            title: format!("{metric} against step"),
            x_label: "time step dt [s]".into(),
            y_label: format!("{metric} [{unit}]"),
            x_log: true,
            y_log: true,
            series: series(&|p| p.dt),
            vlines: vec![],
            hlines: vec![],
        });
    }
    out
}

fn tables(cases: &[Case], points: &[Point], reps: usize) -> String {
    let mut s = format!(
        "<!-- written by `cargo bench --bench accuracy`; {} -->\n\
         Real-time factor = simulated time / median wall time of {reps} timed runs after a \
         probe run (stepping only, single rank). Errors from the probe run; 0 is shown as 0.\n\n",
        harness::machine_description()
    );
    for case in cases {
        let _ = writeln!(s, "### {} — {}\n", case.name, case.title);
        let mut head = String::from(
            "| config | dt [s] | steps | wall [s] | real-time factor | worst step [ms] |",
        );
        let mut rule = String::from("|---|---|---|---|---|---|");
        for (m, u) in case.metrics {
            let _ = write!(head, " {m} [{u}] |");
            rule.push_str("---|");
        }
        let _ = writeln!(s, "{head}\n{rule}");
        for p in points.iter().filter(|p| p.case == case.name) {
            let _ = write!(
                s,
                "| {} | {:e} | {} | {:.4} | {:.3} | {:.3} |",
                p.config,
                p.dt,
                p.steps,
                p.wall(),
                p.realtime_factor(),
                1e3 * harness::median(&p.worst_steps)
            );
            for (_, _, v) in &p.metrics {
                let _ = write!(s, " {} |", harness::fmt_err(*v));
            }
            if let Some(f) = &p.failure {
                let _ = write!(s, " FAILED: {f}");
            }
            s.push('\n');
        }
        s.push('\n');
    }
    s
}
