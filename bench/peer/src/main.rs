//! rigidsim and Rapier (`rapier3d-f64`) on the same work (issue 7 §3).
//!
//! Both engines are built from the very same rigidsim scene: the same convex
//! parts (each part one convex-hull collider), the same mass, centre of mass
//! and principal inertia (given to Rapier explicitly, colliders massless),
//! restitution, friction and their combine rule (rigidsim's `min`), gravity
//! and step. Errors are measured the same way for both (`bench/common`), and
//! overlaps by one independent oracle (parry's GJK/EPA).
//!
//! Rapier runs with its recommended settings: `IntegrationParameters::default()`
//! (4 solver iterations, 1 stabilisation iteration, warm start, contact
//! softness defaults, automatic CCD of fast bodies against fixed ones, sleeping
//! on), single-threaded (no `parallel` feature) like rigidsim's single rank; a
//! second configuration uses 8 solver iterations, which its documentation
//! recommends for stacks.
//!
//! `rigidsim-peer [--tiny] [--reps N] [--counts 20,50] [--out DIR] [--replot]`;
//! see `scripts/bench_peer.sh`. `--replot` redraws the PNGs from `peer.csv`.

#[path = "../../common/harness.rs"]
mod harness;
#[path = "../../common/plot.rs"]
mod plot;

use harness::{Case, Engine, Point, Rigidsim, Snap};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rapier3d_f64::prelude::*;
use rigidsim::body::BodyKind;
use rigidsim::scene::Scene;
use rigidsim::scene::schema::CombineRule;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Rapier on a rigidsim scene.
struct Rapier {
    world: PhysicsWorld,
    handles: Vec<Option<RigidBodyHandle>>,
    dynamic: Vec<bool>,
    /// Last state of each body (a fallen body keeps its last state).
    last: Vec<Snap>,
    fall_z: f64,
}

fn v(x: &Vector3<f64>) -> Vector {
    Vector::new(x.x, x.y, x.z)
}

fn q(x: &UnitQuaternion<f64>) -> Rotation {
    Rotation::from_xyzw(x.i, x.j, x.k, x.w)
}

fn rule(r: CombineRule) -> CoefficientCombineRule {
    match r {
        CombineRule::Min => CoefficientCombineRule::Min,
        CombineRule::Max => CoefficientCombineRule::Max,
        CombineRule::Mean => CoefficientCombineRule::Average,
        CombineRule::Product => CoefficientCombineRule::Multiply,
    }
}

/// A part as Rapier's best-suited shape for the very same solid: an
/// axis-aligned box becomes Rapier's `cuboid` (its box–box contact manifolds
/// are specialised), anything else a convex hull.
fn part_collider(vertices: &[Vector3<f64>]) -> ColliderBuilder {
    let (mut lo, mut hi) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for p in vertices {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let tol = 1e-12 * (hi - lo).norm();
    let on_corner = |p: &Vector3<f64>| {
        (0..3).all(|k| (p[k] - lo[k]).abs() <= tol || (p[k] - hi[k]).abs() <= tol)
    };
    if vertices.len() == 8 && vertices.iter().all(on_corner) {
        let (c, h) = ((lo + hi) * 0.5, (hi - lo) * 0.5);
        return ColliderBuilder::cuboid(h.x, h.y, h.z).translation(v(&c));
    }
    let pts: Vec<Vector> = vertices.iter().map(v).collect();
    ColliderBuilder::convex_hull(&pts).expect("convex part")
}

impl Rapier {
    fn new(scene: &Scene, iterations: usize, sleeping: bool) -> Rapier {
        let s = &scene.settings;
        let mut world = PhysicsWorld::new();
        world.gravity = v(&s.gravity);
        world.integration_parameters.dt = s.dt;
        world.integration_parameters.num_solver_iterations = iterations;
        let mut handles = Vec::new();
        let mut dynamic = Vec::new();
        for b in &scene.bodies {
            let o = &scene.objects[b.object.0 as usize];
            let pose = Pose::from_parts(v(&b.state.position), q(&b.state.orientation));
            let builder = match b.kind {
                BodyKind::Fixed => RigidBodyBuilder::fixed(),
                BodyKind::Driven {
                    velocity,
                    angular_velocity,
                } => RigidBodyBuilder::kinematic_velocity_based()
                    .linvel(v(&velocity))
                    .angvel(v(&angular_velocity)),
                BodyKind::Dynamic => {
                    let w = b.angular_velocity(o);
                    RigidBodyBuilder::dynamic()
                        .additional_mass_properties(MassProperties::with_principal_inertia_frame(
                            Vector::ZERO,
                            o.mass,
                            v(&o.principal_moments),
                            q(&o.principal_rotation),
                        ))
                        .linvel(v(&b.state.velocity))
                        .angvel(v(&w))
                        .can_sleep(sleeping)
                }
            };
            let h = world.insert_body(builder.pose(pose));
            for p in &o.parts {
                let c = part_collider(p.hull.vertices())
                    .density(0.0)
                    .friction(o.friction)
                    .restitution(o.restitution)
                    .friction_combine_rule(rule(s.friction_rule))
                    .restitution_combine_rule(rule(s.restitution_rule));
                world.insert_collider(c, Some(h));
            }
            handles.push(Some(h));
            dynamic.push(matches!(b.kind, BodyKind::Dynamic));
        }
        let mut r = Rapier {
            world,
            handles,
            dynamic,
            last: Vec::new(),
            fall_z: s.fall_z,
        };
        r.refresh();
        r
    }

    fn refresh(&mut self) {
        self.last.resize(
            self.handles.len(),
            Snap {
                position: Vector3::zeros(),
                orientation: UnitQuaternion::identity(),
                velocity: Vector3::zeros(),
                angular_velocity: Vector3::zeros(),
            },
        );
        for (i, h) in self.handles.iter().enumerate() {
            let Some(h) = h else { continue };
            let b = &self.world.bodies[*h];
            let (t, r, lv, av) = (b.translation(), b.rotation(), b.linvel(), b.angvel());
            self.last[i] = Snap {
                position: Vector3::new(t.x, t.y, t.z),
                orientation: UnitQuaternion::new_normalize(Quaternion::new(r.w, r.x, r.y, r.z)),
                velocity: Vector3::new(lv.x, lv.y, lv.z),
                angular_velocity: Vector3::new(av.x, av.y, av.z),
            };
        }
    }
}

impl Engine for Rapier {
    fn step(&mut self) -> Result<(), String> {
        self.world.step();
        // Like rigidsim: a body below fall_z leaves the simulation.
        for i in 0..self.handles.len() {
            if let Some(h) = self.handles[i]
                && self.dynamic[i]
                && self.world.bodies[h].translation().z < self.fall_z
            {
                self.world.remove_body(h);
                self.handles[i] = None;
            }
        }
        self.refresh();
        Ok(())
    }
    fn snaps(&self, out: &mut Vec<Snap>) {
        out.clear();
        out.extend_from_slice(&self.last);
    }
    fn at_rest(&self) -> bool {
        self.handles
            .iter()
            .zip(&self.dynamic)
            .all(|(h, &d)| !d || h.is_none_or(|h| self.world.bodies[h].is_sleeping()))
    }
}

#[derive(Clone, Copy)]
enum Config {
    Rigidsim,
    Rapier { iterations: usize },
}

impl Config {
    fn name(self) -> String {
        match self {
            Config::Rigidsim => "rigidsim".into(),
            Config::Rapier { iterations: 4 } => "rapier_default".into(),
            Config::Rapier { iterations } => format!("rapier_iter{iterations}"),
        }
    }
    fn make(self, scene: Scene) -> Box<dyn Engine> {
        match self {
            Config::Rigidsim => Box::new(Rigidsim::new(scene, true)),
            Config::Rapier { iterations } => Box::new(Rapier::new(&scene, iterations, true)),
        }
    }
}

const CONFIGS: [Config; 3] = [
    Config::Rigidsim,
    Config::Rapier { iterations: 4 },
    Config::Rapier { iterations: 8 },
];

/// A whole-scene run to rest (nuts and bolts): what the thesis measured.
struct SceneRun {
    scene: String,
    config: String,
    bodies: usize,
    sim_time: f64,
    walls: Vec<f64>,
    worst_frames: Vec<f64>,
    frame_interval: f64,
    penetration: f64,
    rested: bool,
}

fn nuts_and_bolts(count: u64) -> Scene {
    let text = std::fs::read_to_string("scenes/nuts_and_bolts.toml")
        .expect("run from the repository root (scenes/nuts_and_bolts.toml)");
    let text = text.replace("count = 20", &format!("count = {count}"));
    let mut s = rigidsim::scene::from_str(
        &text,
        Path::new(&format!("nuts_and_bolts_{count}.toml")),
        Path::new("scenes"),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    s.settings.render = None;
    s
}

fn run_scene(scene: &Scene, config: Config, reps: usize, max_time: f64) -> SceneRun {
    let dt = scene.settings.dt;
    let frame_steps = ((scene.settings.frame_interval / dt).round() as u64).max(1);
    let max_steps = harness::steps_for(max_time.min(scene.settings.end_time()), dt);
    let mut out = SceneRun {
        scene: scene.name.clone(),
        config: config.name(),
        bodies: scene.bodies.len(),
        sim_time: 0.0,
        walls: Vec::new(),
        worst_frames: Vec::new(),
        frame_interval: scene.settings.frame_interval,
        penetration: 0.0,
        rested: false,
    };
    // Probe run: overlaps at every frame, and where it comes to rest.
    let oracle = harness::Oracle::new(scene);
    let mut e = config.make(scene.clone());
    let mut snaps = Vec::new();
    let mut steps = 0;
    while steps < max_steps {
        if steps > 0 && e.at_rest() {
            out.rested = true;
            break;
        }
        if let Err(err) = e.step() {
            eprintln!("peer: {} failed: {err}", out.config);
            break;
        }
        steps += 1;
        if steps % frame_steps == 0 {
            e.snaps(&mut snaps);
            out.penetration = out.penetration.max(oracle.deepest(&snaps));
        }
    }
    out.sim_time = steps as f64 * dt;
    // Timed runs: the same number of steps.
    for _ in 0..reps {
        let mut e = config.make(scene.clone());
        let mut worst: f64 = 0.0;
        let start = Instant::now();
        let mut frame = Instant::now();
        for k in 1..=steps {
            let _ = e.step();
            if k % frame_steps == 0 || k == steps {
                worst = worst.max(frame.elapsed().as_secs_f64());
                frame = Instant::now();
            }
        }
        out.walls.push(start.elapsed().as_secs_f64());
        out.worst_frames.push(worst);
    }
    out
}

fn main() {
    let mut tiny = std::env::var("TINY").is_ok_and(|v| v == "1");
    let mut replot = false;
    let mut reps = 5;
    let mut out: Option<PathBuf> = None;
    let mut counts: Vec<u64> = vec![20, 50];
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--tiny" => tiny = true,
            "--replot" => replot = true,
            "--reps" => reps = args.next().and_then(|s| s.parse().ok()).expect("--reps N"),
            "--out" => out = args.next().map(PathBuf::from),
            "--counts" => {
                counts = args
                    .next()
                    .unwrap_or_default()
                    .split(',')
                    .filter_map(|s| s.parse().ok())
                    .collect()
            }
            other => {
                eprintln!("peer: unknown argument {other}");
                std::process::exit(2);
            }
        }
    }
    let machine = harness::machine_name();
    let out = out.unwrap_or_else(|| {
        if tiny {
            PathBuf::from("target/bench-tiny").join(&machine)
        } else {
            PathBuf::from("bench/results").join(&machine)
        }
    });
    std::fs::create_dir_all(&out).expect("cannot create the results folder");
    let mut cases = harness::cases();
    let dts: Vec<f64> = if tiny {
        for c in &mut cases {
            c.duration = c.duration.min(0.05);
        }
        reps = 1;
        counts = vec![2];
        vec![1e-2]
    } else {
        vec![1e-3, 3e-3, 1e-2, 3e-2]
    };
    let started = Instant::now();
    if replot {
        // Redraw the figures from an earlier run's peer.csv; measure nothing.
        let text = std::fs::read_to_string(out.join("peer.csv")).expect("--replot needs peer.csv");
        let points = harness::read_csv(&text);
        draw(&cases, &points, &out);
        return;
    }

    // 1. The exact cases, every engine, every step.
    let mut points: Vec<Point> = Vec::new();
    for case in &cases {
        for &config in &CONFIGS {
            for &dt in &dts {
                let p = harness::measure(case, &config.name(), dt, reps, &mut |s| config.make(s));
                eprintln!(
                    "peer: {:<18} {:<15} dt {:<6e} RTF {:>9.1} {}",
                    case.name,
                    p.config,
                    dt,
                    p.realtime_factor(),
                    p.metrics
                        .iter()
                        .map(|(n, _, v)| format!("{n} {v:.2e}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                );
                points.push(p);
            }
        }
    }
    std::fs::write(
        out.join("peer.csv"),
        format!("{}\n{}", harness::CSV_HEADER, harness::csv_rows(&points)),
    )
    .expect("write peer.csv");

    // 2. Nuts and bolts to rest, as in the thesis.
    let mut runs = Vec::new();
    let max_time = if tiny { 0.05 } else { 20.0 };
    let scene_reps = if tiny { 1 } else { reps.min(3) };
    for &n in &counts {
        let scene = nuts_and_bolts(n);
        for &config in &CONFIGS[..2] {
            let r = run_scene(&scene, config, scene_reps, max_time);
            eprintln!(
                "peer: nuts_and_bolts {n:>4} {:<15} {:.2} s simulated{} in {:.3} s, worst frame {:.4} s, overlap {:.2e} m",
                r.config,
                r.sim_time,
                if r.rested { " to rest" } else { "" },
                harness::median(&r.walls),
                harness::median(&r.worst_frames),
                r.penetration
            );
            runs.push(r);
        }
    }
    let mut csv = String::from(
        "scene,config,bodies,sim_time_s,rested,runs,wall_median_s,worst_frame_median_s,frame_interval_s,realtime_factor,max_penetration_m\n",
    );
    for r in &runs {
        let w = harness::median(&r.walls);
        let _ = writeln!(
            csv,
            "{},{},{},{},{},{},{:e},{:e},{},{:e},{:e}",
            r.scene,
            r.config,
            r.bodies,
            r.sim_time,
            r.rested,
            r.walls.len(),
            w,
            harness::median(&r.worst_frames),
            r.frame_interval,
            r.sim_time / w,
            r.penetration
        );
    }
    std::fs::write(out.join("peer_scenes.csv"), csv).expect("write peer_scenes.csv");
    std::fs::write(out.join("peer.md"), tables(&cases, &points, &runs, reps))
        .expect("write peer.md");
    draw(&cases, &points, &out);
    eprintln!(
        "peer: done in {:.1} s; results in {}",
        started.elapsed().as_secs_f64(),
        out.display()
    );
}

fn draw(cases: &[Case], points: &[Point], out: &Path) {
    for case in cases {
        let path = out.join(format!("peer_{}.png", case.name));
        let title = format!("rigidsim vs Rapier: {}", case.title);
        if let Err(e) = plot::draw(&path, &title, &panels(case, points), 2) {
            eprintln!("peer: plot failed: {e}");
        }
    }
}

fn panels(case: &Case, points: &[Point]) -> Vec<plot::Panel> {
    case.metrics
        .iter()
        .map(|&(metric, unit)| plot::Panel {
            title: format!("{metric} against speed"),
            x_label: "real-time factor (simulated s / wall s)".into(),
            y_label: format!("{metric} [{unit}]"),
            x_log: true,
            y_log: true,
            series: CONFIGS
                .iter()
                .map(|c| plot::Series {
                    label: c.name(),
                    points: points
                        .iter()
                        .filter(|p| p.case == case.name && p.config == c.name())
                        .map(|p| (p.realtime_factor(), harness::floor_zero(p.metric(metric))))
                        .collect(),
                    thin: false,
                })
                .collect(),
            vlines: vec![(1.0, "real time".into())],
            hlines: vec![],
        })
        .collect()
}

fn ratio(a: f64, b: f64) -> String {
    if a.is_nan() || b.is_nan() {
        "n/a".into()
    } else if b == 0.0 {
        if a == 0.0 {
            "both 0".into()
        } else {
            "Rapier exact".into()
        }
    } else if a == 0.0 {
        "rigidsim exact".into()
    } else if a / b < 0.01 || a / b > 1000.0 {
        format!("{:.1e}", a / b)
    } else {
        format!("{:.3}", a / b)
    }
}

fn tables(cases: &[Case], points: &[Point], runs: &[SceneRun], reps: usize) -> String {
    let mut s = format!(
        "<!-- written by bench/peer (scripts/bench_peer.sh); {} -->\n\
         Time ratio = rigidsim wall / Rapier wall (below 1: rigidsim faster). Error ratio = \
         rigidsim error / Rapier error (below 1: rigidsim more accurate). Wall = median of {reps} \
         timed runs after a probe run; single thread each.\n\n",
        harness::machine_description()
    );
    let mut dts: Vec<f64> = points.iter().map(|p| p.dt).collect();
    dts.sort_by(|a, b| a.total_cmp(b));
    dts.dedup();
    for rapier in ["rapier_default", "rapier_iter8"] {
        for &dt in &dts {
            let _ = writeln!(s, "### rigidsim vs {rapier}, dt = {dt} s\n");
            s.push_str("| case | metric | rigidsim RTF | Rapier RTF | time ratio | rigidsim error | Rapier error | error ratio |\n|---|---|---|---|---|---|---|---|\n");
            for case in cases {
                let find = |c: &str| {
                    points
                        .iter()
                        .find(|p| p.case == case.name && p.config == c && p.dt == dt)
                };
                let (Some(a), Some(b)) = (find("rigidsim"), find(rapier)) else {
                    continue;
                };
                for &(m, u) in case.metrics {
                    let (ea, eb) = (a.metric(m), b.metric(m));
                    let _ = writeln!(
                        s,
                        "| {} | {m} [{u}] | {:.1} | {:.1} | {:.3} | {} | {} | {} |",
                        case.name,
                        a.realtime_factor(),
                        b.realtime_factor(),
                        a.wall() / b.wall(),
                        harness::fmt_err(ea),
                        harness::fmt_err(eb),
                        ratio(ea, eb)
                    );
                }
            }
            s.push('\n');
        }
    }
    s.push_str(
        "### Nuts and bolts falling onto the 2 m floor, to rest (dt = 0.01 s, one thread)\n\n",
    );
    s.push_str("| bodies | engine | simulated [s] | rested | wall [s] | real-time factor | worst frame [s] | frame interval [s] | deepest overlap [m] |\n|---|---|---|---|---|---|---|---|---|\n");
    for r in runs {
        let w = harness::median(&r.walls);
        let _ = writeln!(
            s,
            "| {} | {} | {:.2} | {} | {:.3} | {:.2} | {:.4} | {} | {:.2e} |",
            r.bodies - 1,
            r.config,
            r.sim_time,
            if r.rested { "yes" } else { "no (cap)" },
            w,
            r.sim_time / w,
            harness::median(&r.worst_frames),
            r.frame_interval,
            r.penetration
        );
    }
    for pair in runs.chunks(2) {
        if let [a, b] = pair {
            let (wa, wb) = (harness::median(&a.walls), harness::median(&b.walls));
            let _ = writeln!(
                s,
                "\n{} bodies: wall ratio rigidsim/Rapier {:.2} (per simulated second {:.2}), worst-frame ratio {:.2}.",
                a.bodies - 1,
                wa / wb,
                (wa / a.sim_time) / (wb / b.sim_time),
                harness::median(&a.worst_frames) / harness::median(&b.worst_frames)
            );
        }
    }
    s
}
