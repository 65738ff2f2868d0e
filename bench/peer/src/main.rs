//! `yardstick`: one measure for every engine (issue 22 §6).
//!
//! Every engine, rigidsim included, runs as its own program on the bodies
//! that `rigidsim export` writes, and writes its run as rigidsim's
//! `trajectory.csv` plus a record of its timed runs. This tool reads those
//! files and nothing else of the engine: the exact cases' errors come from
//! `bench/common/harness.rs` (the answers of `tests/physics_exact.rs`), and
//! overlaps from one oracle, parry3d-f64's GJK/EPA on the exported parts. So
//! no engine is measured by its own code.
//!
//! Subcommands (see `scripts/bench_peer.sh`, which drives them):
//! - `yardstick scenes DIR [--tiny] [--dts 1e-3,1e-2]`: writes the exact
//!   cases as rigidsim scenes, `DIR/<case>@<dt>.toml`, and prints one line
//!   per scene: `case dt duration path`.
//! - `yardstick time SCENE.toml --duration S --record JSON [--frame S]
//!   [--reps N]`: rigidsim's timed runs on one rank, in process and timed
//!   like every other engine's (the step call only).
//! - `yardstick measure --engine NAME --bodies FILE --trajectory CSV
//!   --record JSON (--case NAME --dt S | --pour N) --out FILE.jsonl`:
//!   measures one run and appends one JSON line.
//! - `yardstick report FILE.jsonl --out DIR [--commit C] [--command TEXT]`:
//!   `peers.csv`, `peers.md` (tables and ratios to rigidsim) and the
//!   work-precision plots `peers_<case>.png`.

#[path = "../../common/harness.rs"]
mod harness;
#[path = "../../common/plot.rs"]
mod plot;

use harness::{Oracle, Probe, Snap};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::{Value, json};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::PathBuf;

/// A body rests, as a trajectory is read, while its speed is below 1 cm/s
/// and its rotation below 0.1 rad/s (2 mm/s at the rim of a 4 cm nut). The
/// run's time to rest is the first sample from which every later sample has
/// every dynamic body that has not fallen at rest.
const REST_SPEED: f64 = 0.01;
const REST_SPIN: f64 = 0.1;

fn fail(msg: &str) -> ! {
    eprintln!("yardstick: {msg}");
    std::process::exit(2)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.first().map(String::as_str) {
        Some("scenes") => scenes(&args[1..]),
        Some("time") => time(&args[1..]),
        Some("measure") => measure(&args[1..]),
        Some("report") => report(&args[1..]),
        _ => fail("usage: yardstick scenes|measure|report ... (see bench/peer/src/main.rs)"),
    }
}

/// `--name value` pairs and bare flags.
fn options(args: &[String]) -> (Vec<String>, BTreeMap<String, String>) {
    let (mut free, mut opts) = (Vec::new(), BTreeMap::new());
    let mut i = 0;
    while i < args.len() {
        if let Some(name) = args[i].strip_prefix("--") {
            if name == "tiny" {
                opts.insert(name.to_string(), String::new());
            } else {
                let v = args
                    .get(i + 1)
                    .unwrap_or_else(|| fail(&format!("--{name} needs a value")));
                opts.insert(name.to_string(), v.clone());
                i += 1;
            }
        } else {
            free.push(args[i].clone());
        }
        i += 1;
    }
    (free, opts)
}

fn scenes(args: &[String]) {
    let (free, opts) = options(args);
    let dir = PathBuf::from(free.first().unwrap_or_else(|| fail("scenes DIR")));
    std::fs::create_dir_all(&dir).unwrap_or_else(|e| fail(&format!("{}: {e}", dir.display())));
    let tiny = opts.contains_key("tiny");
    let dts: Vec<f64> = opts
        .get("dts")
        .map(|s| {
            s.split(',')
                .map(|x| x.parse().unwrap_or_else(|_| fail("--dts 1e-3,1e-2")))
                .collect()
        })
        .unwrap_or_else(|| vec![1e-2]);
    for mut case in harness::cases() {
        if tiny {
            case.duration = case.duration.min(0.05);
        }
        for &dt in &dts {
            let path = dir.join(format!("{}@{dt:e}.toml", case.name));
            std::fs::write(&path, case.toml(dt)).unwrap_or_else(|e| fail(&format!("{e}")));
            println!("{} {dt:e} {} {}", case.name, case.duration, path.display());
        }
    }
}

/// rigidsim's timed runs on one rank, in process like every other engine's
/// (the `step` call only, no trajectory or summary writing): the record
/// `measure` reads. Its trajectory comes from the CLI (`rigidsim SCENE`).
fn time(args: &[String]) {
    let (free, o) = options(args);
    let path = free
        .first()
        .unwrap_or_else(|| fail("time SCENE.toml --duration S --record JSON"));
    let get = |k: &str| {
        o.get(k)
            .cloned()
            .unwrap_or_else(|| fail(&format!("time needs --{k}")))
    };
    let num = |k: &str, d: f64| {
        o.get(k).map_or(d, |v| {
            v.parse().unwrap_or_else(|_| fail(&format!("--{k} S")))
        })
    };
    let duration = num("duration", f64::NAN);
    let (frame, reps) = (num("frame", 0.1), num("reps", 1.0) as usize);
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| fail(&format!("{path}: {e}")));
    let dir = std::path::Path::new(path)
        .parent()
        .unwrap_or(std::path::Path::new("."));
    let mut scene = rigidsim::scene::from_str(&text, std::path::Path::new(path), dir)
        .unwrap_or_else(|e| fail(&e.to_string()));
    scene.settings.render = None;
    let dt = scene.settings.dt;
    let steps = harness::steps_for(duration, dt);
    let frame_steps = ((frame / dt).round() as u64).max(1);
    let (mut walls, mut worsts) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let mut e = harness::Rigidsim::new(scene.clone(), true);
        let (mut total, mut in_frame, mut worst) = (0.0f64, 0.0f64, 0.0f64);
        for k in 1..=steps {
            let clock = std::time::Instant::now();
            harness::Engine::step(&mut e).unwrap_or_else(|err| fail(&format!("{path}: {err}")));
            let s = clock.elapsed().as_secs_f64();
            total += s;
            in_frame += s;
            if k % frame_steps == 0 || k == steps {
                worst = worst.max(in_frame);
                in_frame = 0.0;
            }
        }
        walls.push(total);
        worsts.push(worst);
    }
    let rec = json!({
        "engine": "rigidsim", "version": "rigidsim (this checkout)", "steps": steps, "dt": dt,
        "sim_time_s": steps as f64 * dt, "walls_s": walls, "worst_frames_s": worsts,
        "frame_interval_s": frame, "threads": 1,
        "mapping": { "rule": "the scene's own (restitution_rule, friction_rule)" },
    });
    let out = get("record");
    std::fs::write(&out, format!("{rec}\n")).unwrap_or_else(|e| fail(&format!("{out}: {e}")));
}

fn read_json(path: &str) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| fail(&format!("{path}: {e}")));
    serde_json::from_str(&text).unwrap_or_else(|e| fail(&format!("{path}: {e}")))
}

fn f3(v: &Value) -> [f64; 3] {
    let a = v.as_array().unwrap_or_else(|| fail("expected [x, y, z]"));
    [0, 1, 2].map(|k| a[k].as_f64().unwrap_or_else(|| fail("expected a number")))
}

/// The oracle over the exported parts, and per body whether it is dynamic.
fn oracle_of(export: &Value) -> (Oracle, Vec<bool>, f64) {
    let objects: Vec<Vec<Vec<[f64; 3]>>> = export["objects"]
        .as_array()
        .unwrap_or_else(|| fail("bodies file: no objects"))
        .iter()
        .map(|o| {
            o["parts"]
                .as_array()
                .unwrap_or_else(|| fail("bodies file: an object without parts"))
                .iter()
                .map(|p| p["vertices"].as_array().unwrap().iter().map(f3).collect())
                .collect()
        })
        .collect();
    let bodies = export["bodies"]
        .as_array()
        .unwrap_or_else(|| fail("bodies file: no bodies"));
    let object_of = bodies
        .iter()
        .map(|b| b["object"].as_u64().unwrap() as usize)
        .collect();
    let dynamic: Vec<bool> = bodies.iter().map(|b| b["kind"] == "dynamic").collect();
    let fall_z = export["world"]["fall_z"]
        .as_f64()
        .unwrap_or(f64::NEG_INFINITY);
    let oracle = Oracle::from_parts(&objects, object_of, dynamic.clone(), fall_z)
        .unwrap_or_else(|e| fail(&e));
    (oracle, dynamic, fall_z)
}

/// A trajectory.csv: (time, every body's state) per sample, in file order.
fn read_trajectory(path: &str, bodies: usize) -> Vec<(f64, Vec<Snap>)> {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| fail(&format!("{path}: {e}")));
    let mut lines = text.lines();
    if lines.next() != Some("time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz") {
        fail(&format!("{path}: not rigidsim's trajectory.csv header"));
    }
    let mut out: Vec<(f64, Vec<Snap>)> = Vec::new();
    for (n, line) in lines.enumerate() {
        let c: Vec<f64> = line
            .split(',')
            .map(|x| {
                x.parse()
                    .unwrap_or_else(|_| fail(&format!("{path}:{}: bad number {x}", n + 2)))
            })
            .collect();
        if c.len() != 15 {
            fail(&format!("{path}:{}: {} columns, not 15", n + 2, c.len()));
        }
        let snap = Snap {
            position: Vector3::new(c[2], c[3], c[4]),
            orientation: UnitQuaternion::new_normalize(Quaternion::new(c[5], c[6], c[7], c[8])),
            velocity: Vector3::new(c[9], c[10], c[11]),
            angular_velocity: Vector3::new(c[12], c[13], c[14]),
        };
        let body = c[1] as usize;
        if body == 0 {
            // A run's last sample may repeat the time of the one before
            // (the end row after a regular one): keep the last.
            if out.last().is_some_and(|l| l.0 == c[0]) {
                out.pop();
            }
            out.push((c[0], Vec::with_capacity(bodies)));
        }
        let last = out
            .last_mut()
            .unwrap_or_else(|| fail(&format!("{path}: rows do not start at body 0")));
        if last.1.len() != body || last.0 != c[0] {
            fail(&format!("{path}:{}: rows out of order", n + 2));
        }
        last.1.push(snap);
    }
    if out.iter().any(|s| s.1.len() != bodies) {
        fail(&format!(
            "{path}: a sample lacks bodies ({bodies} in the bodies file)"
        ));
    }
    out
}

fn median(v: &[f64]) -> f64 {
    harness::median(v)
}

fn nums(v: &Value) -> Vec<f64> {
    v.as_array()
        .map(|a| a.iter().filter_map(Value::as_f64).collect())
        .unwrap_or_default()
}

fn num_or_null(x: f64) -> Value {
    if x.is_finite() { json!(x) } else { Value::Null }
}

fn measure(args: &[String]) {
    let (_, o) = options(args);
    let get = |k: &str| {
        o.get(k)
            .cloned()
            .unwrap_or_else(|| fail(&format!("measure needs --{k}")))
    };
    let (engine, out) = (get("engine"), get("out"));
    let export = read_json(&get("bodies"));
    let record = read_json(&get("record"));
    let (oracle, dynamic, fall_z) = oracle_of(&export);
    let samples = read_trajectory(&get("trajectory"), dynamic.len());
    let walls = nums(&record["walls_s"]);
    let sim_time = record["sim_time_s"].as_f64().unwrap_or(f64::NAN);
    let wall = median(&walls);
    let mut line = json!({
        "engine": engine,
        "version": record["version"],
        "threads": record["threads"],
        "steps": record["steps"],
        "sim_time_s": sim_time,
        "walls_s": walls,
        "wall_s": num_or_null(wall),
        "realtime_factor": num_or_null(sim_time / wall),
        "worst_frame_s": num_or_null(median(&nums(&record["worst_frames_s"]))),
        "frame_interval_s": record["frame_interval_s"],
        "mapping": record["mapping"],
    });
    if let Some(name) = o.get("case") {
        let dt: f64 = get("dt").parse().unwrap_or_else(|_| fail("--dt S"));
        let case = harness::cases()
            .into_iter()
            .find(|c| c.name == name)
            .unwrap_or_else(|| fail(&format!("no case {name}")));
        let scene = case.scene(dt);
        if scene.bodies.len() != dynamic.len() {
            fail("the bodies file is not this case's scene");
        }
        if samples.len() as u64 != record["steps"].as_u64().unwrap_or(0) + 1 {
            fail(&format!(
                "{engine} {name}: {} samples for {} steps (a case needs every step)",
                samples.len(),
                record["steps"]
            ));
        }
        let mut probe = Probe::with_oracle(
            &case,
            &scene,
            &samples[0].1,
            case.has_contacts().then_some(oracle),
        );
        for (t, snaps) in &samples[1..] {
            probe.observe(*t, snaps);
        }
        let metrics: serde_json::Map<String, Value> = case
            .metrics
            .iter()
            .zip(probe.finish())
            .map(|(&(m, _), v)| (m.to_string(), num_or_null(v)))
            .collect();
        line["kind"] = json!("case");
        line["case"] = json!(name);
        line["dt"] = json!(dt);
        line["metrics"] = Value::Object(metrics);
    } else {
        let count = get("pour");
        let mut deepest: f64 = 0.0;
        let mut rest_from: Option<f64> = None;
        for (t, snaps) in &samples {
            deepest = deepest.max(oracle.deepest(snaps));
            let resting = snaps.iter().zip(&dynamic).all(|(s, &d)| {
                !d || s.position.z < fall_z
                    || (s.velocity.norm() < REST_SPEED && s.angular_velocity.norm() < REST_SPIN)
            });
            match (resting, rest_from) {
                (true, None) => rest_from = Some(*t),
                (false, _) => rest_from = None,
                _ => {}
            }
        }
        let last = &samples.last().unwrap_or_else(|| fail("empty trajectory")).1;
        let fallen = last
            .iter()
            .zip(&dynamic)
            .filter(|(s, d)| **d && s.position.z < fall_z)
            .count();
        line["kind"] = json!("pour");
        line["case"] = json!(format!("pour{count}"));
        line["dt"] = export["world"]["dt"].clone();
        line["bodies"] = json!(dynamic.iter().filter(|d| **d).count());
        line["deepest_overlap_m"] = json!(deepest);
        line["rest_time_s"] = rest_from.map_or(Value::Null, |t| json!(t));
        line["fallen"] = json!(fallen);
        line["samples"] = json!(samples.len());
    }
    let mut f = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&out)
        .unwrap_or_else(|e| fail(&format!("{out}: {e}")));
    writeln!(f, "{line}").unwrap_or_else(|e| fail(&format!("{out}: {e}")));
    eprintln!("yardstick: {}", summary_line(&line));
}

fn summary_line(l: &Value) -> String {
    let mut s = format!(
        "{:<14} {:<22} RTF {:>9.1}",
        l["case"].as_str().unwrap_or(""),
        l["engine"].as_str().unwrap_or(""),
        l["realtime_factor"].as_f64().unwrap_or(f64::NAN)
    );
    if let Some(m) = l["metrics"].as_object() {
        for (k, v) in m {
            let _ = write!(s, " {k} {}", fmt(v.as_f64().unwrap_or(f64::NAN)));
        }
    } else {
        let _ = write!(
            s,
            " wall {:.3} s, overlap {} m, rest {}",
            l["wall_s"].as_f64().unwrap_or(f64::NAN),
            fmt(l["deepest_overlap_m"].as_f64().unwrap_or(f64::NAN)),
            l["rest_time_s"]
                .as_f64()
                .map_or("never".into(), |t| format!("{t:.2} s"))
        );
    }
    s
}

fn fmt(v: f64) -> String {
    harness::fmt_err(v)
}

/// Engines in the order the tables list them; the first is the reference.
const ENGINES: [&str; 9] = [
    "rigidsim",
    "rigidsim_np2",
    "rapier_default",
    "rapier_tuned",
    "rapier_tuned_parallel",
    "bullet_dantzig",
    "bullet_default",
    "mujoco_default",
    "mujoco_hard",
];

fn engine_rank(e: &str) -> usize {
    ENGINES
        .iter()
        .position(|x| *x == e)
        .unwrap_or(ENGINES.len())
}

/// The reference an engine's ratios are taken against: rigidsim on as many
/// processors as the engine uses (2 ranks against 2 threads).
fn reference_of(l: &Value) -> &'static str {
    if l["threads"].as_u64().unwrap_or(1) > 1 {
        "rigidsim_np2"
    } else {
        "rigidsim"
    }
}

fn ratio(a: f64, b: f64) -> String {
    if !a.is_finite() || !b.is_finite() {
        "n/a".into()
    } else if b == 0.0 {
        if a == 0.0 {
            "both 0".into()
        } else {
            "ref. exact".into()
        }
    } else if a / b < 0.01 || a / b > 1000.0 {
        format!("{:.1e}", a / b)
    } else {
        format!("{:.3}", a / b)
    }
}

/// What a MuJoCo record says of divergence (`bench/peer_py/peer.py`).
fn divergence(l: &Value) -> String {
    let m = &l["mapping"];
    match (
        m["diverged_with_mapped_restitution_at_s"].as_f64(),
        m["diverged_again_at_s"].as_f64(),
    ) {
        (Some(a), Some(b)) => format!(
            "diverged at {a:.2} s with the mapped restitution, and at {b:.2} s with damping ratio 1 (MuJoCo then resets the state)"
        ),
        (Some(a), None) => format!(
            "diverged at {a:.2} s with the mapped restitution; run with damping ratio 1 (no rebound)"
        ),
        _ => String::new(),
    }
}

fn report(args: &[String]) {
    let (free, o) = options(args);
    let input = free
        .first()
        .unwrap_or_else(|| fail("report FILE.jsonl --out DIR"));
    let out = PathBuf::from(
        o.get("out")
            .cloned()
            .unwrap_or_else(|| fail("report needs --out DIR")),
    );
    std::fs::create_dir_all(&out).unwrap_or_else(|e| fail(&format!("{}: {e}", out.display())));
    let text = std::fs::read_to_string(input).unwrap_or_else(|e| fail(&format!("{input}: {e}")));
    let mut lines: Vec<Value> = text
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    lines.sort_by(|a, b| {
        let key = |l: &Value| {
            (
                l["bodies"].as_u64().unwrap_or(0),
                l["case"].as_str().unwrap_or("").to_string(),
                engine_rank(l["engine"].as_str().unwrap_or("")),
            )
        };
        key(a).cmp(&key(b)).then(
            a["dt"]
                .as_f64()
                .unwrap_or(0.0)
                .total_cmp(&b["dt"].as_f64().unwrap_or(0.0)),
        )
    });
    let cases = harness::cases();
    let f = |l: &Value, k: &str| l[k].as_f64().unwrap_or(f64::NAN);
    let find = |case: &str, engine: &str, dt: f64| {
        lines
            .iter()
            .find(|l| l["case"] == case && l["engine"] == engine && f(l, "dt") == dt)
    };

    // Long CSV: one row per run and measure.
    let mut csv = String::from(
        "kind,case,engine,version,threads,dt_s,steps,sim_time_s,wall_s,realtime_factor,worst_frame_s,frame_interval_s,measure,value\n",
    );
    for l in &lines {
        let mut measures: Vec<(String, f64)> = Vec::new();
        if let Some(m) = l["metrics"].as_object() {
            measures.extend(
                m.iter()
                    .map(|(k, v)| (k.clone(), v.as_f64().unwrap_or(f64::NAN))),
            );
        } else {
            for k in ["deepest_overlap_m", "rest_time_s", "fallen"] {
                measures.push((k.into(), f(l, k)));
            }
        }
        for (m, v) in measures {
            let _ = writeln!(
                csv,
                "{},{},{},{},{},{},{},{},{:e},{:e},{:e},{},{m},{:e}",
                l["kind"].as_str().unwrap_or(""),
                l["case"].as_str().unwrap_or(""),
                l["engine"].as_str().unwrap_or(""),
                l["version"].as_str().unwrap_or(""),
                l["threads"],
                f(l, "dt"),
                l["steps"],
                f(l, "sim_time_s"),
                f(l, "wall_s"),
                f(l, "realtime_factor"),
                f(l, "worst_frame_s"),
                f(l, "frame_interval_s"),
                v
            );
        }
    }
    std::fs::write(out.join("peers.csv"), csv).unwrap_or_else(|e| fail(&format!("peers.csv: {e}")));

    // Tables.
    let mut md = format!(
        "<!-- written by `yardstick report` (scripts/bench_peer.sh) -->\n\
         Machine: {}. Commit: {}. Command: `{}`.\n\n\
         Every engine ran as its own program on `rigidsim export`'s bodies and wrote \
         rigidsim's trajectory.csv; every error and overlap below is `yardstick`'s, from \
         those files (exact answers of bench/common/harness.rs; overlaps by parry3d-f64 on \
         the exported parts). Wall: the engine's step calls only, median of the timed runs. \
         Ratios: engine / rigidsim (on 2 ranks for the 2-thread engine): time ratio below 1 \
         means the engine is faster, error ratio below 1 more accurate.\n\n",
        harness::machine_description(),
        o.get("commit").map_or("unknown", String::as_str),
        o.get("command")
            .map_or("scripts/bench_peer.sh", String::as_str)
    );
    let mut dts: Vec<f64> = lines
        .iter()
        .filter(|l| l["kind"] == "case")
        .map(|l| f(l, "dt"))
        .collect();
    dts.sort_by(f64::total_cmp);
    dts.dedup();
    for &dt in &dts {
        let _ = writeln!(md, "### Exact cases, dt = {dt} s\n");
        md.push_str("| case | engine | RTF | time ratio | measure | error | error ratio | note |\n|---|---|---|---|---|---|---|---|\n");
        for case in &cases {
            let Some(reference) = find(case.name, "rigidsim", dt) else {
                continue;
            };
            for engine in ENGINES {
                let Some(l) = find(case.name, engine, dt) else {
                    continue;
                };
                for (k, &(m, unit)) in case.metrics.iter().enumerate() {
                    let (e, r) = (f(&l["metrics"], m), f(&reference["metrics"], m));
                    let _ = writeln!(
                        md,
                        "| {} | {engine} | {} | {} | {m} [{unit}] | {} | {} | {} |",
                        if k == 0 { case.name } else { "" },
                        if k == 0 {
                            format!("{:.1}", f(l, "realtime_factor"))
                        } else {
                            String::new()
                        },
                        if k == 0 {
                            ratio(f(l, "wall_s"), f(reference, "wall_s"))
                        } else {
                            String::new()
                        },
                        fmt(e),
                        if engine == "rigidsim" {
                            "—".into()
                        } else {
                            ratio(e, r)
                        },
                        if k == 0 { divergence(l) } else { String::new() }
                    );
                }
            }
        }
        md.push('\n');
    }
    let pours: Vec<&Value> = lines.iter().filter(|l| l["kind"] == "pour").collect();
    if !pours.is_empty() {
        md.push_str("### Pours of nuts and bolts onto the 2 m floor\n\n");
        md.push_str("| bodies | engine | threads | simulated [s] | wall [s] | RTF | worst 0.1 s frame [s] | deepest overlap [m] | time to rest [s] | fallen | wall ratio | overlap ratio | note |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
        for l in &pours {
            let reference = pours
                .iter()
                .find(|r| r["case"] == l["case"] && r["engine"] == reference_of(l));
            let (wr, or) = reference.map_or(("n/a".into(), "n/a".into()), |r| {
                let same_span = f(r, "sim_time_s") == f(l, "sim_time_s");
                let (wa, wb) = if same_span {
                    (f(l, "wall_s"), f(r, "wall_s"))
                } else {
                    // A capped run: wall per simulated second.
                    (
                        f(l, "wall_s") / f(l, "sim_time_s"),
                        f(r, "wall_s") / f(r, "sim_time_s"),
                    )
                };
                (
                    ratio(wa, wb),
                    ratio(f(l, "deepest_overlap_m"), f(r, "deepest_overlap_m")),
                )
            });
            let _ = writeln!(
                md,
                "| {} | {} | {} | {:.2} | {:.3} | {:.2} | {:.4} | {} | {} | {} | {wr} | {or} | {} |",
                l["bodies"],
                l["engine"].as_str().unwrap_or(""),
                l["threads"],
                f(l, "sim_time_s"),
                f(l, "wall_s"),
                f(l, "realtime_factor"),
                f(l, "worst_frame_s"),
                fmt(f(l, "deepest_overlap_m")),
                // Resting only at the last sample is not coming to rest.
                l["rest_time_s"]
                    .as_f64()
                    .filter(|&t| t < f(l, "sim_time_s"))
                    .map_or("not within the run".into(), |t| format!("{t:.2}")),
                l["fallen"],
                divergence(l)
            );
        }
        md.push_str(
            "\nWall ratio and overlap ratio: engine / rigidsim (the 2-thread Rapier against \
             rigidsim on 2 ranks); a run capped short of the others' span is compared per \
             simulated second.\n",
        );
    }
    let mut versions: Vec<String> = lines
        .iter()
        .map(|l| {
            format!(
                "{}: {}",
                l["engine"].as_str().unwrap_or(""),
                l["version"].as_str().unwrap_or("")
            )
        })
        .collect();
    versions.sort();
    versions.dedup();
    let _ = writeln!(md, "\nVersions: {}.", versions.join("; "));
    let mut maps: Vec<String> = lines
        .iter()
        .filter(|l| l["kind"] == "case" || l["kind"] == "pour")
        .map(|l| {
            format!(
                "{} {}: {}",
                l["case"].as_str().unwrap_or(""),
                l["engine"].as_str().unwrap_or(""),
                l["mapping"]
            )
        })
        .collect();
    maps.dedup();
    std::fs::write(out.join("peers.md"), md).unwrap_or_else(|e| fail(&format!("peers.md: {e}")));
    std::fs::write(out.join("peers_mapping.txt"), maps.join("\n") + "\n")
        .unwrap_or_else(|e| fail(&format!("peers_mapping.txt: {e}")));

    // Work-precision plots: every engine's curve, one point per step.
    for case in &cases {
        if !lines.iter().any(|l| l["case"] == case.name) {
            continue;
        }
        let panels: Vec<plot::Panel> = case
            .metrics
            .iter()
            .map(|&(m, unit)| plot::Panel {
                title: format!("{m} against speed"),
                x_label: "real-time factor (simulated s / wall s)".into(),
                y_label: format!("{m} [{unit}]"),
                x_log: true,
                y_log: true,
                series: ENGINES
                    .iter()
                    .filter_map(|&e| {
                        let points: Vec<(f64, f64)> = dts
                            .iter()
                            .filter_map(|&dt| find(case.name, e, dt))
                            .map(|l| {
                                (
                                    f(l, "realtime_factor"),
                                    harness::floor_zero(f(&l["metrics"], m)),
                                )
                            })
                            .collect();
                        (!points.is_empty()).then(|| plot::Series {
                            label: e.into(),
                            points,
                            thin: false,
                        })
                    })
                    .collect(),
                vlines: vec![(1.0, "real time".into())],
                hlines: vec![],
            })
            .collect();
        let path = out.join(format!("peers_{}.png", case.name));
        if let Err(e) = plot::draw(&path, &format!("every engine: {}", case.title), &panels, 2) {
            eprintln!("yardstick: plot failed: {e}");
        }
    }
    eprintln!(
        "yardstick: {} runs; tables in {}",
        lines.len(),
        out.join("peers.md").display()
    );
}
