//! Rapier (`rapier3d-f64`) on a scene exported by `rigidsim export`.
//!
//! Reads the bodies file (README.md, "rigidsim export"), builds the very same
//! bodies: each convex part a collider (an axis-aligned box part Rapier's
//! `cuboid`, whose box–box manifolds are specialised; any other part the
//! convex hull of the same vertices), massless colliders and the body's mass,
//! centre of mass and principal inertia given explicitly, restitution and
//! friction with rigidsim's combine rule (Rapier has the same four rules, so
//! every pair's coefficient is rigidsim's with each body's own values).
//! Then, like `bench/peer_py/peer.py`, a probe run writes rigidsim's
//! `trajectory.csv` (nothing timed) and `--reps` fresh runs are timed (the
//! `step` call only) into a JSON record, for `yardstick` to measure.
//!
//! Configurations: `default` is `IntegrationParameters::default()` (its
//! documented recommendation: 4 solver iterations, 1 stabilisation iteration,
//! warm start, default softness, CCD of fast bodies against fixed ones,
//! sleeping on); `tuned` sets `length_unit` to the dynamic bodies' size (the
//! median of their bounding-box diagonals), as its documentation says to
//! for bodies far from 1 m. Built with the `parallel` feature, the same
//! configurations run on `RAYON_NUM_THREADS` threads.
//!
//! `rapier-peer CONFIG BODIES --duration S --trajectory CSV --record JSON
//!  [--sample-every N] [--frame S] [--reps N]`

use rapier3d_f64::prelude::*;
use serde::Deserialize;
use std::fmt::Write as _;
use std::io::Write as _;
use std::time::Instant;

#[derive(Deserialize)]
struct Export {
    format: u32,
    world: WorldIn,
    objects: Vec<ObjectIn>,
    bodies: Vec<BodyIn>,
}

#[derive(Deserialize)]
struct WorldIn {
    gravity: [f64; 3],
    dt: f64,
    fall_z: Option<f64>,
    restitution_rule: String,
    friction_rule: String,
}

#[derive(Deserialize)]
struct ObjectIn {
    parts: Vec<PartIn>,
}

#[derive(Deserialize)]
struct PartIn {
    vertices: Vec<[f64; 3]>,
}

#[derive(Deserialize)]
struct DrivenIn {
    velocity: [f64; 3],
    angular_velocity: [f64; 3],
}

#[derive(Deserialize)]
struct BodyIn {
    object: usize,
    kind: String,
    driven: Option<DrivenIn>,
    mass: f64,
    principal_moments: [f64; 3],
    principal_rotation: [f64; 4],
    restitution: f64,
    friction: f64,
    initial: StateIn,
}

#[derive(Deserialize)]
struct StateIn {
    position: [f64; 3],
    orientation: [f64; 4],
    velocity: [f64; 3],
    angular_velocity: [f64; 3],
}

fn v(x: &[f64; 3]) -> Vector {
    Vector::new(x[0], x[1], x[2])
}

/// `[w, x, y, z]` as Rapier's rotation.
fn q(x: &[f64; 4]) -> Rotation {
    Rotation::from_xyzw(x[1], x[2], x[3], x[0])
}

fn rule(r: &str) -> CoefficientCombineRule {
    match r {
        "min" => CoefficientCombineRule::Min,
        "max" => CoefficientCombineRule::Max,
        "mean" => CoefficientCombineRule::Average,
        "product" => CoefficientCombineRule::Multiply,
        other => fail(&format!("unknown combine rule {other}")),
    }
}

fn fail(msg: &str) -> ! {
    eprintln!("rapier-peer: {msg}");
    std::process::exit(2)
}

/// A part as Rapier's best-suited shape for the very same solid.
fn part_collider(vertices: &[[f64; 3]]) -> ColliderBuilder {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for p in vertices {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    let diag = (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt();
    let tol = 1e-12 * diag;
    let on_corner =
        |p: &[f64; 3]| (0..3).all(|k| (p[k] - lo[k]).abs() <= tol || (p[k] - hi[k]).abs() <= tol);
    if vertices.len() == 8 && vertices.iter().all(on_corner) {
        let c = [0, 1, 2].map(|k| 0.5 * (lo[k] + hi[k]));
        let h = [0, 1, 2].map(|k| 0.5 * (hi[k] - lo[k]));
        return ColliderBuilder::cuboid(h[0], h[1], h[2]).translation(v(&c));
    }
    let pts: Vec<Vector> = vertices.iter().map(v).collect();
    ColliderBuilder::convex_hull(&pts).unwrap_or_else(|| fail("a part is not a convex solid"))
}

/// The dynamic bodies' size: the median bounding-box diagonal.
fn body_size(e: &Export) -> f64 {
    let mut sizes: Vec<f64> = e
        .bodies
        .iter()
        .filter(|b| b.kind == "dynamic")
        .map(|b| {
            let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
            for p in &e.objects[b.object].parts {
                for x in &p.vertices {
                    for k in 0..3 {
                        lo[k] = lo[k].min(x[k]);
                        hi[k] = hi[k].max(x[k]);
                    }
                }
            }
            (0..3).map(|k| (hi[k] - lo[k]).powi(2)).sum::<f64>().sqrt()
        })
        .collect();
    if sizes.is_empty() {
        return 1.0;
    }
    sizes.sort_by(f64::total_cmp);
    sizes[sizes.len() / 2]
}

type State = ([f64; 3], [f64; 4], [f64; 3], [f64; 3]);

struct Rapier {
    world: PhysicsWorld,
    handles: Vec<Option<RigidBodyHandle>>,
    dynamic: Vec<bool>,
    /// Last state of each body (a body below fall_z keeps its last state).
    last: Vec<State>,
    fall_z: f64,
}

impl Rapier {
    fn new(e: &Export, length_unit: Option<f64>) -> Rapier {
        let w = &e.world;
        let mut world = PhysicsWorld::new();
        world.gravity = v(&w.gravity);
        world.integration_parameters.dt = w.dt;
        if let Some(l) = length_unit {
            world.integration_parameters.length_unit = l;
        }
        let (fr, rr) = (rule(&w.friction_rule), rule(&w.restitution_rule));
        let mut handles = Vec::new();
        let mut dynamic = Vec::new();
        for b in &e.bodies {
            let s = &b.initial;
            let pose = Pose::from_parts(v(&s.position), q(&s.orientation));
            let builder = match (b.kind.as_str(), &b.driven) {
                ("fixed", _) => RigidBodyBuilder::fixed(),
                ("driven", Some(d)) => RigidBodyBuilder::kinematic_velocity_based()
                    .linvel(v(&d.velocity))
                    .angvel(v(&d.angular_velocity)),
                ("dynamic", _) => RigidBodyBuilder::dynamic()
                    .additional_mass_properties(MassProperties::with_principal_inertia_frame(
                        Vector::ZERO,
                        b.mass,
                        v(&b.principal_moments),
                        q(&b.principal_rotation),
                    ))
                    .linvel(v(&s.velocity))
                    .angvel(v(&s.angular_velocity)),
                (k, _) => fail(&format!("unknown body kind {k}")),
            };
            let h = world.insert_body(builder.pose(pose));
            for p in &e.objects[b.object].parts {
                let c = part_collider(&p.vertices)
                    .density(0.0)
                    .friction(b.friction)
                    .restitution(b.restitution)
                    .friction_combine_rule(fr)
                    .restitution_combine_rule(rr);
                world.insert_collider(c, Some(h));
            }
            handles.push(Some(h));
            dynamic.push(b.kind == "dynamic");
        }
        let mut r = Rapier {
            world,
            handles,
            dynamic,
            last: vec![([0.0; 3], [1.0, 0.0, 0.0, 0.0], [0.0; 3], [0.0; 3]); e.bodies.len()],
            fall_z: w.fall_z.unwrap_or(f64::NEG_INFINITY),
        };
        r.refresh();
        r
    }

    fn step(&mut self) {
        self.world.step();
    }

    /// Reads every body's state; like rigidsim, a dynamic body below fall_z
    /// leaves the simulation.
    fn refresh(&mut self) {
        for i in 0..self.handles.len() {
            let Some(h) = self.handles[i] else { continue };
            let b = &self.world.bodies[h];
            let (t, r, lv, av) = (b.translation(), b.rotation(), b.linvel(), b.angvel());
            let n = (r.w * r.w + r.x * r.x + r.y * r.y + r.z * r.z).sqrt();
            self.last[i] = (
                [t.x, t.y, t.z],
                [r.w / n, r.x / n, r.y / n, r.z / n],
                [lv.x, lv.y, lv.z],
                [av.x, av.y, av.z],
            );
            if self.dynamic[i] && t.z < self.fall_z {
                self.world.remove_body(h);
                self.handles[i] = None;
            }
        }
    }
}

fn write_rows(out: &mut String, t: f64, states: &[State]) {
    for (i, (x, q, v, w)) in states.iter().enumerate() {
        let _ = writeln!(
            out,
            "{t},{i},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            x[0], x[1], x[2], q[0], q[1], q[2], q[3], v[0], v[1], v[2], w[0], w[1], w[2]
        );
    }
}

fn main() {
    let mut args = std::env::args().skip(1);
    let config = args
        .next()
        .unwrap_or_else(|| fail("usage: rapier-peer CONFIG BODIES ..."));
    let bodies = args
        .next()
        .unwrap_or_else(|| fail("usage: rapier-peer CONFIG BODIES ..."));
    let (mut duration, mut trajectory, mut record) = (None, None, None);
    let (mut sample_every, mut frame, mut reps) = (1u64, 0.1f64, 1usize);
    while let Some(a) = args.next() {
        let mut val = || {
            args.next()
                .unwrap_or_else(|| fail(&format!("{a} needs a value")))
        };
        match a.as_str() {
            "--duration" => duration = val().parse::<f64>().ok(),
            "--trajectory" => trajectory = Some(val()),
            "--record" => record = Some(val()),
            "--sample-every" => {
                sample_every = val().parse().unwrap_or_else(|_| fail("--sample-every N"))
            }
            "--frame" => frame = val().parse().unwrap_or_else(|_| fail("--frame S")),
            "--reps" => reps = val().parse().unwrap_or_else(|_| fail("--reps N")),
            other => fail(&format!("unknown argument {other}")),
        }
    }
    let duration = duration.unwrap_or_else(|| fail("--duration S is required"));
    let (trajectory, record) = (
        trajectory.unwrap_or_else(|| fail("--trajectory CSV is required")),
        record.unwrap_or_else(|| fail("--record JSON is required")),
    );
    let text = std::fs::read_to_string(&bodies).unwrap_or_else(|e| fail(&format!("{bodies}: {e}")));
    let e: Export =
        serde_json::from_str(&text).unwrap_or_else(|err| fail(&format!("{bodies}: {err}")));
    if e.format != 1 {
        fail(&format!(
            "{bodies}: export format {} (this peer reads 1)",
            e.format
        ));
    }
    let length_unit = match config.as_str() {
        "default" => None,
        "tuned" => Some(body_size(&e)),
        other => fail(&format!("unknown configuration {other} (default | tuned)")),
    };
    let dt = e.world.dt;
    let steps = ((duration / dt) - 1e-9).ceil().max(0.0) as u64;
    let frame_steps = ((frame / dt).round() as u64).max(1);

    // Probe run: the trajectory, nothing timed.
    let mut r = Rapier::new(&e, length_unit);
    let mut csv = String::from("time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz\n");
    write_rows(&mut csv, 0.0, &r.last);
    for k in 1..=steps {
        r.step();
        r.refresh();
        if k % sample_every == 0 || k == steps {
            write_rows(&mut csv, k as f64 * dt, &r.last);
        }
    }
    std::fs::write(&trajectory, csv).unwrap_or_else(|err| fail(&format!("{trajectory}: {err}")));

    // Timed runs: fresh worlds, only the step call timed.
    let (mut walls, mut worsts) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let mut r = Rapier::new(&e, length_unit);
        let (mut total, mut in_frame, mut worst) = (0.0f64, 0.0f64, 0.0f64);
        for k in 1..=steps {
            let clock = Instant::now();
            r.step();
            let s = clock.elapsed().as_secs_f64();
            total += s;
            in_frame += s;
            r.refresh();
            if k % frame_steps == 0 || k == steps {
                worst = worst.max(in_frame);
                in_frame = 0.0;
            }
        }
        walls.push(total);
        worsts.push(worst);
    }
    #[cfg(feature = "parallel")]
    let (name, threads) = (
        format!("rapier_{config}_parallel"),
        rayon::current_num_threads(),
    );
    #[cfg(not(feature = "parallel"))]
    let (name, threads) = (format!("rapier_{config}"), 1usize);
    let rec = serde_json::json!({
        "engine": name,
        "version": "rapier3d-f64 0.36.1",
        "steps": steps,
        "dt": dt,
        "sim_time_s": steps as f64 * dt,
        "walls_s": walls,
        "worst_frames_s": worsts,
        "frame_interval_s": frame,
        "threads": threads,
        "mapping": { "length_unit": length_unit.unwrap_or(1.0),
                     "rule": "Rapier's own combine rule set to rigidsim's" },
    });
    let mut f =
        std::fs::File::create(&record).unwrap_or_else(|err| fail(&format!("{record}: {err}")));
    let _ = writeln!(f, "{rec}");
}
