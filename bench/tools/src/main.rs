//! `rigidsim-bench-report MANIFEST OUT_DIR`: reads the `summary.json` of every
//! run listed in MANIFEST (written by `scripts/bench_scaling.sh`) and writes
//! the tables (CSV, Markdown) and the thesis-style figures (PNG) of issue 7 §2.
//!
//! MANIFEST columns: `series,bodies,ranks,variant,rep,dir`, where series is
//! `load_profile` (the 27 spheres), `rt10` (nuts and bolts, dt = 0.01 s, 10 Hz
//! frames: the thesis's set-up), `rt60` (dt = frame = 1/60 s) or `hetero`
//! (variant `even` / `slow`, with or without `_force`), or `pour` (the
//! nuts-and-bolts pours of `scripts/bench_pour.sh`, variant = the commit), or
//! `bin` (the pile of `scenes/bin_of_parts.toml` in `scripts/bench_pour.sh`,
//! variant = the commit), or `network` (`scripts/bench_network.sh`: ranks = PCs of a lab, variant =
//! the link, `1pc` for one rank without a lab), or `many_ranks`
//! (`scripts/bench_many_ranks.sh`: the pours on 1 … 16 ranks, variant = the
//! scene's name).
//!
//! Summaries that are missing (a run that failed or was cut off by the
//! script's time limit) are listed and left out.

#[path = "../../common/plot.rs"]
mod plot;

use serde_json::Value;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

struct Run {
    series: String,
    bodies: u64,
    ranks: u32,
    variant: String,
    s: Value,
}

fn f(v: &Value, path: &[&str]) -> f64 {
    let mut x = v;
    for p in path {
        x = &x[*p];
    }
    x.as_f64().unwrap_or(f64::NAN)
}

fn median(v: &[f64]) -> f64 {
    let mut s: Vec<f64> = v.iter().copied().filter(|x| !x.is_nan()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// The thesis's load profile (SPEC 2.8, table 3.3), percent of compute.
const THESIS: [(&str, f64); 3] = [
    ("exact collision", 41.48),
    ("contact forces (Dantzig)", 37.35),
    ("building systems", 17.0),
];

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 3 {
        eprintln!("usage: rigidsim-bench-report MANIFEST OUT_DIR");
        std::process::exit(2);
    }
    let out = PathBuf::from(&args[2]);
    std::fs::create_dir_all(&out).expect("create OUT_DIR");
    let manifest = std::fs::read_to_string(&args[1]).expect("read MANIFEST");
    let mut runs = Vec::new();
    let mut missing = Vec::new();
    for line in manifest.lines().skip(1).filter(|l| !l.trim().is_empty()) {
        let c: Vec<&str> = line.split(',').collect();
        if c.len() < 6 {
            continue;
        }
        let path = Path::new(c[5]).join("summary.json");
        match std::fs::read_to_string(&path)
            .ok()
            .and_then(|t| serde_json::from_str::<Value>(&t).ok())
        {
            Some(s) => runs.push(Run {
                series: c[0].into(),
                bodies: c[1].parse().unwrap_or(0),
                ranks: c[2].parse().unwrap_or(0),
                variant: c[3].into(),
                s,
            }),
            None => missing.push(format!("{} bodies={} ranks={} {}", c[0], c[1], c[2], c[3])),
        }
    }
    for m in &missing {
        eprintln!("report: no summary for {m} (failed or cut off)");
    }
    if !runs.is_empty() && runs.iter().all(|r| r.series == "many_ranks") {
        // scripts/bench_many_ranks.sh: many_ranks.{csv,md,png} only.
        many_ranks(&runs, &out);
        for m in &missing {
            eprintln!("report: left out of many_ranks.md: {m}");
        }
        return;
    }
    if !runs.is_empty() && runs.iter().all(|r| r.series == "network") {
        // scripts/bench_network.sh: network.{csv,md,png} only; the other
        // series' files of an earlier run stay as they are.
        network(&runs, &out);
        for m in &missing {
            eprintln!("report: left out of network.md: {m}");
        }
        return;
    }
    let mut md = String::new();
    load_profile(&runs, &out, &mut md);
    scaling(&runs, &out, &mut md);
    hetero(&runs, &out, &mut md);
    real_cores(&runs, &out, &mut md);
    real_cores_pour(&runs, &out, &mut md);
    pours(&runs, &out, &mut md);
    network(&runs, &out);
    if !missing.is_empty() {
        let _ = writeln!(
            md,
            "\nRuns without a summary (failed, or cut off by the time limit): {}.",
            missing.join("; ")
        );
    }
    std::fs::write(out.join("scaling.md"), md).expect("write scaling.md");
    eprintln!(
        "report: {} runs read; results in {}",
        runs.len(),
        out.display()
    );
}

/// Exclusive seconds per stage. `stage_seconds.time_of_impact` also contains
/// the narrowphase, island and solve work done inside the rollback loop (and
/// counts the rollback integration twice), so the time of impact's own share
/// is what the wall time leaves after the exclusive stages.
fn stages(s: &Value) -> Vec<(&'static str, f64)> {
    let st = |k: &str| f(s, &["stage_seconds", k]);
    let wall = f(s, &["wall_time_s"]);
    let named = [
        ("integrate", st("integrate")),
        ("broadphase", st("broadphase")),
        ("narrowphase", st("narrowphase")),
        ("build_islands", st("build_islands")),
        ("solve_islands", st("solve_islands")),
    ];
    let sum: f64 = named.iter().map(|x| x.1).sum();
    let mut v = named.to_vec();
    v.push(("time_of_impact (own) + other", (wall - sum).max(0.0)));
    v
}

fn load_profile(runs: &[Run], out: &Path, md: &mut String) {
    let lp: Vec<&Run> = runs.iter().filter(|r| r.series == "load_profile").collect();
    if lp.is_empty() {
        return;
    }
    let mut csv = String::from("run,stage,seconds,share_percent\n");
    let mut shares: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    let mut walls = Vec::new();
    let mut sims = Vec::new();
    for (k, r) in lp.iter().enumerate() {
        let wall = f(&r.s, &["wall_time_s"]);
        walls.push(wall);
        sims.push(f(&r.s, &["sim_time_s"]));
        for (name, sec) in stages(&r.s) {
            let share = 100.0 * sec / wall;
            let _ = writeln!(csv, "{k},{name},{sec:e},{share:.3}");
            shares.entry(name).or_default().push(share);
        }
    }
    let m = |k: &str| median(shares.get(k).map_or(&[][..], |v| v.as_slice()));
    let s0 = &lp[0].s;
    let bisect = f(s0, &["counters", "toi_bisection_queries"]);
    let tests = f(s0, &["counters", "pair_tests"]);
    // The thesis's grouping: V-Clip work is the narrowphase plus the time of
    // impact's bisection (its own V-Clip queries and re-integration).
    let mapped = [
        (
            "exact collision",
            m("narrowphase") + m("time_of_impact (own) + other"),
        ),
        // (the remainder also holds the loop's bookkeeping: an upper bound)
        ("contact forces (Dantzig)", m("solve_islands")),
        ("building systems", m("build_islands")),
        ("spheres + integration", m("broadphase") + m("integrate")),
    ];
    for (name, share) in &mapped {
        let _ = writeln!(csv, "median,{name} (thesis grouping),,{share:.3}");
    }
    std::fs::write(out.join("load_profile.csv"), csv).expect("write load_profile.csv");

    let _ = writeln!(
        md,
        "## Load profile: 27 spheres, 5000 frames at 0.01 s (one rank)\n\n\
         Median of {} run(s), wall {:.2} s (real-time factor {:.2}). `time_of_impact (own) + other` is the wall \
         time left after the exclusive stages: the bisection's own V-Clip queries ({} of them, against {} \
         narrowphase pair tests), the rollback re-integration and the loop's bookkeeping.\n",
        lp.len(),
        median(&walls),
        median(&sims) / median(&walls),
        bisect,
        tests
    );
    md.push_str("| stage | share [%] |\n|---|---|\n");
    for (name, _) in stages(s0) {
        let _ = writeln!(md, "| {name} | {:.2} |", m(name));
    }
    md.push_str("\n| thesis grouping | thesis [%] | rigidsim [%] |\n|---|---|---|\n");
    for (name, share) in &mapped {
        let thesis = THESIS
            .iter()
            .find(|t| t.0 == *name)
            .map_or("small".to_string(), |t| format!("{:.2}", t.1));
        let _ = writeln!(md, "| {name} | {thesis} | {share:.2} |");
    }
    md.push('\n');

    let cats: Vec<&str> = mapped.iter().map(|m| m.0).collect();
    let thesis: Vec<f64> = cats
        .iter()
        .map(|c| THESIS.iter().find(|t| t.0 == *c).map_or(4.17, |t| t.1))
        .collect();
    let ours: Vec<f64> = mapped.iter().map(|m| m.1).collect();
    if let Err(e) = bars(
        &out.join("load_profile.png"),
        "Load profile, 27 spheres, 5000 frames: share of compute [%]",
        &cats,
        &[("thesis (2002)", &thesis), ("rigidsim, one rank", &ours)],
    ) {
        eprintln!("report: {e}");
    }
}

fn bars(path: &Path, title: &str, cats: &[&str], groups: &[(&str, &[f64])]) -> Result<(), String> {
    use plotters::prelude::*;
    let err = |e: &dyn std::fmt::Debug| format!("{}: {e:?}", path.display());
    let root = BitMapBackend::new(path, (1000, 520)).into_drawing_area();
    root.fill(&WHITE).map_err(|e| err(&e))?;
    let ymax = groups
        .iter()
        .flat_map(|g| g.1.iter().copied())
        .fold(0.0, f64::max)
        * 1.15;
    let mut chart = ChartBuilder::on(&root)
        .caption(title, ("sans-serif", 20))
        .margin(16)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(0.0..cats.len() as f64, 0.0..ymax.max(1.0))
        .map_err(|e| err(&e))?;
    let names: Vec<String> = cats.iter().map(|s| s.to_string()).collect();
    let fmt = move |x: &f64| {
        let i = (x - 0.5).round();
        if (x - 0.5 - i).abs() < 1e-6 && i >= 0.0 && (i as usize) < names.len() {
            names[i as usize].clone()
        } else {
            String::new()
        }
    };
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_labels(cats.len() * 2 + 1)
        .x_label_formatter(&fmt)
        .y_desc("share of compute [%]")
        .draw()
        .map_err(|e| err(&e))?;
    let colors = [
        RGBColor(150, 150, 150),
        RGBColor(31, 119, 180),
        RGBColor(214, 39, 40),
    ];
    let w = 0.8 / groups.len() as f64;
    for (g, (label, values)) in groups.iter().enumerate() {
        let color = colors[g % colors.len()];
        chart
            .draw_series(values.iter().enumerate().map(|(i, &v)| {
                let x0 = i as f64 + 0.1 + g as f64 * w;
                Rectangle::new([(x0, 0.0), (x0 + w * 0.95, v)], color.filled())
            }))
            .map_err(|e| err(&e))?
            .label(*label)
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 14, y + 5)], color.filled()));
        chart
            .draw_series(values.iter().enumerate().map(|(i, &v)| {
                let x0 = i as f64 + 0.1 + g as f64 * w;
                Text::new(
                    format!("{v:.1}"),
                    (x0 + 0.02, v + ymax * 0.02),
                    ("sans-serif", 13),
                )
            }))
            .map_err(|e| err(&e))?;
    }
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .position(plotters::chart::SeriesLabelPosition::UpperRight)
        .draw()
        .map_err(|e| err(&e))?;
    root.present().map_err(|e| err(&e))?;
    Ok(())
}

/// Medians over the repetitions of one (series, bodies, ranks, variant).
struct Agg {
    bodies: u64,
    ranks: u32,
    variant: String,
    runs: usize,
    wall: f64,
    worst: f64,
    sim: f64,
    interval: f64,
    bytes_per_frame: f64,
    np_share: f64,
    solve_share: f64,
    rested: usize,
    fallen: f64,
}

fn aggregate(runs: &[&Run]) -> Vec<Agg> {
    let mut groups: BTreeMap<(u32, u64, String), Vec<&Run>> = BTreeMap::new();
    for r in runs {
        groups
            .entry((r.ranks, r.bodies, r.variant.clone()))
            .or_default()
            .push(r);
    }
    groups
        .into_iter()
        .map(|((ranks, bodies, variant), rs)| {
            let col =
                |g: &dyn Fn(&Value) -> f64| median(&rs.iter().map(|r| g(&r.s)).collect::<Vec<_>>());
            Agg {
                bodies,
                ranks,
                variant,
                runs: rs.len(),
                wall: col(&|s| f(s, &["wall_time_s"])),
                worst: col(&|s| f(s, &["worst_frame_s"])),
                sim: col(&|s| f(s, &["sim_time_s"])),
                interval: col(&|s| f(s, &["frame_interval_s"])),
                bytes_per_frame: col(&|s| {
                    let c = &s["per_rank"][0];
                    let frames = (f(s, &["sim_time_s"]) / f(s, &["frame_interval_s"])).max(1.0);
                    (f(c, &["bytes_sent"]) + f(c, &["bytes_received"])) / frames
                }),
                np_share: col(&|s| {
                    let d = f(s, &["distributed", "narrowphase_distributed"]);
                    d / (d + f(s, &["distributed", "narrowphase_local"])).max(1.0)
                }),
                solve_share: col(&|s| {
                    let d = f(s, &["distributed", "solve_distributed"]);
                    d / (d + f(s, &["distributed", "solve_local"])).max(1.0)
                }),
                rested: rs.iter().filter(|r| r.s["end_reason"] == "rest").count(),
                fallen: col(&|s| f(s, &["bodies_fallen"])),
            }
        })
        .collect()
}

fn rank_label(ranks: u32, variant: &str) -> String {
    if variant.contains("render") {
        format!("{ranks} ranks (4 compute + render)")
    } else if ranks == 1 {
        "1 rank".into()
    } else {
        format!("{ranks} ranks")
    }
}

/// Largest body count N such that every measured count up to N stays within
/// the frame interval.
fn realtime_limit(aggs: &[&Agg]) -> u64 {
    let mut sorted: Vec<&&Agg> = aggs.iter().collect();
    sorted.sort_by_key(|a| a.bodies);
    let mut best = 0;
    for a in sorted {
        if a.worst <= a.interval {
            best = a.bodies;
        } else {
            break;
        }
    }
    best
}

fn scaling(runs: &[Run], out: &Path, md: &mut String) {
    let mut csv = String::from(
        "series,bodies,ranks,variant,runs,rested_runs,sim_time_s,wall_median_s,worst_frame_median_s,frame_interval_s,realtime_factor,bytes_per_frame,narrowphase_distributed_share,solve_distributed_share,bodies_fallen\n",
    );
    // Per frequency: (ranks, variant, largest real-time body count).
    type Limits = Vec<(u32, String, u64)>;
    let mut limits: Vec<(String, Limits)> = Vec::new();
    for (series, hz) in [
        ("rt10", "10 Hz, dt = 0.01 s"),
        ("rt60", "60 Hz, dt = 1/60 s"),
    ] {
        let rs: Vec<&Run> = runs.iter().filter(|r| r.series == series).collect();
        if rs.is_empty() {
            continue;
        }
        let aggs = aggregate(&rs);
        for a in &aggs {
            let _ = writeln!(
                csv,
                "{series},{},{},{},{},{},{:.3},{:e},{:e},{},{:.4},{:.0},{:.4},{:.4},{}",
                a.bodies,
                a.ranks,
                a.variant,
                a.runs,
                a.rested,
                a.sim,
                a.wall,
                a.worst,
                a.interval,
                a.sim / a.wall,
                a.bytes_per_frame,
                a.np_share,
                a.solve_share,
                a.fallen
            );
        }
        let mut keys: Vec<(u32, String)> =
            aggs.iter().map(|a| (a.ranks, a.variant.clone())).collect();
        keys.sort();
        keys.dedup();
        let by = |k: &(u32, String)| -> Vec<&Agg> {
            aggs.iter()
                .filter(|a| a.ranks == k.0 && a.variant == k.1)
                .collect()
        };
        let interval = aggs.first().map_or(0.1, |a| a.interval);
        let series_of = |y: &dyn Fn(&Agg) -> f64| -> Vec<plot::Series> {
            keys.iter()
                .map(|k| plot::Series {
                    label: rank_label(k.0, &k.1),
                    points: by(k).iter().map(|a| (a.bodies as f64, y(a))).collect(),
                    thin: false,
                })
                .collect()
        };
        let panels = vec![
            plot::Panel {
                title: "total compute time to rest (fig. 5.1)".into(),
                x_label: "bodies".into(),
                y_label: "wall time [s]".into(),
                series: series_of(&|a| a.wall),
                ..Default::default()
            },
            plot::Panel {
                title: "total compute time to rest, log-log".into(),
                x_label: "bodies".into(),
                y_label: "wall time [s]".into(),
                x_log: true,
                y_log: true,
                series: series_of(&|a| a.wall),
                ..Default::default()
            },
            plot::Panel {
                title: format!("worst frame ({hz}; figs. 5.6-5.10)"),
                x_label: "bodies".into(),
                y_label: "worst frame [s]".into(),
                x_log: true,
                y_log: true,
                series: series_of(&|a| a.worst),
                hlines: vec![(
                    interval,
                    format!("real time: frame interval {interval:.4} s"),
                )],
                ..Default::default()
            },
            plot::Panel {
                title: "real-time factor (simulated / wall)".into(),
                x_label: "bodies".into(),
                y_label: "real-time factor".into(),
                x_log: true,
                y_log: true,
                series: series_of(&|a| a.sim / a.wall),
                hlines: vec![(1.0, "real time".into())],
                ..Default::default()
            },
            plot::Panel {
                title: "share of narrowphase stages distributed".into(),
                x_label: "bodies".into(),
                y_label: "share distributed".into(),
                series: series_of(&|a| a.np_share),
                ..Default::default()
            },
            plot::Panel {
                title: "bytes per frame (rank 0 sent + received)".into(),
                x_label: "bodies".into(),
                y_label: "bytes / frame".into(),
                x_log: true,
                y_log: true,
                series: series_of(&|a| a.bytes_per_frame),
                ..Default::default()
            },
        ];
        let title = format!(
            "Nuts and bolts onto the 2 m floor ({hz}); ranks beyond 2 share 2 cores (oversubscribed)"
        );
        if let Err(e) = plot::draw(
            &out.join(format!("scaling_{series}.png")),
            &title,
            &panels,
            2,
        ) {
            eprintln!("report: {e}");
        }
        let lim: Vec<(u32, String, u64)> = keys
            .iter()
            .map(|k| (k.0, k.1.clone(), realtime_limit(&by(k))))
            .collect();
        limits.push((hz.to_string(), lim));

        let _ = writeln!(md, "## Scaling, nuts and bolts ({hz})\n");
        md.push_str("| bodies | ranks | runs | rested | simulated [s] | wall [s] | worst frame [s] | real-time factor | narrowphase distributed | solve distributed | bytes/frame |\n|---|---|---|---|---|---|---|---|---|---|---|\n");
        for k in &keys {
            for a in by(k) {
                let _ = writeln!(
                    md,
                    "| {} | {} | {} | {}/{} | {:.2} | {:.3} | {:.4} | {:.2} | {:.0} % | {:.0} % | {:.0} |",
                    a.bodies,
                    rank_label(a.ranks, &a.variant),
                    a.runs,
                    a.rested,
                    a.runs,
                    a.sim,
                    a.wall,
                    a.worst,
                    a.sim / a.wall,
                    100.0 * a.np_share,
                    100.0 * a.solve_share,
                    a.bytes_per_frame
                );
            }
        }
        md.push('\n');
    }
    std::fs::write(out.join("scaling.csv"), csv).expect("write scaling.csv");
    if limits.is_empty() {
        return;
    }
    md.push_str("## Largest body count that stays real time (worst frame within the frame interval for every count up to it)\n\n| ranks |");
    for (hz, _) in &limits {
        let _ = write!(md, " {hz} |");
    }
    md.push_str("\n|---|");
    for _ in &limits {
        md.push_str("---|");
    }
    md.push('\n');
    let keys: Vec<(u32, String)> = limits[0].1.iter().map(|l| (l.0, l.1.clone())).collect();
    for k in &keys {
        let _ = write!(md, "| {} |", rank_label(k.0, &k.1));
        for (_, lim) in &limits {
            let v = lim
                .iter()
                .find(|l| l.0 == k.0 && l.1 == k.1)
                .map_or("-".into(), |l| l.2.to_string());
            let _ = write!(md, " {v} |");
        }
        md.push('\n');
    }
    md.push('\n');
    let panel = plot::Panel {
        title: "largest real-time body count per rank count (thesis: 9, 16, -, 21)".into(),
        x_label: "ranks".into(),
        y_label: "bodies".into(),
        series: limits
            .iter()
            .map(|(hz, lim)| plot::Series {
                label: hz.clone(),
                points: lim.iter().map(|l| (l.0 as f64, l.2 as f64)).collect(),
                thin: false,
            })
            .chain(std::iter::once(plot::Series {
                label: "thesis, 10 Hz (1, 2, 4 PCs)".into(),
                points: vec![(1.0, 9.0), (2.0, 16.0), (4.0, 21.0)],
                thin: true,
            }))
            .collect(),
        ..Default::default()
    };
    if let Err(e) = plot::draw(
        &out.join("scaling_realtime_limit.png"),
        "Real time held up to",
        &[panel],
        1,
    ) {
        eprintln!("report: {e}");
    }
}

/// The runs of one real-cores series by rank count, and whether their state
/// hashes all agree; `None` when the series has no runs.
fn by_ranks<'a>(runs: &'a [Run], series: &str) -> Option<(BTreeMap<u32, Vec<&'a Run>>, bool)> {
    let rs: Vec<&Run> = runs.iter().filter(|r| r.series == series).collect();
    if rs.is_empty() {
        return None;
    }
    let hashes: std::collections::BTreeSet<&str> = rs
        .iter()
        .filter_map(|r| r.s["state_hash"].as_str())
        .collect();
    let mut by: BTreeMap<u32, Vec<&Run>> = BTreeMap::new();
    for r in rs {
        by.entry(r.ranks).or_default().push(r);
    }
    Some((by, hashes.len() == 1))
}

/// Series `cores`: `bench/scenes/eight_stacks.toml` (heavy contact solves,
/// few impact events) on 1 rank and on as many ranks as the machine has
/// cores, without rendering: what distributing gains where no rank shares a
/// core. Medians per rank count; the state hash must agree.
fn real_cores(runs: &[Run], out: &Path, md: &mut String) {
    let Some((by, hashes_agree)) = by_ranks(runs, "cores") else {
        return;
    };
    let mut csv = String::from(
        "ranks,runs,wall_median_s,worst_frame_median_s,solve_islands_median_s,solve_distributed_share\n",
    );
    md.push_str(
        "## Distribution on real cores: eight stacks of 15 boxes, `--no-sleep`, no rendering\n\n",
    );
    md.push_str("| ranks | runs | wall [s] | worst frame [ms] | solve_islands [s] | solves distributed |\n|---|---|---|---|---|---|\n");
    for (ranks, rs) in &by {
        let m = |g: &dyn Fn(&Value) -> f64| median(&rs.iter().map(|r| g(&r.s)).collect::<Vec<_>>());
        let wall = m(&|s| f(s, &["wall_time_s"]));
        let worst = m(&|s| f(s, &["worst_frame_s"]));
        let solve = m(&|s| f(s, &["stage_seconds", "solve_islands"]));
        let share = m(&|s| {
            let d = f(s, &["distributed", "solve_distributed"]);
            d / (d + f(s, &["distributed", "solve_local"])).max(1.0)
        });
        let _ = writeln!(
            csv,
            "{ranks},{},{wall:e},{worst:e},{solve:e},{share:.4}",
            rs.len()
        );
        let _ = writeln!(
            md,
            "| {ranks} | {} | {wall:.3} | {:.1} | {solve:.3} | {:.0} % |",
            rs.len(),
            worst * 1e3,
            share * 100.0
        );
    }
    let _ = writeln!(
        md,
        "\nState hashes: {} (must be one).\n",
        if hashes_agree { "all equal" } else { "DIFFER" }
    );
    std::fs::write(out.join("cores.csv"), csv).expect("write cores.csv");
}

fn hetero(runs: &[Run], out: &Path, md: &mut String) {
    let rs: Vec<&Run> = runs.iter().filter(|r| r.series == "hetero").collect();
    if rs.is_empty() {
        return;
    }
    let mut csv = String::from(
        "bodies,ranks,variant,rep_wall_s,rank,role,speed_estimate,tasks,task_share,busy_s\n",
    );
    let mut groups: BTreeMap<(u64, String), Vec<&Run>> = BTreeMap::new();
    for r in &rs {
        groups
            .entry((r.bodies, r.variant.clone()))
            .or_default()
            .push(r);
    }
    md.push_str("## Heterogeneous ranks: one worker slowed (`--slow-rank 2=3.0`), 3 ranks (coordinator + 2 workers)\n\n");
    md.push_str("| bodies | variant | runs | wall [s] | worst frame [s] | speed estimate rank 1 | speed estimate rank 2 | tasks rank 0 / 1 / 2 |\n|---|---|---|---|---|---|---|---|\n");
    let mut speed_pts: BTreeMap<String, Vec<(f64, f64)>> = BTreeMap::new();
    for ((bodies, variant), rs) in &groups {
        for r in rs {
            let total: f64 = r.s["per_rank"]
                .as_array()
                .map_or(0.0, |a| a.iter().map(|p| f(p, &["tasks"])).sum());
            for p in r.s["per_rank"].as_array().into_iter().flatten() {
                let _ = writeln!(
                    csv,
                    "{bodies},{},{variant},{:e},{},{},{:.4},{},{:.4},{:e}",
                    r.ranks,
                    f(&r.s, &["wall_time_s"]),
                    p["rank"],
                    p["role"].as_str().unwrap_or(""),
                    f(p, &["speed"]),
                    p["tasks"],
                    f(p, &["tasks"]) / total.max(1.0),
                    f(p, &["busy_s"])
                );
            }
        }
        let m = |g: &dyn Fn(&Value) -> f64| median(&rs.iter().map(|r| g(&r.s)).collect::<Vec<_>>());
        let speed = |k: usize| m(&|s| f(&s["per_rank"][k], &["speed"]));
        let tasks = |k: usize| m(&|s| f(&s["per_rank"][k], &["tasks"]));
        let _ = writeln!(
            md,
            "| {bodies} | {variant} | {} | {:.3} | {:.4} | {:.3} | {:.3} | {:.0} / {:.0} / {:.0} |",
            rs.len(),
            m(&|s| f(s, &["wall_time_s"])),
            m(&|s| f(s, &["worst_frame_s"])),
            speed(1),
            speed(2),
            tasks(0),
            tasks(1),
            tasks(2)
        );
        speed_pts
            .entry(format!("{variant}: rank 2 / rank 1 speed"))
            .or_default()
            .push((*bodies as f64, speed(2) / speed(1)));
        speed_pts
            .entry(format!("{variant}: rank 2 / rank 1 tasks"))
            .or_default()
            .push((*bodies as f64, tasks(2) / tasks(1).max(1.0)));
    }
    md.push('\n');
    std::fs::write(out.join("hetero.csv"), csv).expect("write hetero.csv");
    let panel = plot::Panel {
        title: "rank 2 slowed 3x: what the speed estimate recovers (ideal speed ratio 1/3)".into(),
        x_label: "bodies".into(),
        y_label: "ratio rank 2 / rank 1".into(),
        series: speed_pts
            .into_iter()
            .map(|(label, points)| plot::Series {
                label,
                points,
                thin: false,
            })
            .collect(),
        hlines: vec![(1.0 / 3.0, "1/3".into()), (1.0, "1".into())],
        ..Default::default()
    };
    if let Err(e) = plot::draw(&out.join("hetero.png"), "Heterogeneous ranks", &[panel], 1) {
        eprintln!("report: {e}");
    }
}

/// The pours of `scripts/bench_pour.sh`: per body count and commit (the
/// variant), medians over the reps of wall per simulated second, stage
/// shares, impact events, queries per event and groups; `pours.md`,
/// `pours.csv`, `pours.png`.
/// One point of the pours' plot: bodies, commit, wall per simulated
/// second, queries per impact event.
type PourPoint = (u64, String, f64, f64);

fn pours(runs: &[Run], out: &Path, md: &mut String) {
    let pour: Vec<&Run> = runs.iter().filter(|r| r.series == "pour").collect();
    if pour.is_empty() {
        return;
    }
    // A counter the commit did not have yet.
    let count = |x: f64| {
        if x.is_nan() {
            "—".to_string()
        } else {
            format!("{x:.0}")
        }
    };
    let mut keys: Vec<(u64, String)> = pour.iter().map(|r| (r.bodies, r.variant.clone())).collect();
    keys.sort();
    keys.dedup();
    let mut variants: Vec<String> = keys.iter().map(|k| k.1.clone()).collect();
    variants.dedup();
    variants.sort();
    variants.dedup();
    let per_s = |r: &Run, v: f64| v / f(&r.s, &["sim_time_s"]);
    // Wall seconds outside the contact solves (the growth target's measure).
    let outside =
        |r: &Run| f(&r.s, &["wall_time_s"]) - f(&r.s, &["stage_seconds", "solve_islands"]);
    let med =
        |rs: &[&Run], g: &dyn Fn(&Run) -> f64| median(&rs.iter().map(|r| g(r)).collect::<Vec<_>>());
    let stage_names = [
        "time_of_impact",
        "solve_islands",
        "narrowphase",
        "broadphase",
        "integrate",
        "build_islands",
    ];
    let mut csv = String::from(
        "bodies,commit,runs,simulated_s,ended,wall_s,wall_per_sim_s,outside_solve_per_sim_s,worst_frame_s,toi_events,queries_per_event,groups,largest_group,group_reruns,max_penetration_m,overlaps_accepted",
    );
    for n in stage_names {
        let _ = write!(csv, ",{n}_share");
    }
    csv.push('\n');
    md.push_str("## Pours (nuts and bolts onto the floor, one rank, `--no-render`)\n\n");
    md.push_str("| bodies | commit | runs | simulated [s] | ended | wall per simulated s | outside solve_islands per simulated s | worst 0.1 s frame [s] | time of impact | solve_islands | narrowphase | broadphase | impact events | queries per event | groups | largest group | group re-runs | deepest overlap [µm] | accepted |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    let mut rows: Vec<PourPoint> = Vec::new();
    for (bodies, variant) in &keys {
        let rs: Vec<&Run> = pour
            .iter()
            .copied()
            .filter(|r| r.bodies == *bodies && &r.variant == variant)
            .collect();
        let wall = med(&rs, &|r| per_s(r, f(&r.s, &["wall_time_s"])));
        let outside_per_s = med(&rs, &|r| per_s(r, outside(r)));
        let share = |k: &str| {
            med(&rs, &|r| {
                f(&r.s, &["stage_seconds", k]) / f(&r.s, &["wall_time_s"])
            })
        };
        let c = |k: &str| med(&rs, &|r| f(&r.s, &["counters", k]));
        let qpe = med(&rs, &|r| {
            f(&r.s, &["counters", "toi_bisection_queries"])
                / f(&r.s, &["counters", "toi_events"]).max(1.0)
        });
        let sim = med(&rs, &|r| f(&r.s, &["sim_time_s"]));
        let ended = rs.first().map_or(String::new(), |r| {
            r.s["end_reason"].as_str().unwrap_or("").to_string()
        });
        let worst = med(&rs, &|r| f(&r.s, &["worst_frame_s"]));
        let pen = med(&rs, &|r| f(&r.s, &["max_penetration_m"]));
        let _ = writeln!(
            md,
            "| {bodies} | {variant} | {} | {sim:.2} | {ended} | {wall:.3} | {outside_per_s:.3} | {worst:.3} | {:.0} % | {:.0} % | {:.0} % | {:.0} % | {:.0} | {qpe:.1} | {} | {} | {} | {:.3} | {:.0} |",
            rs.len(),
            100.0 * share("time_of_impact"),
            100.0 * share("solve_islands"),
            100.0 * share("narrowphase"),
            100.0 * share("broadphase"),
            c("toi_events"),
            count(c("groups")),
            count(c("largest_group")),
            count(c("group_reruns")),
            1e6 * pen,
            c("overlaps_accepted"),
        );
        let _ = write!(
            csv,
            "{bodies},{variant},{},{sim},{ended},{},{wall},{outside_per_s},{worst},{},{qpe},{},{},{},{pen},{}",
            rs.len(),
            med(&rs, &|r| f(&r.s, &["wall_time_s"])),
            c("toi_events"),
            c("groups"),
            c("largest_group"),
            c("group_reruns"),
            c("overlaps_accepted"),
        );
        for n in stage_names {
            let _ = write!(csv, ",{}", share(n));
        }
        csv.push('\n');
        rows.push((*bodies, variant.clone(), wall, qpe));
    }
    md.push('\n');
    // Growth: the largest count against `pour_window` (200 bodies over the
    // same simulated window), wall outside solve_islands, per commit.
    let window: Vec<&Run> = runs.iter().filter(|r| r.series == "pour_window").collect();
    if !window.is_empty() {
        let big = keys.iter().map(|k| k.0).max().unwrap_or(0);
        md.push_str("Growth over the same simulated window (the largest pour against 200 bodies), wall seconds outside `solve_islands`, and how much more of each kind of work the larger pour does (ratios of the counters; per pair test: the time outside `solve_islands` over `counters.pair_tests`, in µs, 200 bodies → the larger pour):\n\n| commit | 200 bodies [s] | ");
        let _ = write!(
            md,
            "{big} bodies [s] | ratio | impact events | queries | pair tests | contacts solved | outside per pair test [µs] |\n|---|---|---|---|---|---|---|---|---|\n"
        );
        for v in &variants {
            let small: Vec<&Run> = window.iter().copied().filter(|r| &r.variant == v).collect();
            let large: Vec<&Run> = pour
                .iter()
                .copied()
                .filter(|r| &r.variant == v && r.bodies == big)
                .collect();
            let counter = |rs: &[&Run], k: &str| med(rs, &|r| f(&r.s, &["counters", k]));
            let ratio = |k: &str| counter(&large, k) / counter(&small, k);
            let per_test =
                |rs: &[&Run]| 1e6 * med(rs, &|r| outside(r) / f(&r.s, &["counters", "pair_tests"]));
            let (a, b) = (med(&small, &outside), med(&large, &outside));
            let _ = writeln!(
                md,
                "| {v} | {a:.2} | {b:.2} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} → {:.1} |",
                b / a,
                ratio("toi_events"),
                ratio("toi_bisection_queries"),
                ratio("pair_tests"),
                ratio("contacts"),
                per_test(&small),
                per_test(&large),
            );
        }
        md.push('\n');
    }
    bin_table(runs, md);
    std::fs::write(out.join("pours.csv"), csv).expect("write pours.csv");
    let series_of = |pick: &dyn Fn(&PourPoint) -> f64| -> Vec<plot::Series> {
        variants
            .iter()
            .map(|v| plot::Series {
                label: v.clone(),
                points: rows
                    .iter()
                    .filter(|r| &r.1 == v)
                    .map(|r| (r.0 as f64, pick(r)))
                    .collect(),
                thin: false,
            })
            .collect()
    };
    let panels = vec![
        plot::Panel {
            title: "wall seconds per simulated second".into(),
            x_label: "bodies".into(),
            y_label: "wall / simulated".into(),
            x_log: true,
            y_log: true,
            series: series_of(&|r| r.2),
            hlines: vec![(1.0, "real time".into())],
            ..Default::default()
        },
        plot::Panel {
            title: "time-of-impact queries per impact event".into(),
            x_label: "bodies".into(),
            y_label: "queries / event".into(),
            x_log: true,
            series: series_of(&|r| r.3),
            ..Default::default()
        },
    ];
    if let Err(e) = plot::draw(
        &out.join("pours.png"),
        "Pours of nuts and bolts, one rank",
        &panels,
        2,
    ) {
        eprintln!("report: {e}");
    }
    std::fs::write(
        out.join("pours.md"),
        md.split("## Pours")
            .nth(1)
            .map(|t| format!("## Pours{t}"))
            .unwrap_or_default(),
    )
    .expect("write pours.md");
}

/// The pile in a bin (series `bin`), per commit: medians of the run's pace,
/// its error (deepest overlap, the LCP's worst violation, bodies that left
/// the bin) and how far the cluster could share it.
fn bin_table(runs: &[Run], md: &mut String) {
    let bin: Vec<&Run> = runs.iter().filter(|r| r.series == "bin").collect();
    let mut variants: Vec<&str> = bin.iter().map(|r| r.variant.as_str()).collect();
    variants.sort();
    variants.dedup();
    if variants.is_empty() {
        return;
    }
    md.push_str("The pile: `scenes/bin_of_parts.toml` (300 nuts and bolts dropped into a closed bin), one rank, `--no-render`:\n\n| commit | runs | simulated [s] | ended | wall per simulated s | worst 0.1 s frame [s] | impact events | solve_islands share | largest LCP rows | LCP worst violation [m/s] | deepest overlap [µm] | bodies fallen | largest group share | group speed-up bound, 16 ranks |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for v in variants {
        let rs: Vec<&Run> = bin.iter().copied().filter(|r| r.variant == v).collect();
        let med = |g: &dyn Fn(&Run) -> f64| median(&rs.iter().map(|r| g(r)).collect::<Vec<_>>());
        let at = |path: &[&str]| med(&|r| f(&r.s, path));
        let bound16 = med(&|r| {
            r.s["distributed"]["group_speedup_bound"]
                .as_array()
                .and_then(|a| a.iter().find(|x| x["ranks"] == 16))
                .and_then(|x| x["speedup"].as_f64())
                .unwrap_or(f64::NAN)
        });
        let ended = rs[0].s["end_reason"].as_str().unwrap_or("");
        let _ = writeln!(
            md,
            "| {v} | {} | {:.2} | {ended} | {:.2} | {:.3} | {:.0} | {:.0} % | {:.0} | {:.1e} | {:.2} | {:.0} | {:.2} | {bound16:.2} |",
            rs.len(),
            at(&["sim_time_s"]),
            med(&|r| f(&r.s, &["wall_time_s"]) / f(&r.s, &["sim_time_s"])),
            at(&["worst_frame_s"]),
            at(&["counters", "toi_events"]),
            100.0
                * med(&|r| f(&r.s, &["stage_seconds", "solve_islands"]) / f(&r.s, &["wall_time_s"])),
            at(&["counters", "solve", "largest_rows"]),
            at(&["counters", "solve", "worst_violation"]),
            1e6 * at(&["max_penetration_m"]),
            at(&["bodies_fallen"]),
            at(&["distributed", "largest_group_share"]),
        );
    }
    md.push('\n');
}

/// The 200-body pour on 1 rank and on every core (series `cores_pour`):
/// medians of wall time and worst frame, the share of steps whose group
/// steps were distributed, and the hash check; `cores_pour.csv`.
fn real_cores_pour(runs: &[Run], out: &Path, md: &mut String) {
    let Some((by, hashes_agree)) = by_ranks(runs, "cores_pour") else {
        return;
    };
    let one = by.get(&1).map(|rs| {
        median(
            &rs.iter()
                .map(|r| f(&r.s, &["wall_time_s"]))
                .collect::<Vec<_>>(),
        )
    });
    let mut csv = String::from(
        "ranks,runs,wall_median_s,wall_over_one_rank,worst_frame_median_s,groups_distributed_share\n",
    );
    md.push_str("## Distribution on real cores: the 200-body pour, no rendering\n\n");
    md.push_str("| ranks | runs | wall [s] | against 1 rank | worst frame [ms] | steps with group steps distributed |\n|---|---|---|---|---|---|\n");
    for (ranks, rs) in &by {
        let m = |g: &dyn Fn(&Value) -> f64| median(&rs.iter().map(|r| g(&r.s)).collect::<Vec<_>>());
        let wall = m(&|s| f(s, &["wall_time_s"]));
        let worst = m(&|s| f(s, &["worst_frame_s"]));
        let share = m(&|s| {
            let d = f(s, &["distributed", "groups_distributed"]);
            d / (d + f(s, &["distributed", "groups_local"])).max(1.0)
        });
        let ratio = one.map_or(f64::NAN, |o| wall / o);
        let _ = writeln!(
            csv,
            "{ranks},{},{wall:e},{ratio:.4},{worst:e},{share:.4}",
            rs.len()
        );
        let _ = writeln!(
            md,
            "| {ranks} | {} | {wall:.3} | {ratio:.2} | {:.1} | {:.0} % |",
            rs.len(),
            worst * 1e3,
            share * 100.0
        );
    }
    let _ = writeln!(
        md,
        "\nState hashes: {} (must be one).\n",
        if hashes_agree { "all equal" } else { "DIFFER" }
    );
    std::fs::write(out.join("cores_pour.csv"), csv).expect("write cores_pour.csv");
}

/// The network experiment of `scripts/bench_network.sh` (SPEC 4, thesis
/// figs. 5.3–5.5): per scene, link and number of PCs, medians over the reps
/// of wall per simulated second and worst frame, and what the network
/// carried and decided: bytes per frame through rank 0's link, the measured
/// round trip and link rate, and the share of each stage's runs that went to
/// workers. `network.csv`, `network.md`, `network.png`.
fn network(runs: &[Run], out: &Path) {
    let rs: Vec<&Run> = runs.iter().filter(|r| r.series == "network").collect();
    if rs.is_empty() {
        return;
    }
    // One PC first, then the links fastest first (`100mbit` before `10mbit`).
    let order = |link: &str| -> (u8, i64) {
        let (num, unit) = link.split_at(link.find(|c: char| !c.is_ascii_digit()).unwrap_or(0));
        let scale = match unit {
            "gbit" => 1_000_000,
            "mbit" => 1_000,
            _ => 1,
        };
        match num.parse::<i64>() {
            Ok(n) if link != "1pc" => (1, -n * scale),
            _ => (0, 0),
        }
    };
    // (bodies, link order, link, PCs).
    type Key = (u64, (u8, i64), String, u32);
    let mut groups: BTreeMap<Key, Vec<&Run>> = BTreeMap::new();
    for r in &rs {
        groups
            .entry((r.bodies, order(&r.variant), r.variant.clone(), r.ranks))
            .or_default()
            .push(r);
    }
    let share = |s: &Value, stage: &str| {
        let d = f(s, &["distributed", &format!("{stage}_distributed")]);
        let l = f(s, &["distributed", &format!("{stage}_local")]);
        if d + l > 0.0 { d / (d + l) } else { f64::NAN }
    };
    let mut csv = String::from(
        "bodies,link,pcs,runs,hashes,sim_s,wall_per_sim_s,worst_frame_s,bytes_per_frame,round_trip_s,\
         link_bytes_per_s,narrowphase_distributed,solve_distributed,groups_distributed\n",
    );
    let mut md = String::from(
        "| bodies | link | PCs | runs | simulated [s] | wall / simulated | worst frame [s] | \
         rank 0 bytes / frame | round trip [ms] | link measured [MB/s] | \
         narrowphase / solve / groups distributed |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    // Per scene and link: (PCs, value) for the figure; one PC joins every link's line.
    // Lines in the order of the table (by bodies, then link).
    type Lines = Vec<(String, Vec<(f64, f64)>)>;
    fn add(lines: &mut Lines, label: &str, point: (f64, f64)) {
        match lines.iter_mut().find(|(l, _)| l == label) {
            Some((_, points)) => points.push(point),
            None => lines.push((label.to_string(), vec![point])),
        }
    }
    let (mut wall, mut bytes, mut dist): (Lines, Lines, Lines) = Default::default();
    let links: Vec<String> = {
        let mut l: Vec<String> = rs
            .iter()
            .map(|r| r.variant.clone())
            .filter(|v| v != "1pc")
            .collect();
        l.sort();
        l.dedup();
        l
    };
    for ((bodies, _, link, pcs), g) in &groups {
        let m = |h: &dyn Fn(&Value) -> f64| median(&g.iter().map(|r| h(&r.s)).collect::<Vec<_>>());
        let mut hashes: Vec<&str> = g
            .iter()
            .filter_map(|r| r.s["state_hash"].as_str())
            .collect();
        hashes.sort_unstable();
        hashes.dedup();
        let sim = m(&|s| f(s, &["sim_time_s"]));
        let per_sim = m(&|s| f(s, &["wall_time_s"]) / f(s, &["sim_time_s"]));
        let worst = m(&|s| f(s, &["worst_frame_s"]));
        let bpf = m(&|s| {
            let c = &s["per_rank"][0];
            f(c, &["bytes_sent_per_frame"]) + f(c, &["bytes_received_per_frame"])
        });
        let rtt = m(&|s| f(s, &["distributed", "message_latency_s"]));
        let rate = m(&|s| {
            s["per_rank"]
                .as_array()
                .into_iter()
                .flatten()
                .filter_map(|p| p["link_bytes_per_s"].as_f64())
                .fold(f64::NAN, f64::min)
        });
        let (np, so, gr) = (
            m(&|s| share(s, "narrowphase")),
            m(&|s| share(s, "solve")),
            m(&|s| share(s, "groups")),
        );
        let _ = writeln!(
            csv,
            "{bodies},{link},{pcs},{},{},{sim},{per_sim:e},{worst:e},{bpf:e},{rtt:e},{rate:e},{np:.4},{so:.4},{gr:.4}",
            g.len(),
            hashes.join(" ")
        );
        let pct = |x: f64| {
            if x.is_nan() {
                "–".to_string()
            } else {
                format!("{:.0} %", 100.0 * x)
            }
        };
        let _ = writeln!(
            md,
            "| {bodies} | {} | {pcs} | {} | {sim:.2} | {per_sim:.3} | {worst:.3} | {} | {} | {} | {} / {} / {} |",
            if link == "1pc" { "–" } else { link.as_str() },
            g.len(),
            if *pcs > 1 {
                format!("{bpf:.0}")
            } else {
                "–".into()
            },
            if *pcs > 1 {
                format!("{:.2}", rtt * 1e3)
            } else {
                "–".into()
            },
            if rate.is_finite() {
                format!("{:.2}", rate / 1e6)
            } else {
                "–".into()
            },
            pct(np),
            pct(so),
            pct(gr)
        );
        let lines: Vec<String> = if link == "1pc" {
            links
                .iter()
                .map(|l| format!("{bodies} bodies, {l}"))
                .collect()
        } else {
            vec![format!("{bodies} bodies, {link}")]
        };
        for line in lines {
            add(&mut wall, &line, (*pcs as f64, per_sim));
            if *pcs > 1 {
                add(&mut bytes, &line, (*pcs as f64, bpf));
                add(&mut dist, &line, (*pcs as f64, gr));
            }
        }
    }
    std::fs::write(out.join("network.csv"), csv).expect("write network.csv");
    std::fs::write(out.join("network.md"), md).expect("write network.md");
    let panel = |title: &str, y: &str, y_log: bool, lines: Lines| plot::Panel {
        title: title.into(),
        x_label: "PCs (one rank each)".into(),
        y_label: y.into(),
        y_log,
        series: lines
            .into_iter()
            .map(|(label, mut points)| {
                points.sort_by(|a, b| a.0.total_cmp(&b.0));
                plot::Series {
                    label,
                    points,
                    thin: false,
                }
            })
            .collect(),
        ..Default::default()
    };
    let panels = [
        panel(
            "wall time per simulated second",
            "wall / simulated",
            true,
            wall,
        ),
        panel(
            "bytes per frame through rank 0's link",
            "bytes / frame",
            true,
            bytes,
        ),
        panel("group steps distributed", "share of steps", false, dist),
    ];
    if let Err(e) = plot::draw(
        &out.join("network.png"),
        "The network experiment: a lab in a box at 100 and 10 Mbit/s",
        &panels,
        3,
    ) {
        eprintln!("report: {e}");
    }
}

/// The pours on many ranks (`scripts/bench_many_ranks.sh`): per scene and
/// rank count, medians over the reps of the wall time, the speed-up over one
/// rank beside Amdahl's bound 1 / ((1 − p) + p / R) with p the one-rank
/// runs' parallel fraction (`distributed.parallel_fraction`: the share of
/// the wall time inside work that goes to other ranks when there are
/// some), the efficiency, how often the group steps went out, rank 0's
/// waiting, and the one-rank runs' bound on the group stage at R ranks
/// with every group whole (`distributed.group_speedup_bound`); every run
/// of a scene must end on one state hash.
/// `many_ranks.csv`, `many_ranks.md`, `many_ranks.png`.
/// `x` to two places, or a dash where it is not known (NaN).
fn two_places(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.2}")
    } else {
        "—".into()
    }
}

/// The `speedup` of the entry for `ranks` in a list of `{ranks, speedup}`
/// (NaN where there is none).
fn speedup_at(list: &Value, ranks: u32) -> f64 {
    list.as_array()
        .and_then(|bs| {
            bs.iter()
                .find(|b| b["ranks"].as_u64() == Some(u64::from(ranks)))
        })
        .and_then(|b| b["speedup"].as_f64())
        .unwrap_or(f64::NAN)
}

fn many_ranks(runs: &[Run], out: &Path) {
    let mut scenes: BTreeMap<(u64, String), BTreeMap<u32, Vec<&Run>>> = BTreeMap::new();
    for r in runs.iter().filter(|r| r.series == "many_ranks") {
        scenes
            .entry((r.bodies, r.variant.clone()))
            .or_default()
            .entry(r.ranks)
            .or_default()
            .push(r);
    }
    let mut csv = String::from(
        "scene,bodies,ranks,runs,sim_s,wall_median_s,speedup,amdahl_bound,efficiency,\
         groups_distributed_share,rank0_waiting_share,largest_group_share,\
         group_stage_bound,group_stage_bound_events_shared,predicted_speedup,hashes\n",
    );
    let mut md = String::new();
    let (mut measured, mut bound_lines, mut per_sim) = (Vec::new(), Vec::new(), Vec::new());
    let mut predicted_lines = Vec::new();
    let mut most_ranks = 1u32;
    for ((bodies, scene), by) in &scenes {
        let med = |rs: &[&Run], g: &dyn Fn(&Value) -> f64| {
            median(&rs.iter().map(|r| g(&r.s)).collect::<Vec<_>>())
        };
        let one = by.get(&1);
        let one_wall = one.map_or(f64::NAN, |rs| med(rs, &|s| f(s, &["wall_time_s"])));
        let p = one.map_or(f64::NAN, |rs| {
            med(rs, &|s| f(s, &["distributed", "parallel_fraction"]))
        });
        let mut hashes: Vec<&str> = by
            .values()
            .flatten()
            .filter_map(|r| r.s["state_hash"].as_str())
            .collect();
        hashes.sort_unstable();
        hashes.dedup();
        let _ = writeln!(
            md,
            "## {scene} ({bodies} bodies), {} s simulated\n\n\
             Parallel fraction on one rank p = {p:.3} (Amdahl's bound at R ranks: \
             1 / ((1 − p) + p / R)). State hashes: {} ({}).\n\n\
             | ranks | runs | wall [s] | speed-up | predicted | Amdahl's bound | efficiency | \
             steps with group steps sent out | rank 0 waiting | largest group's share | \
             group stage's bound, groups whole | the same, events shared |\n\
             |---|---|---|---|---|---|---|---|---|---|---|---|",
            med(by.values().next().map_or(&[][..], |v| &v[..]), &|s| f(
                s,
                &["sim_time_s"]
            )),
            hashes.join(", "),
            if hashes.len() == 1 {
                "one, as it must be"
            } else {
                "DIFFER"
            }
        );
        let (mut line, mut bound, mut predicted_line) = (Vec::new(), Vec::new(), Vec::new());
        for (&ranks, rs) in by {
            most_ranks = most_ranks.max(ranks);
            let wall = med(rs, &|s| f(s, &["wall_time_s"]));
            let sim = med(rs, &|s| f(s, &["sim_time_s"]));
            let speedup = one_wall / wall;
            let amdahl = 1.0 / ((1.0 - p) + p / ranks as f64);
            let sent = med(rs, &|s| {
                let d = f(s, &["distributed", "groups_distributed"]);
                d / (d + f(s, &["distributed", "groups_local"])).max(1.0)
            });
            let waiting = med(rs, &|s| {
                f(&s["per_rank"][0], &["waiting_s"]) / f(s, &["wall_time_s"])
            });
            let largest = med(rs, &|s| f(s, &["distributed", "largest_group_share"]));
            // The one-rank runs' bounds on the group stage at this many
            // ranks (`distributed.group_speedup_bound`, and with the event
            // loops shared `event_shared_bound`) and their prediction of
            // the whole run (`distributed.predicted`, with `--predict`),
            // where given.
            let at_ranks = |key: &str| {
                if ranks == 1 {
                    1.0
                } else {
                    one.map_or(f64::NAN, |rs| {
                        med(rs, &|s| speedup_at(&s["distributed"][key], ranks))
                    })
                }
            };
            let group_bound = at_ranks("group_speedup_bound");
            let shared_bound = at_ranks("event_shared_bound");
            let predicted = at_ranks("predicted");
            let run_hashes: Vec<&str> = rs
                .iter()
                .filter_map(|r| r.s["state_hash"].as_str())
                .collect();
            let _ = writeln!(
                csv,
                "{scene},{bodies},{ranks},{},{sim},{wall:e},{speedup:.4},{amdahl:.4},{:.4},{sent:.4},{waiting:.4},{largest:.4},{group_bound:.4},{shared_bound:.4},{predicted:.4},{}",
                rs.len(),
                speedup / ranks as f64,
                run_hashes.join(" ")
            );
            let _ = writeln!(
                md,
                "| {ranks} | {} | {wall:.3} | {speedup:.2} | {} | {amdahl:.2} | {:.0} % | {:.0} % | {:.0} % | {:.0} % | {} | {} |",
                rs.len(),
                two_places(predicted),
                100.0 * speedup / ranks as f64,
                100.0 * sent,
                100.0 * waiting,
                100.0 * largest,
                two_places(group_bound),
                two_places(shared_bound)
            );
            line.push((ranks as f64, speedup));
            if predicted.is_finite() {
                predicted_line.push((ranks as f64, predicted));
            }
            bound.push((ranks as f64, amdahl));
            per_sim.push((scene.clone(), (ranks as f64, wall / sim)));
        }
        md.push('\n');
        measured.push(plot::Series {
            label: format!("{scene}: measured"),
            points: line,
            thin: false,
        });
        if !predicted_line.is_empty() {
            predicted_lines.push(plot::Series {
                label: format!("{scene}: predicted by one rank"),
                points: predicted_line,
                thin: true,
            });
        }
        bound_lines.push(plot::Series {
            label: format!("{scene}: Amdahl's bound (p = {p:.2})"),
            points: bound,
            thin: true,
        });
    }
    std::fs::write(out.join("many_ranks.csv"), csv).expect("write many_ranks.csv");
    std::fs::write(out.join("many_ranks.md"), md).expect("write many_ranks.md");
    let mut speedup_series = measured;
    speedup_series.extend(predicted_lines);
    speedup_series.extend(bound_lines);
    speedup_series.push(plot::Series {
        label: "ideal (R)".into(),
        points: vec![(1.0, 1.0), (most_ranks as f64, most_ranks as f64)],
        thin: true,
    });
    let mut wall_series: Vec<plot::Series> = Vec::new();
    for (label, point) in per_sim {
        match wall_series.iter_mut().find(|s| s.label == label) {
            Some(s) => s.points.push(point),
            None => wall_series.push(plot::Series {
                label,
                points: vec![point],
                thin: false,
            }),
        }
    }
    let panels = [
        plot::Panel {
            title: "speed-up over one rank".into(),
            x_label: "ranks (one per core)".into(),
            y_label: "speed-up".into(),
            series: speedup_series,
            ..Default::default()
        },
        plot::Panel {
            title: "wall time per simulated second".into(),
            x_label: "ranks (one per core)".into(),
            y_label: "wall / simulated".into(),
            y_log: true,
            series: wall_series,
            ..Default::default()
        },
    ];
    if let Err(e) = plot::draw(
        &out.join("many_ranks.png"),
        "The pours on many ranks against Amdahl's bound",
        &panels,
        2,
    ) {
        eprintln!("report: {e}");
    }
}
