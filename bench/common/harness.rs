//! The exact cases of issue 7 §1, their exact answers and error measures, and
//! the timing harness shared by `benches/accuracy.rs` (rigidsim alone) and
//! `bench/peer` (rigidsim and Rapier side by side).
//!
//! Every case is a scene in rigidsim's TOML format; an engine is anything that
//! steps that scene and reports each body's state (`Snap`). The exact answers
//! are those of `tests/physics_exact.rs`, restated here.
//!
//! Method (Erez, Tassa & Todorov 2015; OSRF "boxes"; SimBenchmark): for each
//! case, configuration and step size, one probe run records the errors (and,
//! through an independent oracle, the deepest overlap), then `reps` timed runs
//! step the same scene with nothing else in the loop. The real-time factor is
//! simulated time over the median wall time of the timed runs.
#![allow(dead_code)]

use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use parry3d_f64::math::{Pose as PPose, Rotation as PRot, Vector as PVec};
use parry3d_f64::query;
use parry3d_f64::shape::ConvexPolyhedron as ParryPoly;
use rigidsim::body::BodyKind;
use rigidsim::scene::Scene;
use rigidsim::step::{Inline, World};
use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

pub const G: f64 = 9.81;

/// One body's state as every engine reports it: centre of mass, orientation,
/// velocity, world angular velocity.
#[derive(Clone, Copy, Debug)]
pub struct Snap {
    pub position: Vector3<f64>,
    pub orientation: UnitQuaternion<f64>,
    pub velocity: Vector3<f64>,
    pub angular_velocity: Vector3<f64>,
}

/// Something that steps a scene: rigidsim's `World`, or a peer engine.
pub trait Engine {
    fn step(&mut self) -> Result<(), String>;
    fn snaps(&self, out: &mut Vec<Snap>);
    /// True once every dynamic body rests or has fallen off (runs "to rest").
    fn at_rest(&self) -> bool;
}

/// rigidsim, single rank, inline executor (what `mpirun -np 1` runs).
pub struct Rigidsim {
    pub world: World,
    exec: Inline,
}

impl Rigidsim {
    pub fn new(scene: Scene, resting_systems: bool) -> Rigidsim {
        let mut world = World::new(scene);
        world.settings.sleep_enabled = resting_systems;
        Rigidsim {
            world,
            exec: Inline::default(),
        }
    }
}

impl Engine for Rigidsim {
    fn step(&mut self) -> Result<(), String> {
        self.world.step(&mut self.exec).map_err(|e| e.to_string())
    }
    fn snaps(&self, out: &mut Vec<Snap>) {
        out.clear();
        for (i, b) in self.world.state.bodies.iter().enumerate() {
            out.push(Snap {
                position: b.state.position,
                orientation: b.state.orientation,
                velocity: b.state.velocity,
                angular_velocity: b.angular_velocity(self.world.object(i)),
            });
        }
    }
    fn at_rest(&self) -> bool {
        self.world.at_rest()
    }
}

pub fn scene_of(toml: &str, name: &str) -> Scene {
    rigidsim::scene::from_str(toml, Path::new(&format!("{name}.toml")), Path::new("."))
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Kinetic energy from a snap, with the scene's own mass and inertia.
pub fn kinetic_energy(scene: &Scene, i: usize, s: &Snap) -> f64 {
    let b = &scene.bodies[i];
    if !matches!(b.kind, BodyKind::Dynamic) {
        return 0.0;
    }
    let o = &scene.objects[b.object.0 as usize];
    let r = s.orientation.to_rotation_matrix();
    let inertia = r.matrix() * o.inertia * r.matrix().transpose();
    0.5 * o.mass * s.velocity.norm_squared()
        + 0.5 * s.angular_velocity.dot(&(inertia * s.angular_velocity))
}

pub fn angular_momentum(scene: &Scene, i: usize, s: &Snap) -> Vector3<f64> {
    let o = &scene.objects[scene.bodies[i].object.0 as usize];
    let r = s.orientation.to_rotation_matrix();
    r.matrix() * o.inertia * r.matrix().transpose() * s.angular_velocity
}

// ---------------------------------------------------------------------------
// Penetration oracle: parry3d-f64's GJK/EPA on the very same convex parts, so
// both engines' overlaps are measured by one independent yardstick.

pub struct Oracle {
    /// Per object: its parts as parry polyhedra.
    parts: Vec<Vec<ParryPoly>>,
    radius: Vec<f64>,
    object_of: Vec<usize>,
    dynamic: Vec<bool>,
    /// Bodies below this have left the simulation (both engines freeze or
    /// drop them): their overlaps with later fallers do not count.
    fall_z: f64,
}

fn to_pose(p: &Vector3<f64>, q: &UnitQuaternion<f64>) -> PPose {
    PPose::from_parts(
        PVec::new(p.x, p.y, p.z),
        PRot::from_xyzw(q.i, q.j, q.k, q.w),
    )
}

impl Oracle {
    pub fn new(scene: &Scene) -> Oracle {
        Oracle {
            parts: scene
                .objects
                .iter()
                .map(|o| {
                    o.parts
                        .iter()
                        .map(|p| {
                            let pts: Vec<PVec> = p
                                .hull
                                .vertices()
                                .iter()
                                .map(|v| PVec::new(v.x, v.y, v.z))
                                .collect();
                            ParryPoly::from_convex_hull(&pts).expect("convex part")
                        })
                        .collect()
                })
                .collect(),
            radius: scene.objects.iter().map(|o| o.outer_radius()).collect(),
            object_of: scene.bodies.iter().map(|b| b.object.0 as usize).collect(),
            dynamic: scene
                .bodies
                .iter()
                .map(|b| matches!(b.kind, BodyKind::Dynamic))
                .collect(),
            fall_z: scene.settings.fall_z,
        }
    }

    /// The oracle over parts given as vertex lists (e.g. read back from
    /// `rigidsim export`'s file): per object its convex parts, then per body
    /// its object, whether it is dynamic, and the scene's `fall_z`.
    pub fn from_parts(
        objects: &[Vec<Vec<[f64; 3]>>],
        object_of: Vec<usize>,
        dynamic: Vec<bool>,
        fall_z: f64,
    ) -> Result<Oracle, String> {
        let mut parts = Vec::new();
        let mut radius = Vec::new();
        for (i, o) in objects.iter().enumerate() {
            let mut polys = Vec::new();
            let mut r: f64 = 0.0;
            for p in o {
                let pts: Vec<PVec> = p.iter().map(|v| PVec::new(v[0], v[1], v[2])).collect();
                r = p
                    .iter()
                    .map(|v| (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
                    .fold(r, f64::max);
                polys.push(
                    ParryPoly::from_convex_hull(&pts)
                        .ok_or_else(|| format!("object {i}: a part is not a convex solid"))?,
                );
            }
            parts.push(polys);
            radius.push(r);
        }
        Ok(Oracle {
            parts,
            radius,
            object_of,
            dynamic,
            fall_z,
        })
    }

    /// Deepest overlap (metres) between any two bodies in these states.
    pub fn deepest(&self, snaps: &[Snap]) -> f64 {
        let mut deepest: f64 = 0.0;
        let gone = |k: usize| self.dynamic[k] && snaps[k].position.z < self.fall_z;
        for i in 0..snaps.len() {
            for j in i + 1..snaps.len() {
                if !(self.dynamic[i] || self.dynamic[j]) || gone(i) || gone(j) {
                    continue;
                }
                let (oi, oj) = (self.object_of[i], self.object_of[j]);
                let reach = self.radius[oi] + self.radius[oj];
                if (snaps[i].position - snaps[j].position).norm() > reach {
                    continue;
                }
                let pi = to_pose(&snaps[i].position, &snaps[i].orientation);
                let pj = to_pose(&snaps[j].position, &snaps[j].orientation);
                for a in &self.parts[oi] {
                    for b in &self.parts[oj] {
                        if let Ok(Some(c)) = query::contact(&pi, a, &pj, b, 0.0) {
                            deepest = deepest.max(-c.dist);
                        }
                    }
                }
            }
        }
        deepest
    }
}

// ---------------------------------------------------------------------------
// The cases.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Projectile,
    Tumbling,
    Bounce,
    Exchange,
    Cradle,
    Stack,
    Sliding,
}

pub struct Case {
    pub name: &'static str,
    pub title: &'static str,
    pub kind: Kind,
    /// Simulated seconds per run.
    pub duration: f64,
    /// (metric name, unit) in the order `Probe::finish` returns them.
    pub metrics: &'static [(&'static str, &'static str)],
}

const FLOOR: &str = r#"
[objects.floor]
shape = { box = { half_extents = [5.0, 5.0, 0.1] } }
mass = 1.0
restitution = 1.0
friction = 0.0

[[bodies]]
object = "floor"
position = [0.0, 0.0, -0.1]
fixed = true
"#;

/// Bounce case: e = 0.8 from h0 = 1 m; five impacts take 2.58 s.
pub const BOUNCE_E: f64 = 0.8;
/// Sliding case: μ = 0.3 on a 30° slope (gravity tilted about y).
pub const SLIDE_MU: f64 = 0.3;

pub fn cases() -> Vec<Case> {
    vec![
        Case {
            name: "projectile",
            title: "projectile (parabola, 1 s)",
            kind: Kind::Projectile,
            duration: 1.0,
            metrics: &[("position_error", "m")],
        },
        Case {
            name: "tumbling_box",
            title: "torque-free box 0.1x0.4x0.9 m, w0 = (0.1, 5, 0.1), 10 s",
            kind: Kind::Tumbling,
            duration: 10.0,
            metrics: &[("energy_drift", "rel"), ("momentum_drift", "rel")],
        },
        Case {
            name: "bouncing_cube",
            title: "cube bouncing, e = 0.8, h0 = 1 m, 4 apexes",
            kind: Kind::Bounce,
            duration: 2.6,
            metrics: &[
                ("apex_height_error", "rel"),
                ("impact_time_error", "s"),
                ("penetration", "m"),
            ],
        },
        Case {
            name: "two_cube_exchange",
            title: "two equal cubes head-on, e = 1 (velocities exchange)",
            kind: Kind::Exchange,
            duration: 1.0,
            metrics: &[("velocity_error", "m/s"), ("penetration", "m")],
        },
        Case {
            name: "newtons_cradle",
            title: "Newton's cradle, 3 cubes, e = 1",
            kind: Kind::Cradle,
            duration: 1.0,
            metrics: &[
                ("velocity_error_lcp", "m/s"),
                ("velocity_error_sequential", "m/s"),
                ("energy_error", "rel"),
                ("penetration", "m"),
            ],
        },
        Case {
            name: "resting_stack",
            title: "stack of 10 cubes resting, 5 s",
            kind: Kind::Stack,
            duration: 5.0,
            metrics: &[("drift", "m"), ("penetration", "m")],
        },
        Case {
            name: "sliding_box",
            title: "box sliding on a 30 deg slope, mu = 0.3, 2 s",
            kind: Kind::Sliding,
            duration: 2.0,
            metrics: &[
                ("acceleration_error", "rel"),
                ("sideways_drift", "m"),
                ("penetration", "m"),
            ],
        },
    ]
}

impl Case {
    /// The scene at step `dt`, as rigidsim's TOML.
    pub fn toml(&self, dt: f64) -> String {
        let d = self.duration;
        match self.kind {
            Kind::Projectile => format!(
                "[world]\ndt = {dt}\nduration = {d}\n\
                 [objects.ball]\nshape = {{ box = {{ half_extents = [0.1, 0.1, 0.1] }} }}\nmass = 2.0\n\
                 [[bodies]]\nobject = \"ball\"\nvelocity = [1.0, 0.0, 5.0]\n"
            ),
            Kind::Tumbling => format!(
                "[world]\ngravity = [0.0, 0.0, 0.0]\ndt = {dt}\nduration = {d}\n\
                 [objects.box]\nshape = {{ box = {{ half_extents = [0.05, 0.2, 0.45] }} }}\nmass = 10.0\n\
                 [[bodies]]\nobject = \"box\"\nangular_velocity = [0.1, 5.0, 0.1]\n"
            ),
            Kind::Bounce => format!(
                "[world]\ndt = {dt}\nduration = {d}\n{FLOOR}\n\
                 [objects.cube]\nshape = {{ box = {{ half_extents = [0.05, 0.05, 0.05] }} }}\nmass = 1.0\n\
                 restitution = {BOUNCE_E}\nfriction = 0.0\n\
                 [[bodies]]\nobject = \"cube\"\nposition = [0.0, 0.0, 1.05]\n"
            ),
            Kind::Exchange | Kind::Cradle => {
                let (v, x): (&[f64], &[f64]) = if self.kind == Kind::Exchange {
                    (&[1.0, -0.5], &[-0.5, 0.5])
                } else {
                    (&[1.0, 0.0, 0.0], &[-0.3, 0.0, 0.1])
                };
                let mut s = format!(
                    "[world]\ngravity = [0.0, 0.0, 0.0]\ndt = {dt}\nduration = {d}\n\
                     [objects.cube]\nshape = {{ box = {{ half_extents = [0.05, 0.05, 0.05] }} }}\n\
                     mass = 1.0\nrestitution = 1.0\nfriction = 0.0\n"
                );
                for (v, x) in v.iter().zip(x) {
                    let _ = write!(
                        s,
                        "[[bodies]]\nobject = \"cube\"\nposition = [{x}, 0.0, 0.0]\nvelocity = [{v}, 0.0, 0.0]\n"
                    );
                }
                s
            }
            Kind::Stack => {
                let mut s = format!(
                    "[world]\ndt = {dt}\nduration = {d}\n{FLOOR}\n\
                     [objects.cube]\nshape = {{ box = {{ half_extents = [0.1, 0.1, 0.1] }} }}\n\
                     mass = 1.0\nrestitution = 0.0\nfriction = 0.6\n"
                );
                for i in 0..10 {
                    let _ = write!(
                        s,
                        "[[bodies]]\nobject = \"cube\"\nposition = [0.0, 0.0, {}]\n",
                        0.1 + 0.2 * i as f64
                    );
                }
                s
            }
            Kind::Sliding => {
                // 9.81 · (sin 30°, 0, −cos 30°).
                let (gx, gz) = (G * 0.5, -G * 3f64.sqrt() / 2.0);
                format!(
                    "[world]\ngravity = [{gx}, 0.0, {gz}]\ndt = {dt}\nduration = {d}\n\
                     [objects.floor]\nshape = {{ box = {{ half_extents = [50.0, 50.0, 0.1] }} }}\nmass = 1.0\n\
                     friction = {SLIDE_MU}\nrestitution = 0.0\n\
                     [[bodies]]\nobject = \"floor\"\nposition = [0.0, 0.0, -0.1]\nfixed = true\n\
                     [objects.box]\nshape = {{ box = {{ half_extents = [0.1, 0.15, 0.05] }} }}\nmass = 2.0\n\
                     friction = {SLIDE_MU}\nrestitution = 0.0\n\
                     [[bodies]]\nobject = \"box\"\nposition = [0.0, 0.0, 0.05]\n"
                )
            }
        }
    }

    pub fn scene(&self, dt: f64) -> Scene {
        scene_of(&self.toml(dt), self.name)
    }

    /// Whether the oracle's overlap is measured (cases with contacts).
    pub fn has_contacts(&self) -> bool {
        !matches!(self.kind, Kind::Projectile | Kind::Tumbling)
    }
}

/// Observes a run step by step and turns it into the case's errors.
pub struct Probe {
    kind: Kind,
    scene: Scene,
    initial: Vec<Snap>,
    e0: f64,
    l0: f64,
    worst_e: f64,
    worst_l: f64,
    prev_vz: f64,
    apexes: Vec<f64>,
    impacts: Vec<f64>,
    last: Vec<Snap>,
    time: f64,
    oracle: Option<Oracle>,
    pub penetration: f64,
}

impl Probe {
    pub fn new(case: &Case, scene: &Scene, initial: &[Snap]) -> Probe {
        let oracle = case.has_contacts().then(|| Oracle::new(scene));
        Probe::with_oracle(case, scene, initial, oracle)
    }

    /// The same probe with a given overlap oracle (`None`: overlaps not
    /// measured).
    pub fn with_oracle(
        case: &Case,
        scene: &Scene,
        initial: &[Snap],
        oracle: Option<Oracle>,
    ) -> Probe {
        let e0: f64 = (0..initial.len())
            .map(|i| kinetic_energy(scene, i, &initial[i]))
            .sum();
        let l0 = if initial.is_empty() {
            0.0
        } else {
            angular_momentum(scene, initial.len() - 1, &initial[initial.len() - 1]).norm()
        };
        Probe {
            kind: case.kind,
            scene: scene.clone(),
            initial: initial.to_vec(),
            e0,
            l0,
            worst_e: 0.0,
            worst_l: 0.0,
            prev_vz: 0.0,
            apexes: Vec::new(),
            impacts: Vec::new(),
            last: initial.to_vec(),
            time: 0.0,
            oracle,
            penetration: 0.0,
        }
    }

    /// After each step, at simulated time `t`.
    pub fn observe(&mut self, t: f64, snaps: &[Snap]) {
        self.time = t;
        if let Some(o) = &self.oracle {
            self.penetration = self.penetration.max(o.deepest(snaps));
        }
        match self.kind {
            Kind::Tumbling => {
                let e = kinetic_energy(&self.scene, 0, &snaps[0]);
                let l = angular_momentum(&self.scene, 0, &snaps[0]).norm();
                self.worst_e = self.worst_e.max(((e - self.e0) / self.e0).abs());
                self.worst_l = self.worst_l.max(((l - self.l0) / self.l0).abs());
            }
            Kind::Bounce => {
                let s = &snaps[1];
                let (z, vz) = (s.position.z - 0.05, s.velocity.z);
                if self.prev_vz < 0.0 && vz > 0.0 {
                    // Bounced in this step: back along the free parabola
                    // z + vz τ − ½ g τ² to the floor (τ < 0).
                    let tau = (vz - (vz * vz + 2.0 * G * z.max(0.0)).sqrt()) / G;
                    self.impacts.push(t + tau);
                }
                if self.prev_vz > 0.0 && vz <= 0.0 {
                    // Apex inside this step: z + vz²/2g is exact on the parabola.
                    self.apexes.push(z + vz * vz / (2.0 * G));
                }
                self.prev_vz = vz;
            }
            _ => {}
        }
        self.last.clear();
        self.last.extend_from_slice(snaps);
    }

    /// The case's errors, in the order of `Case::metrics`. NaN: not measurable
    /// (e.g. fewer bounces than the exact answer has).
    pub fn finish(&self) -> Vec<f64> {
        let s = &self.last;
        let t = self.time;
        match self.kind {
            Kind::Projectile => {
                let exact = Vector3::new(t, 0.0, 5.0 * t - 0.5 * G * t * t);
                vec![(s[0].position - exact).norm()]
            }
            Kind::Tumbling => vec![self.worst_e, self.worst_l],
            Kind::Bounce => {
                let (e, h0) = (BOUNCE_E, 1.0);
                let v1 = (2.0 * G * h0).sqrt();
                let mut exact_impacts = vec![v1 / G];
                for k in 1..5 {
                    let last = *exact_impacts.last().unwrap();
                    exact_impacts.push(last + 2.0 * e.powi(k) * v1 / G);
                }
                let apex = if self.apexes.len() >= 4 {
                    (1..=4)
                        .map(|k| {
                            let want = e.powi(2 * k as i32) * h0;
                            ((self.apexes[k - 1] - want) / want).abs()
                        })
                        .fold(0.0, f64::max)
                } else {
                    f64::NAN
                };
                let impact = if self.impacts.len() >= 4 {
                    (0..4)
                        .map(|k| (self.impacts[k] - exact_impacts[k]).abs())
                        .fold(0.0, f64::max)
                } else {
                    f64::NAN
                };
                vec![apex, impact, self.penetration]
            }
            Kind::Exchange => {
                let ea = (s[0].velocity - Vector3::new(-0.5, 0.0, 0.0)).norm();
                let eb = (s[1].velocity - Vector3::new(1.0, 0.0, 0.0)).norm();
                vec![ea.max(eb), self.penetration]
            }
            Kind::Cradle => {
                // One simultaneous LCP: (−1/3, 2/3, 2/3)·v; sequential pairwise
                // impacts (the toy): (0, 0, v). Both conserve momentum and energy.
                let v = 1.0;
                let lcp = [-v / 3.0, 2.0 * v / 3.0, 2.0 * v / 3.0];
                let seq = [0.0, 0.0, v];
                let err = |want: &[f64; 3]| {
                    (0..3)
                        .map(|i| (s[i].velocity - Vector3::new(want[i], 0.0, 0.0)).norm())
                        .fold(0.0, f64::max)
                };
                let e: f64 = (0..3).map(|i| kinetic_energy(&self.scene, i, &s[i])).sum();
                vec![
                    err(&lcp),
                    err(&seq),
                    ((e - self.e0) / self.e0).abs(),
                    self.penetration,
                ]
            }
            Kind::Stack => {
                let drift = (1..s.len())
                    .map(|i| (s[i].position - self.initial[i].position).norm())
                    .fold(0.0, f64::max);
                vec![drift, self.penetration]
            }
            Kind::Sliding => {
                // Slides from rest along +x at a = g (sin 30° − μ cos 30°):
                // x = ½ a t².
                let a_exact = G * (0.5 - SLIDE_MU * 3f64.sqrt() / 2.0);
                let d = s[1].position - self.initial[1].position;
                let a = 2.0 * d.x / (t * t);
                vec![((a - a_exact) / a_exact).abs(), d.y.abs(), self.penetration]
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Measurement.

/// One point of a work-precision curve.
#[derive(Clone, Debug)]
pub struct Point {
    pub case: &'static str,
    pub config: String,
    pub dt: f64,
    pub steps: u64,
    pub sim_time: f64,
    /// Wall seconds of each timed run (stepping only).
    pub walls: Vec<f64>,
    /// Slowest single step of each timed run.
    pub worst_steps: Vec<f64>,
    pub metrics: Vec<(&'static str, &'static str, f64)>,
    pub failure: Option<String>,
}

pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(|a, b| a.total_cmp(b));
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

impl Point {
    pub fn wall(&self) -> f64 {
        median(&self.walls)
    }
    pub fn realtime_factor(&self) -> f64 {
        self.sim_time / self.wall()
    }
    pub fn metric(&self, name: &str) -> f64 {
        self.metrics
            .iter()
            .find(|m| m.0 == name)
            .map_or(f64::NAN, |m| m.2)
    }
}

pub fn steps_for(duration: f64, dt: f64) -> u64 {
    (duration / dt - 1e-9).ceil() as u64
}

/// Probe run (errors), then `reps` timed runs; the probe run doubles as the
/// warm-up. `make` builds a fresh engine on the case's scene at `dt`.
pub fn measure(
    case: &Case,
    config: &str,
    dt: f64,
    reps: usize,
    make: &mut dyn FnMut(Scene) -> Box<dyn Engine>,
) -> Point {
    let scene = case.scene(dt);
    let steps = steps_for(case.duration, dt);
    let mut point = Point {
        case: case.name,
        config: config.to_string(),
        dt,
        steps,
        sim_time: steps as f64 * dt,
        walls: Vec::new(),
        worst_steps: Vec::new(),
        metrics: Vec::new(),
        failure: None,
    };
    // Probe run.
    let mut engine = make(scene.clone());
    let mut snaps = Vec::new();
    engine.snaps(&mut snaps);
    let mut probe = Probe::new(case, &scene, &snaps);
    for k in 1..=steps {
        if let Err(e) = engine.step() {
            point.failure = Some(e);
            break;
        }
        engine.snaps(&mut snaps);
        probe.observe(k as f64 * dt, &snaps);
    }
    let values = probe.finish();
    point.metrics = case
        .metrics
        .iter()
        .zip(values)
        .map(|(&(n, u), v)| (n, u, if point.failure.is_some() { f64::NAN } else { v }))
        .collect();
    if point.failure.is_some() {
        return point;
    }
    // Timed runs.
    for _ in 0..reps {
        let mut engine = make(scene.clone());
        let mut worst: f64 = 0.0;
        let mut total = 0.0;
        for _ in 0..steps {
            let clock = Instant::now();
            let r = engine.step();
            let s = clock.elapsed().as_secs_f64();
            total += s;
            worst = worst.max(s);
            if let Err(e) = r {
                point.failure = Some(e);
                return point;
            }
        }
        point.walls.push(total);
        point.worst_steps.push(worst);
    }
    point
}

pub const CSV_HEADER: &str = "case,config,dt_s,steps,sim_time_s,runs,wall_median_s,wall_min_s,wall_max_s,realtime_factor,worst_step_s,metric,unit,value,failure";

/// Long format: one row per (point, metric).
pub fn csv_rows(points: &[Point]) -> String {
    let mut out = String::new();
    for p in points {
        let min = p.walls.iter().copied().fold(f64::INFINITY, f64::min);
        let max = p.walls.iter().copied().fold(0.0, f64::max);
        for (m, unit, v) in &p.metrics {
            let _ = writeln!(
                out,
                "{},{},{:e},{},{},{},{:e},{:e},{:e},{:e},{:e},{},{},{:e},{}",
                p.case,
                p.config,
                p.dt,
                p.steps,
                p.sim_time,
                p.walls.len(),
                p.wall(),
                min,
                max,
                p.realtime_factor(),
                median(&p.worst_steps),
                m,
                unit,
                v,
                p.failure.as_deref().unwrap_or("").replace(',', ";")
            );
        }
    }
    out
}

/// The machine's folder name under bench/results: `$BENCH_MACHINE`, else
/// `<host name>-<cores>cpu`.
pub fn machine_name() -> String {
    std::env::var("BENCH_MACHINE")
        .ok()
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| {
            let host = std::fs::read_to_string("/etc/hostname")
                .ok()
                .map(|s| s.trim().to_string())
                .filter(|s| !s.is_empty())
                .unwrap_or_else(|| "unknown".into());
            let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
            format!("{host}-{cores}cpu")
        })
}

/// One line about the machine for the CSV's companion `machine.txt`.
pub fn machine_description() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!("{cpu}, {cores} cores available")
}

/// A pose as nalgebra's isometry (for engines that want one).
pub fn isometry(s: &Snap) -> Isometry3<f64> {
    Isometry3::from_parts(s.position.into(), s.orientation)
}

/// Exact zeros drawn at 1e-16 on a log axis (NaN stays out of the plot).
pub fn floor_zero(v: f64) -> f64 {
    if v.is_nan() { v } else { v.max(1e-16) }
}

/// An error for a table: "n/a" when not measurable, "0" when exact.
pub fn fmt_err(v: f64) -> String {
    if v.is_nan() {
        "n/a".into()
    } else if v == 0.0 {
        "0".into()
    } else {
        format!("{v:.2e}")
    }
}

/// Reads back a CSV written by `csv_rows` (to redraw plots without measuring
/// again). Timings come back as the median only.
pub fn read_csv(text: &str) -> Vec<Point> {
    let cases = cases();
    let mut points: Vec<Point> = Vec::new();
    for line in text.lines().skip(1) {
        let c: Vec<&str> = line.split(',').collect();
        if c.len() < 15 {
            continue;
        }
        let Some(case) = cases.iter().find(|k| k.name == c[0]) else {
            continue;
        };
        let num = |i: usize| c[i].parse::<f64>().unwrap_or(f64::NAN);
        let dt = num(2);
        let Some(&(name, unit)) = case.metrics.iter().find(|m| m.0 == c[11]) else {
            continue;
        };
        let same = |p: &Point| p.case == case.name && p.config == c[1] && p.dt == dt;
        if !points.last().is_some_and(same) {
            points.push(Point {
                case: case.name,
                config: c[1].to_string(),
                dt,
                steps: num(3) as u64,
                sim_time: num(4),
                walls: vec![num(6)],
                worst_steps: vec![num(10)],
                metrics: Vec::new(),
                failure: (!c[14].is_empty()).then(|| c[14].to_string()),
            });
        }
        if let Some(p) = points.last_mut() {
            p.metrics.push((name, unit, num(13)));
        }
    }
    points
}
