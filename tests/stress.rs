//! Numerical stability under stress (issue 8): the short, CI-sized versions
//! of the cases in docs/stability.md. `scripts/stress.sh` runs the heavy
//! settings (20 s stacks, 10 000 s runs, crowds of 200 and 1000) through the
//! binary and prints a table.
//!
//! Every case checks, every step: no NaN or infinity; the largest overlap the
//! step left (`Diagnostics::max_penetration`) below `CONTACT_TOLERANCE` (10 µm)
//! unless a bound is stated; no body through another (a floor, a wall, a
//! container, the other body of a head-on pair); no energy gain beyond the
//! work done (kinetic plus gravitational energy never above its start, to a
//! stated rounding bound, for scenes where only gravity acts); and, where
//! there is one, the exact answer (contact forces k·m·g, velocities after a
//! collision, a position that must not change).

mod common;

use common::world;
use nalgebra::{UnitQuaternion, Vector3};
use proptest::prelude::*;
use rigidsim::body::Activity;
use rigidsim::collision::narrowphase::CONTACT_TOLERANCE;
use rigidsim::step::{EVENTS_PER_BODY, Inline, World};
use std::fmt::Write as _;

const G: f64 = 9.81;
/// How far the top of the iteratively solved stack of twenty may sink and
/// sway in 2 s, warm-started or from zero: 1 µm, as the exact method's
/// stacks are held (`check_stack`); 0.10 µm and 0.04 µm measured since the
/// subspace step. Before it, sweeps alone sank it 2.9 µm
/// warm-started and 25.8 µm from zero, and it swayed about 3 mm.
const ITERATIVE_SINK: f64 = 1e-6;
const ITERATIVE_SWAY: f64 = 1e-6;

// ------------------------------------------------------------------ helpers

/// The invariants of one run, updated after every step.
struct Watch {
    /// Energy at the start and the largest gain over it seen (J).
    e0: f64,
    gain: f64,
    /// Energy after the last step, and the largest rise in one step (J):
    /// with gravity the only force and restitution ≤ 1, no step may add
    /// energy (an impact or a resting solve only removes it).
    last: f64,
    rise: f64,
    /// When that largest rise happened.
    rise_at: f64,
    /// Largest |quaternion norm − 1| seen.
    quat: f64,
    /// When the largest overlap first exceeded the contact tolerance.
    first_over: Option<f64>,
}

impl Watch {
    fn new(w: &World) -> Watch {
        Watch {
            e0: w.energy(),
            gain: 0.0,
            last: w.energy(),
            rise: 0.0,
            rise_at: 0.0,
            quat: 0.0,
            first_over: None,
        }
    }

    /// One step, then the checks that hold for every case.
    fn step(&mut self, w: &mut World, exec: &mut Inline) {
        w.step(exec)
            .unwrap_or_else(|e| panic!("{e} (step {})", w.state.steps));
        for (i, b) in w.state.bodies.iter().enumerate() {
            let s = &b.state;
            let finite = s.position.iter().all(|x| x.is_finite())
                && s.velocity.iter().all(|x| x.is_finite())
                && s.angular_momentum.iter().all(|x| x.is_finite())
                && s.orientation.coords.iter().all(|x| x.is_finite());
            assert!(finite, "body {i} not finite at t = {}", w.time());
            self.quat = self
                .quat
                .max((s.orientation.quaternion().norm() - 1.0).abs());
        }
        let e = w.energy();
        self.gain = self.gain.max(e - self.e0);
        if e - self.last > self.rise {
            self.rise = e - self.last;
            self.rise_at = w.time();
        }
        self.last = e;
        if self.first_over.is_none() && w.diagnostics.max_penetration > CONTACT_TOLERANCE {
            self.first_over = Some(w.time());
        }
    }

    fn run_until(&mut self, w: &mut World, exec: &mut Inline, t: f64) {
        while w.time() < t - 1e-9 {
            self.step(w, exec);
        }
    }
}

/// World positions of every hull vertex of body `i`.
fn vertices(w: &World, i: usize) -> Vec<Vector3<f64>> {
    w.object(i)
        .parts
        .iter()
        .flat_map(|p| p.hull.vertices().iter())
        .map(|v| w.world_point(i, *v))
        .collect()
}

fn lowest(w: &World, i: usize) -> f64 {
    vertices(w, i)
        .iter()
        .map(|v| v.z)
        .fold(f64::INFINITY, f64::min)
}

fn q(axis: Vector3<f64>, angle: f64) -> String {
    let q = UnitQuaternion::from_axis_angle(&nalgebra::Unit::new_normalize(axis), angle);
    format!("[{}, {}, {}, {}]", q.w, q.i, q.j, q.k)
}

fn floor(restitution: f64, friction: f64) -> String {
    format!(
        r#"
[objects.floor]
shape = {{ box = {{ half_extents = [5.0, 5.0, 0.1] }} }}
mass = 1.0
restitution = {restitution}
friction = {friction}
[[bodies]]
object = "floor"
position = [0.0, 0.0, -0.1]
fixed = true
"#
    )
}

fn cube_object(name: &str, half: f64, mass: f64, restitution: f64, friction: f64) -> String {
    format!(
        "[objects.{name}]\nshape = {{ box = {{ half_extents = [{half}, {half}, {half}] }} }}\n\
         mass = {mass}\nrestitution = {restitution}\nfriction = {friction}\n"
    )
}

fn body(object: &str, p: [f64; 3], extra: &str) -> String {
    format!(
        "[[bodies]]\nobject = \"{object}\"\nposition = [{}, {}, {}]\n{extra}\n",
        p[0], p[1], p[2]
    )
}

/// Total normal force of the last contact solve on each touching pair.
fn pair_force(w: &World, a: usize, b: usize) -> f64 {
    w.diagnostics
        .last_pair_forces
        .iter()
        .filter(|(x, y, _)| (x.index(), y.index()) == (a.min(b), a.max(b)))
        .map(|(_, _, f)| f)
        .sum()
}

fn assert_rel(got: f64, want: f64, rel: f64, what: &str) {
    assert!(
        (got - want).abs() <= rel * want.abs(),
        "{what}: {got} vs {want} (relative error {:e}, allowed {rel:e})",
        ((got - want) / want).abs()
    );
}

fn assert_penetration(w: &World, bound: f64, what: &str) {
    assert!(
        w.diagnostics.max_penetration <= bound,
        "{what}: max penetration {:e} m above {bound:e} m",
        w.diagnostics.max_penetration
    );
}

// ------------------------------------------------------------------ stacks

/// n unit cubes (0.2 m, 1 kg, μ = 0.6, e = 0) on the floor, resting systems
/// off so that every step solves the whole stack.
fn stack(masses: &[f64]) -> World {
    let mut s = format!("[world]\ndt = 0.01\nduration = 100.0\n{}", floor(0.0, 0.6));
    for (i, m) in masses.iter().enumerate() {
        s += &cube_object(&format!("c{i}"), 0.1, *m, 0.0, 0.6);
        s += &body(&format!("c{i}"), [0.0, 0.0, 0.1 + 0.2 * i as f64], "");
    }
    let mut w = world(&s);
    w.settings.sleep_enabled = false;
    w
}

/// Stands for `seconds`: the top moves ≤ 1 mm (in fact ≤ `drift_max`), the
/// force under the k-th cube from the top is k·m·g to `force_error_max`,
/// nothing sinks, no energy is gained.
fn check_stack(n: usize, seconds: f64, drift_max: f64, force_error_max: f64) {
    let mut w = stack(&vec![1.0; n]);
    let top0 = w.state.bodies[n].state.position;
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    let mut worst_force: f64 = 0.0;
    while w.time() < seconds - 1e-9 {
        watch.step(&mut w, &mut exec);
        for k in 1..=n {
            let want = (n + 1 - k) as f64 * G;
            let f = pair_force(&w, k - 1, k);
            worst_force = worst_force.max(((f - want) / want).abs());
        }
    }
    let drift = (w.state.bodies[n].state.position - top0).norm();
    println!(
        "stack of {n}: {seconds} s, top drift {drift:.3e} m, force error {worst_force:.1e}, \
         penetration {:.1e} m, energy gain {:.1e} J, LCP failures {}",
        w.diagnostics.max_penetration, watch.gain, w.diagnostics.counters.solve.failed
    );
    assert!(drift <= 1e-3, "top drifted {drift:e} m");
    assert!(
        drift <= drift_max,
        "top drifted {drift:e} m ({drift_max:e} expected)"
    );
    assert!(
        worst_force <= force_error_max,
        "contact force error {worst_force:e}"
    );
    assert_penetration(&w, CONTACT_TOLERANCE, "stack");
    assert!(
        watch.gain <= 1e-9 * n as f64,
        "energy gain {:e} J",
        watch.gain
    );
    assert!(
        w.diagnostics.counters.solve.failed == 0,
        "{:?}",
        w.diagnostics.counters.solve.failures
    );
}

#[test]
fn stack_of_ten_boxes_stands_for_5_s() {
    check_stack(10, 5.0, 1e-6, 1e-6);
}

#[test]
fn stack_of_twenty_boxes_stands_for_3_s() {
    check_stack(20, 3.0, 1e-6, 1e-6);
}

/// The stack of fifty: its 600–800-row islands are solved iteratively with
/// the subspace step (Dantzig's method failed on them 100 times in 5 s and
/// took 242 s). Measured: top drift 1.2 µm, force error 2.5e-6 (the solve's
/// 1e-9 compliance over a 50-body chain), no energy gained, no failure;
/// asserted: 5 µm and 1e-5.
#[test]
fn stack_of_fifty_boxes_stands_for_5_s() {
    check_stack(50, 5.0, 5e-6, 1e-5);
}

/// The stack of twenty solved by sequential impulses (its 240-row island
/// is made iterative by lowering `iterative_min_rows`; islands of 300 rows
/// or more are solved so). With the subspace step the solve carries the
/// whole load whether it starts from last step's forces or from zero: over
/// 2 s the top sinks less than `ITERATIVE_SINK` and sways less than
/// `ITERATIVE_SWAY`, as Dantzig's method holds it, and nothing overlaps past
/// the contact tolerance. A checkpoint taken at 1 s resumes to the same
/// state, so the forces the next solve starts from are kept in it.
#[test]
fn stack_solved_iteratively_holds_warm_or_cold() {
    let n = 20;
    let iterative = |warm: bool| {
        let mut w = stack(&vec![1.0; n]);
        w.settings.warm_start = warm;
        w.settings.iterative_min_rows = 100;
        w
    };
    let run = |warm: bool| {
        let mut w = iterative(warm);
        let top0 = w.state.bodies[n].state.position;
        let mut exec = Inline::default();
        let (mut sink, mut sideways): (f64, f64) = (0.0, 0.0);
        let mut half = None;
        while w.time() < 2.0 - 1e-9 {
            w.step(&mut exec).unwrap();
            let d = w.state.bodies[n].state.position - top0;
            sink = sink.max(-d.z);
            sideways = sideways.max(d.xy().norm());
            if w.state.steps == 100 {
                half = Some(w.checkpoint());
            }
        }
        (w, sink, sideways, half.unwrap())
    };
    let (warm, sink, sideways, half) = run(true);
    let (cold, cold_sink, cold_sideways, _) = run(false);
    println!(
        "stack of {n}, iterative: top sank {sink:.2e} m warm, {cold_sink:.2e} m cold; \
         sideways {sideways:.2e} m warm, {cold_sideways:.2e} m cold; penetration \
         {:.3e} m warm, {:.3e} m cold; {} iterative solves, {} unconverged",
        warm.diagnostics.max_penetration,
        cold.diagnostics.max_penetration,
        warm.diagnostics.counters.solve.iterative_solves,
        warm.diagnostics.counters.solve.iterative_unconverged
    );
    for (w, sink, sideways, start) in [
        (&warm, sink, sideways, "warm"),
        (&cold, cold_sink, cold_sideways, "cold"),
    ] {
        assert!(
            w.diagnostics.counters.solve.iterative_solves > 0
                && w.diagnostics.counters.solve.lcp_solves == 0,
            "{start}: not solved iteratively"
        );
        assert!(sink <= ITERATIVE_SINK, "{start}: top sank {sink:e} m");
        assert!(
            sideways <= ITERATIVE_SWAY,
            "{start}: top swayed {sideways:e} m"
        );
        assert_penetration(w, CONTACT_TOLERANCE, start);
    }
    let mut resumed = World::restore(iterative(true).scene, half).unwrap();
    resumed.settings.iterative_min_rows = 100;
    let mut exec = Inline::default();
    while resumed.state.steps < warm.state.steps {
        resumed.step(&mut exec).unwrap();
    }
    assert_eq!(
        resumed.state_hash(),
        warm.state_hash(),
        "resumed stack differs"
    );
}

/// Rows of 5, 4, 3, 2, 1 cubes (0.2 m, 1 kg, μ = 0.6), 2 cm apart in each
/// row, each cube resting on two below, resting systems off.
fn pyramid() -> World {
    let mut s = format!("[world]\ndt = 0.01\nduration = 100.0\n{}", floor(0.0, 0.6));
    s += &cube_object("cube", 0.1, 1.0, 0.0, 0.6);
    let pitch = 0.22;
    for row in 0..5 {
        let count = 5 - row;
        for k in 0..count {
            let x = (k as f64 - (count - 1) as f64 / 2.0) * pitch;
            s += &body("cube", [x, 0.0, 0.1 + 0.2 * row as f64], "");
        }
    }
    let mut w = world(&s);
    w.settings.sleep_enabled = false;
    w
}

/// The pyramid stands for 3 s: the top drifts ≤ 1 mm, the floor carries the
/// 15 cubes' weight (1e-6), overlaps stay within the contact tolerance.
#[test]
fn pyramid_of_fifteen_boxes_stands_for_3_s() {
    let mut w = pyramid();
    let top = w.state.bodies.len() - 1;
    let start: Vec<_> = w.state.bodies.iter().map(|b| b.state.position).collect();
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    watch.run_until(&mut w, &mut exec, 3.0);
    let floor_force: f64 = (1..=5).map(|i| pair_force(&w, 0, i)).sum();
    let drift = (w.state.bodies[top].state.position - start[top]).norm();
    let worst = (1..w.state.bodies.len())
        .map(|i| (w.state.bodies[i].state.position - start[i]).norm())
        .fold(0.0, f64::max);
    println!(
        "pyramid: top drift {drift:.2e} m, largest move {worst:.2e} m, floor force {floor_force} N \
         (15 m g = {}), penetration {:.1e}, energy gain {:.1e} J, LCP failures {}",
        15.0 * G,
        w.diagnostics.max_penetration,
        watch.gain,
        w.diagnostics.counters.solve.failed
    );
    assert!(drift <= 1e-3, "top drifted {drift:e} m");
    assert_rel(floor_force, 15.0 * G, 1e-6, "floor force");
    assert_penetration(&w, CONTACT_TOLERANCE, "pyramid");
}

/// The pyramid, strictly: every contact solve succeeds (no projected
/// Gauss-Seidel fallback), nothing moves more than 1 µm and no energy is
/// gained. Until the compliant retry (`contact::solver`), the exact LCP
/// failed with "negative pivot … A is not positive semidefinite" from
/// t = 1.0 s and the fallback lifted the pyramid (+1.75e-5 J, 51 µm by 3 s).
#[test]
fn pyramid_of_fifteen_boxes_needs_no_lcp_fallback_and_gains_no_energy() {
    let mut w = pyramid();
    let start: Vec<_> = w.state.bodies.iter().map(|b| b.state.position).collect();
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    watch.run_until(&mut w, &mut exec, 3.0);
    let worst = (1..w.state.bodies.len())
        .map(|i| (w.state.bodies[i].state.position - start[i]).norm())
        .fold(0.0, f64::max);
    assert!(
        w.diagnostics.counters.solve.failed == 0,
        "{} LCP failures, first: {:?}",
        w.diagnostics.counters.solve.failed,
        w.diagnostics.counters.solve.failures.first()
    );
    assert!(worst <= 1e-6, "a cube moved {worst:e} m");
    assert!(watch.gain <= 1e-8, "energy gain {:e} J", watch.gain);
}

// ------------------------------------------------------------------ mass ratios

/// Heavy on light (1 kg under 1000 kg and under 10 000 kg) and light between
/// heavies: the forces are the exact weights above each contact (1e-6), no
/// cube moves more than 1 µm in 3 s.
#[test]
fn mass_ratios_of_1000_and_10000_hold_with_exact_contact_forces() {
    for ratio in [1e3, 1e4] {
        for masses in [vec![1.0, ratio], vec![ratio, 1.0, ratio]] {
            let mut w = stack(&masses);
            let start: Vec<_> = w.state.bodies.iter().map(|b| b.state.position).collect();
            let mut exec = Inline::default();
            let mut watch = Watch::new(&w);
            let mut worst: f64 = 0.0;
            while w.time() < 3.0 - 1e-9 {
                watch.step(&mut w, &mut exec);
                for k in 1..=masses.len() {
                    let want: f64 = masses[k - 1..].iter().sum::<f64>() * G;
                    worst = worst.max(((pair_force(&w, k - 1, k) - want) / want).abs());
                }
            }
            let moved = (1..w.state.bodies.len())
                .map(|i| (w.state.bodies[i].state.position - start[i]).norm())
                .fold(0.0, f64::max);
            println!(
                "masses {masses:?}: force error {worst:.1e}, largest move {moved:.1e} m, \
                 penetration {:.1e} m",
                w.diagnostics.max_penetration
            );
            assert!(worst <= 1e-6, "{masses:?}: force error {worst:e}");
            assert!(moved <= 1e-6, "{masses:?}: moved {moved:e} m");
            assert_penetration(&w, CONTACT_TOLERANCE, "mass ratio");
            assert!(
                watch.gain <= 1e-9 * ratio,
                "{masses:?}: energy gain {:e}",
                watch.gain
            );
        }
    }
}

// ------------------------------------------------------------------ fast bodies

/// A 10 cm cube at 100 and 1000 m/s at a fixed wall 1 cm thick, face on
/// (exact rebound −e·v) and tilted (a corner hits first): it never reaches
/// past the wall's near face by more than the contact tolerance, and leaves
/// with no more kinetic energy than it came with.
#[test]
fn fast_cubes_at_100_and_1000_m_s_do_not_pass_a_1_cm_wall() {
    for speed in [100.0, 1000.0] {
        for tilted in [false, true] {
            let orientation = if tilted {
                q(Vector3::new(0.3, 1.0, 0.6), 0.7)
            } else {
                "[1.0, 0.0, 0.0, 0.0]".into()
            };
            // The tilted cube's rebound carries it below z = −1 m: fall_z is
            // the default it had before issue 23, so the run is the same.
            let text = format!(
                "[world]\ngravity = [0.0, 0.0, 0.0]\ndt = 0.01\nduration = 1.0\nfall_z = -1.0\n\
                 [objects.wall]\nshape = {{ box = {{ half_extents = [0.005, 1.0, 1.0] }} }}\n\
                 mass = 1.0\nrestitution = 0.5\nfriction = 0.3\n{}{}{}",
                body("wall", [1.0, 0.0, 0.0], "fixed = true"),
                cube_object("cube", 0.05, 1.0, 0.5, 0.3),
                body(
                    "cube",
                    [0.0, 0.0, 0.0],
                    &format!("velocity = [{speed}, 0.0, 0.0]\norientation = {orientation}")
                ),
            );
            let mut w = world(&text);
            let mut exec = Inline::default();
            let mut watch = Watch::new(&w);
            let face = 1.0 - 0.005;
            let mut reach = f64::NEG_INFINITY;
            while w.time() < 0.05 - 1e-9 {
                watch.step(&mut w, &mut exec);
                let front = vertices(&w, 1).iter().map(|v| v.x).fold(f64::MIN, f64::max);
                reach = reach.max(front - face);
                assert!(
                    front <= face + CONTACT_TOLERANCE,
                    "{speed} m/s (tilted {tilted}): front at {front} past the wall face {face} \
                     at t = {}",
                    w.time()
                );
            }
            let v = w.state.bodies[1].state.velocity;
            println!(
                "{speed} m/s, tilted {tilted}: v after {:?}, deepest reach {reach:.1e} m, \
                 penetration {:.1e}, energy gain {:.1e} J",
                v.as_slice(),
                w.diagnostics.max_penetration,
                watch.gain
            );
            assert!(v.x < 0.0, "no rebound: {v:?}");
            if !tilted {
                assert_rel(v.x, -0.5 * speed, 1e-9, "rebound velocity");
                assert!(v.yz().norm() <= 1e-9 * speed);
            }
            assert_penetration(&w, CONTACT_TOLERANCE, "fast cube");
            assert!(
                watch.gain <= 1e-9 * 0.5 * speed * speed,
                "energy gain {:e}",
                watch.gain
            );
        }
    }
}

/// Two cubes closing at 1000 m/s (±500, e = 1, equal masses) swap velocities;
/// 1 kg at 1000 m/s into 10 kg at −100 m/s (e = 0.5) leave with the 1-D
/// answer. Their order along x never changes.
#[test]
fn fast_cubes_head_on_give_the_exact_one_dimensional_answer() {
    for (m1, v1, m2, v2, e) in [
        (1.0, 500.0, 1.0, -500.0, 1.0),
        (1.0, 1000.0, 10.0, -100.0, 0.5),
    ] {
        let text = format!(
            "[world]\ngravity = [0.0, 0.0, 0.0]\ndt = 0.01\nduration = 1.0\n{}{}{}{}",
            cube_object("a", 0.05, m1, e, 0.3),
            cube_object("b", 0.05, m2, e, 0.3),
            body(
                "a",
                [-1.0, 0.0, 0.0],
                &format!("velocity = [{v1}, 0.0, 0.0]")
            ),
            body(
                "b",
                [1.0, 0.0, 0.0],
                &format!("velocity = [{v2}, 0.0, 0.0]")
            ),
        );
        let mut w = world(&text);
        let mut exec = Inline::default();
        let mut watch = Watch::new(&w);
        while w.time() < 0.03 - 1e-9 {
            watch.step(&mut w, &mut exec);
            let (xa, xb) = (
                w.state.bodies[0].state.position.x,
                w.state.bodies[1].state.position.x,
            );
            assert!(
                xb - xa >= 0.1 - CONTACT_TOLERANCE,
                "passed through each other at t = {}: {xa} {xb}",
                w.time()
            );
        }
        let p = m1 * v1 + m2 * v2;
        let want1 = (p + m2 * e * (v2 - v1)) / (m1 + m2);
        let want2 = (p + m1 * e * (v1 - v2)) / (m1 + m2);
        let (got1, got2) = (
            w.state.bodies[0].state.velocity.x,
            w.state.bodies[1].state.velocity.x,
        );
        println!(
            "head-on {m1} kg at {v1} vs {m2} kg at {v2}, e {e}: {got1} / {got2} (want {want1} / {want2})"
        );
        assert!((got1 - want1).abs() <= 1e-9 * v1.abs(), "{got1} vs {want1}");
        assert!((got2 - want2).abs() <= 1e-9 * v1.abs(), "{got2} vs {want2}");
        assert_penetration(&w, CONTACT_TOLERANCE, "head-on");
        assert!(
            watch.gain <= 1e-9 * 0.5 * m1 * v1 * v1,
            "energy gain {:e}",
            watch.gain
        );
    }
}

// ------------------------------------------------------------------ degenerate contacts

/// A cube dropped exactly face-aligned on an equal fixed cube (coincident
/// faces, edges and corners): it lands flat, does not turn or slide, and
/// rests on top within the contact tolerance; bouncing (e = 0.5) or not.
#[test]
fn face_aligned_drop_lands_flat_without_turning() {
    for e in [0.0, 0.5] {
        let text = format!(
            "[world]\ndt = 0.01\nduration = 10.0\n{}{}{}{}",
            cube_object("base", 0.1, 1.0, e, 0.5),
            cube_object("cube", 0.1, 1.0, e, 0.5),
            body("base", [0.0, 0.0, 0.1], "fixed = true"),
            body("cube", [0.0, 0.0, 0.6], ""),
        );
        let mut w = world(&text);
        let mut exec = Inline::default();
        let mut watch = Watch::new(&w);
        let mut lowest_bottom = f64::INFINITY;
        while w.time() < 3.0 - 1e-9 {
            watch.step(&mut w, &mut exec);
            lowest_bottom = lowest_bottom.min(lowest(&w, 1));
        }
        let s = w.state.bodies[1].state;
        let turn = s.orientation.angle();
        println!(
            "face-aligned drop e = {e}: rest z {}, xy {:.1e}, turned {turn:.1e} rad, \
             lowest bottom {lowest_bottom}, asleep {}",
            s.position.z,
            s.position.xy().norm(),
            w.state.bodies[1].activity == Activity::Sleeping
        );
        assert!(s.position.xy().norm() <= 1e-9, "slid {:?}", s.position);
        assert!(turn <= 1e-9, "turned {turn:e} rad");
        assert!(
            (s.position.z - 0.3).abs() <= CONTACT_TOLERANCE,
            "rests at z = {}",
            s.position.z
        );
        assert!(
            lowest_bottom >= 0.2 - CONTACT_TOLERANCE,
            "sank to {lowest_bottom}"
        );
        assert_penetration(&w, CONTACT_TOLERANCE, "face-aligned drop");
        assert!(watch.gain <= 1e-9 * 5.0, "energy gain {:e}", watch.gain);
    }
}

/// Edge on edge: a box turned 45° about x (edge down) dropped 5 cm onto a
/// fixed box turned 45° about x (edge up), the two edges parallel
/// (`parallel`), or with the falling box turned about y instead (`crossed`).
/// Whatever it does on the ridge (balance or fall off: the set-up is an
/// exactly symmetric, unstable equilibrium) it comes to rest, never inside
/// the ridge or the floor, with no energy gained. Returns the largest
/// overlap, when it first exceeded the tolerance, and the final height.
fn edge_on_edge(label: &str, falling: &str) -> (f64, Option<f64>, f64) {
    let ridge = q(Vector3::x(), std::f64::consts::FRAC_PI_4);
    let h = 0.1 * std::f64::consts::SQRT_2;
    let text = format!(
        "[world]\ndt = 0.01\nduration = 10.0\n{}{}{}{}{}",
        floor(0.3, 0.5),
        cube_object("ridge", 0.1, 1.0, 0.3, 0.5),
        cube_object("cube", 0.1, 1.0, 0.3, 0.5),
        body(
            "ridge",
            [0.0, 0.0, h],
            &format!("fixed = true\norientation = {ridge}")
        ),
        body(
            "cube",
            [0.0, 0.0, 2.0 * h + h + 0.05],
            &format!("orientation = {falling}")
        ),
    );
    let mut w = world(&text);
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    while w.time() < 4.0 - 1e-9 {
        watch.step(&mut w, &mut exec);
        assert!(
            lowest(&w, 2) >= -CONTACT_TOLERANCE,
            "{label}: through the floor"
        );
    }
    let s = w.state.bodies[2].state;
    println!(
        "edge on edge, {label}: ends at {:?}, {:?}, penetration {:.1e} m (over 10 µm from t = {:?}), \
         TOI events {}, gain {:.1e} J",
        s.position.as_slice(),
        w.state.bodies[2].activity,
        w.diagnostics.max_penetration,
        watch.first_over,
        w.diagnostics.counters.toi_events,
        watch.gain
    );
    assert!(
        watch.gain <= 1e-8,
        "{label}: energy gain {:e} J",
        watch.gain
    );
    assert!(w.at_rest(), "{label}: still moving after 4 s");
    (
        w.diagnostics.max_penetration,
        watch.first_over,
        s.position.z,
    )
}

/// Crossed edges meet at one point above the centre of mass: the exact
/// answer is to balance there, the cube's centre at three half-diagonals.
#[test]
fn crossed_edges_land_and_balance_on_the_point_they_cross() {
    let (pen, _, z) = edge_on_edge("crossed", &q(Vector3::y(), std::f64::consts::FRAC_PI_4));
    assert!(pen <= CONTACT_TOLERANCE, "penetration {pen:e} m");
    let want = 3.0 * 0.1 * std::f64::consts::SQRT_2;
    assert!(
        (z - want).abs() <= CONTACT_TOLERANCE,
        "rests at z = {z}, balance at {want}"
    );
}

/// Parallel edges: a segment of contact along the ridge. At 6fdb978 the
/// cube balances on it (as by symmetry it may); at 1b7540f it slid off,
/// and the overlap ratcheted up by up to `TOI_GAP` per impact event (25–30
/// events a step) from 3.8 µm at t = 0.20 s to 21 µm at 0.31 s. Since the
/// bisection places an impact where V-Clip finds the pair apart, nothing
/// ratchets.
#[test]
fn parallel_edges_land_and_come_to_rest_within_the_contact_tolerance() {
    let (pen, first, _) = edge_on_edge("parallel", &q(Vector3::x(), std::f64::consts::FRAC_PI_4));
    assert!(
        pen <= CONTACT_TOLERANCE,
        "penetration {pen:e} m (over from t = {first:?})"
    );
}

/// An upright cube dropped 1 cm off the top edge of a fixed cube turned 45°
/// about x: it lands on the edge, tips off to the side it overhangs, and
/// ends resting on the floor.
#[test]
fn cube_landing_on_an_edge_tips_off_and_rests_on_the_floor() {
    let h = 0.1 * std::f64::consts::SQRT_2;
    let text = format!(
        "[world]\ndt = 0.01\nduration = 10.0\n{}{}{}{}{}",
        floor(0.2, 0.5),
        cube_object("ridge", 0.1, 1.0, 0.2, 0.5),
        cube_object("cube", 0.1, 1.0, 0.2, 0.5),
        body(
            "ridge",
            [0.0, 0.0, h],
            &format!(
                "fixed = true\norientation = {}",
                q(Vector3::x(), std::f64::consts::FRAC_PI_4)
            )
        ),
        body("cube", [0.0, 0.01, 2.0 * h + 0.3], ""),
    );
    let mut w = world(&text);
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    while w.time() < 6.0 - 1e-9 && !(w.time() > 0.5 && w.at_rest()) {
        watch.step(&mut w, &mut exec);
        assert!(lowest(&w, 2) >= -CONTACT_TOLERANCE, "through the floor");
    }
    let s = w.state.bodies[2].state;
    println!(
        "cube on an edge: rests at {:?} after {} s, penetration {:.1e}, gain {:.1e}",
        s.position.as_slice(),
        w.time(),
        w.diagnostics.max_penetration,
        watch.gain
    );
    assert!(w.at_rest(), "still moving after 6 s");
    assert!(
        s.position.y > 0.1,
        "fell to the wrong side: {:?}",
        s.position
    );
    assert!(
        (s.position.z - 0.1).abs() <= 1e-4,
        "not flat on the floor: z = {}",
        s.position.z
    );
    assert!(lowest(&w, 2) >= -CONTACT_TOLERANCE);
    assert_penetration(&w, CONTACT_TOLERANCE, "edge landing");
    assert!(watch.gain <= 1e-8, "energy gain {:e} J", watch.gain);
}

/// A box pushed into the corner of two walls on a floor (4 + 4 + 4 coplanar
/// contacts, all redundant): it stops there and stays, with or without a
/// spin; the normal forces of the walls are zero once it rests.
#[test]
fn box_pushed_into_a_corner_stays_there() {
    for spin in [0.0, 5.0] {
        let text = format!(
            "[world]\ndt = 0.01\nduration = 10.0\n{}\
             [objects.wall]\nshape = {{ box = {{ half_extents = [0.5, 0.5, 0.5] }} }}\n\
             mass = 1.0\nrestitution = 0.0\nfriction = 0.5\n{}{}{}{}",
            floor(0.0, 0.5),
            body("wall", [-1.0, 0.0, 0.5], "fixed = true"),
            body("wall", [0.0, -1.0, 0.5], "fixed = true"),
            cube_object("cube", 0.1, 1.0, 0.0, 0.5),
            body(
                "cube",
                [-0.4, -0.4, 0.1],
                &format!("velocity = [-1.0, -1.0, 0.0]\nangular_velocity = [0.0, 0.0, {spin}]")
            ),
        );
        let mut w = world(&text);
        w.settings.sleep_enabled = false;
        let mut exec = Inline::default();
        let mut watch = Watch::new(&w);
        while w.time() < 3.0 - 1e-9 {
            watch.step(&mut w, &mut exec);
            let v = vertices(&w, 3);
            let (minx, miny) = v
                .iter()
                .fold((f64::MAX, f64::MAX), |(x, y), p| (x.min(p.x), y.min(p.y)));
            assert!(
                minx >= -0.5 - CONTACT_TOLERANCE && miny >= -0.5 - CONTACT_TOLERANCE,
                "into a wall"
            );
            assert!(lowest(&w, 3) >= -CONTACT_TOLERANCE, "into the floor");
        }
        let s = w.state.bodies[3].state;
        let wall_force = pair_force(&w, 1, 3) + pair_force(&w, 2, 3);
        println!(
            "corner, spin {spin}: rests at {:?}, speed {:.1e}, wall force {wall_force:.1e} N, \
             floor force {} N, penetration {:.1e}, LCP failures {}",
            s.position.as_slice(),
            s.velocity.norm(),
            pair_force(&w, 0, 3),
            w.diagnostics.max_penetration,
            w.diagnostics.counters.solve.failed
        );
        assert!(s.velocity.norm() <= 1e-9, "still moving: {:?}", s.velocity);
        assert_rel(pair_force(&w, 0, 3), G, 1e-6, "floor force");
        assert!(
            wall_force.abs() <= 1e-6,
            "walls push with {wall_force} N at rest"
        );
        assert_penetration(&w, CONTACT_TOLERANCE, "corner");
        assert!(watch.gain <= 1e-9, "energy gain {:e} J", watch.gain);
        if spin == 0.0 {
            let want = Vector3::new(-0.4, -0.4, 0.1);
            assert!(
                (s.position - want).norm() <= 1e-6,
                "moved to {:?}",
                s.position
            );
        }
    }
}

/// A bolt standing on the end of its shaft and wobbling on the end's
/// 40-gon rim, each rim corner landing in turn: body 140 of the 1000-body
/// floor pour at b405307, at 8 s, alone on the floor with its speed ×1.3.
/// Before 969fac5 (a new contact point's impact is placed where it lands)
/// a corner landing on a pair already overlapping was let sink as deep as
/// the pair's deepest point before its impact was placed,
/// and the overlap recovery then lifted it out again, a pump: at be8ea3e
/// this bolt still wobbled at 20 s, its energy climbing 1.03e-4 J back over
/// its lowest so far (1.14e-5 J in one step). Now each corner's impact is
/// placed where that corner lands: it rests at 2.84 s, climbing 3.9e-8 J.
#[test]
fn bolt_wobbling_on_its_rim_rests_without_pumping() {
    let (v, w) = (
        Vector3::new(-0.012_827_352, -0.031_279_977, 0.001_842_674) * 1.3,
        Vector3::new(0.932_761_376, -0.385_771_082, -0.099_210_942) * 1.3,
    );
    let scene = format!(
        "[world]\ndt = 0.01\nduration = 20.0\n{}\
         [objects.bolt]\nshape = {{ bolt = {{ head_across_flats = 0.03, head_height = 0.012, \
         shaft_radius = 0.009, shaft_length = 0.04, sides = 40 }} }}\n\
         density = 7850.0\nrestitution = 0.8\nfriction = 0.5\n{}",
        floor(0.8, 0.5),
        body(
            "bolt",
            // The bolt's origin, placing its centre of mass at (0, 0, 0.0327056).
            [-0.000_201_299_411, 0.000_053_584_668, 0.040_225_552],
            &format!(
                "orientation = [0.864928125, 0.003632694, -0.013361403, -0.501704709]\n\
                 velocity = [{}, {}, {}]\nangular_velocity = [{}, {}, {}]",
                v.x, v.y, v.z, w.x, w.y, w.z
            )
        )
    );
    let mut world = world(&scene);
    let mut exec = Inline::default();
    let mut watch = Watch::new(&world);
    let (mut lowest_energy, mut climb) = (world.energy(), 0.0f64);
    while !world.at_rest() && world.time() < 20.0 {
        watch.step(&mut world, &mut exec);
        lowest_energy = lowest_energy.min(world.energy());
        climb = climb.max(world.energy() - lowest_energy);
    }
    eprintln!(
        "rest at {:.2} s, climb {climb:.2e} J, one-step rise {:.2e} J",
        world.time(),
        watch.rise
    );
    assert!(world.at_rest(), "still wobbling at {} s", world.time());
    assert!(world.time() <= 5.0, "rested only at {} s", world.time());
    assert!(climb <= 1e-6, "energy climbed {climb:e} J over its lowest");
    assert_penetration(&world, CONTACT_TOLERANCE, "bolt on its rim");
}

// ------------------------------------------------------------------ long runs

/// The OSRF box (0.1 × 0.4 × 0.9 m, 10 kg, ω0 = (0.1, 5, 0.1)) tumbling free
/// for 1000 s at dt = 0.01 (10⁵ steps, hundreds of flips): the energy error
/// is the integrator's bounded 6e-8 (below 1e-7), reached in the first
/// 100 s and never growing after; L stays constant as a vector to 1e-12;
/// the quaternion norm stays 1 to 1e-14. (10 000 s in scripts/stress.sh.)
#[test]
fn torque_free_box_for_1000_s_keeps_energy_and_angular_momentum() {
    let mut w = world(
        "[world]\ngravity = [0.0, 0.0, 0.0]\ndt = 0.01\nduration = 1000.0\n\
         [objects.box]\nshape = { box = { half_extents = [0.05, 0.2, 0.45] } }\nmass = 10.0\n\
         [[bodies]]\nobject = \"box\"\nangular_velocity = [0.1, 5.0, 0.1]\n",
    );
    let o = w.object(0).clone();
    let e0 = w.state.bodies[0].kinetic_energy(&o);
    let l0 = w.state.bodies[0].state.angular_momentum;
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    let (mut worst_e, mut worst_l): (f64, f64) = (0.0, 0.0);
    let mut worst_e_100 = 0.0;
    let mut curve = String::new();
    while w.time() < 1000.0 - 1e-9 {
        watch.step(&mut w, &mut exec);
        let b = &w.state.bodies[0];
        worst_e = worst_e.max(((b.kinetic_energy(&o) - e0) / e0).abs());
        worst_l = worst_l.max((b.state.angular_momentum - l0).norm() / l0.norm());
        if w.state.steps % 10_000 == 0 {
            let _ = write!(curve, " {:.0}s:{worst_e:.2e}", w.time());
        }
        if w.state.steps == 10_000 {
            worst_e_100 = worst_e;
        }
    }
    println!(
        "torque-free box 1000 s: energy drift {worst_e:.2e}, L drift {worst_l:.2e}, \
         |q|-1 {:.1e}; energy drift by time:{curve}",
        watch.quat
    );
    assert!(worst_e <= 1e-7, "energy error {worst_e:e}");
    assert!(
        worst_e <= 1.01 * worst_e_100,
        "energy error grows: {worst_e_100:e} by 100 s, {worst_e:e} by 1000 s"
    );
    assert!(worst_l <= 1e-12, "angular momentum drift {worst_l:e}");
    assert!(
        watch.quat <= 1e-14,
        "quaternion norm off by {:e}",
        watch.quat
    );
}

/// The stack of ten, resting systems off, for 60 s (6000 full solves): no
/// cube moves more than 1 µm, no energy is gained. (10 000 s in stress.sh.)
#[test]
fn resting_stack_for_60_s_does_not_creep() {
    let n = 10;
    let mut w = stack(&vec![1.0; n]);
    let start: Vec<_> = w.state.bodies.iter().map(|b| b.state.position).collect();
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    watch.run_until(&mut w, &mut exec, 60.0);
    let moved = (1..=n)
        .map(|i| (w.state.bodies[i].state.position - start[i]).norm())
        .fold(0.0, f64::max);
    let turned = (1..=n)
        .map(|i| w.state.bodies[i].state.orientation.angle())
        .fold(0.0, f64::max);
    println!(
        "resting stack 60 s: largest move {moved:.2e} m, turn {turned:.1e} rad, gain {:.1e} J, \
         |q|-1 {:.1e}",
        watch.gain, watch.quat
    );
    assert!(moved <= 1e-6, "moved {moved:e} m");
    assert!(turned <= 1e-9, "turned {turned:e} rad");
    assert!(watch.gain <= 1e-8, "energy gain {:e}", watch.gain);
    assert_penetration(&w, CONTACT_TOLERANCE, "resting stack");
}

// ------------------------------------------------------------------ crowds

/// 50 nuts and bolts (the thesis scene's shapes, e = 0.8) poured onto the 2 m
/// floor cube run to rest within 20 s; no point of a body gets more than
/// `bound` into the floor (nor do two bodies overlap more), and every one
/// that fell left over an edge (its x or y beyond the cube), not through.
fn pour_fifty_nuts_and_bolts(bound: f64) {
    let text = std::fs::read_to_string("scenes/nuts_and_bolts.toml")
        .unwrap()
        .replace("count = 20", "count = 50");
    let text = text.split("[render]").next().unwrap();
    let mut w = world(text);
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    let n = w.state.bodies.len();
    let mut deepest: f64 = 0.0;
    while w.time() < 20.0 - 1e-9 && !(w.state.steps > 0 && w.at_rest()) {
        watch.step(&mut w, &mut exec);
        for i in 1..n {
            let p = w.state.bodies[i].state.position;
            if w.state.bodies[i].activity != Activity::Fallen
                && p.x.abs() < 0.95
                && p.y.abs() < 0.95
            {
                deepest = deepest.min(lowest(&w, i));
            }
        }
    }
    let fallen: Vec<usize> = (1..n)
        .filter(|&i| w.state.bodies[i].activity == Activity::Fallen)
        .collect();
    println!(
        "50 nuts and bolts: rest at {} s, {} fell off, deepest point over the floor {deepest:.1e} m, \
         penetration {:.1e} m, accepted overlaps {}, energy gain {:.1e} J (E0 {:.3} J)",
        w.time(),
        fallen.len(),
        w.diagnostics.max_penetration,
        w.diagnostics.counters.overlaps_accepted,
        watch.gain,
        watch.e0
    );
    assert!(w.at_rest(), "not at rest after 20 s");
    for &i in &fallen {
        let p = w.state.bodies[i].state.position;
        assert!(
            p.x.abs() > 0.98 || p.y.abs() > 0.98,
            "body {i} fell through the floor at {p:?}"
        );
    }
    assert!(
        watch.gain <= 1e-9 * watch.e0.abs(),
        "energy gain {:e} J",
        watch.gain
    );
    assert!(
        deepest >= -bound,
        "a body reached {deepest} m into the floor"
    );
    assert_penetration(&w, bound, "crowd");
}

/// The pour within a stated bound of 0.1 mm (6.5e-5 m at 6fdb978).
#[test]
fn fifty_nuts_and_bolts_pour_to_rest() {
    pour_fifty_nuts_and_bolts(1e-4);
}

/// The pour within the 10 µm contact tolerance: held at 1b7540f (9.95 µm).
#[test]
fn fifty_nuts_and_bolts_pour_to_rest_within_the_contact_tolerance() {
    pour_fifty_nuts_and_bolts(CONTACT_TOLERANCE);
}

// ------------------------------------------------------------------ random scenes

#[derive(Clone, Debug)]
enum Shape {
    Box([f64; 3]),
    Prism {
        radius: f64,
        half_height: f64,
        sides: u32,
    },
    Hull(Vec<[f64; 3]>),
}

#[derive(Clone, Debug)]
struct RandomBody {
    shape: Shape,
    mass: f64,
    velocity: [f64; 3],
    spin: [f64; 3],
    axis: [f64; 3],
    angle: f64,
    restitution: f64,
    friction: f64,
}

fn shape_strategy() -> impl Strategy<Value = Shape> {
    prop_oneof![
        prop::array::uniform3(0.03..0.1f64).prop_map(Shape::Box),
        (0.03..0.1f64, 0.02..0.1f64, 3u32..9).prop_map(|(radius, half_height, sides)| {
            Shape::Prism {
                radius,
                half_height,
                sides,
            }
        }),
        prop::collection::vec(prop::array::uniform3(-0.1..0.1f64), 8..20).prop_map(Shape::Hull),
    ]
}

fn body_strategy() -> impl Strategy<Value = RandomBody> {
    (
        shape_strategy(),
        -1.0..2.0f64,
        prop::array::uniform3(-3.0..3.0f64),
        prop::array::uniform3(-5.0..5.0f64),
        prop::array::uniform3(-1.0..1.0f64),
        0.0..std::f64::consts::PI,
        0.0..=1.0f64,
        0.0..=1.0f64,
    )
        .prop_map(
            |(shape, log_mass, velocity, spin, axis, angle, restitution, friction)| RandomBody {
                shape,
                mass: 10f64.powf(log_mass),
                velocity,
                spin,
                axis,
                angle,
                restitution,
                friction,
            },
        )
}

/// Container: inner 1.2 × 1.2 m, 1.6 m high, closed by a ceiling.
const HALF_INNER: f64 = 0.6;
const HEIGHT: f64 = 1.6;

fn random_scene(bodies: &[RandomBody], dir: &std::path::Path) -> String {
    let mut s = String::from("[world]\ndt = 0.01\nduration = 2.0\n");
    let slab = |name: &str, h: [f64; 3]| {
        format!(
            "[objects.{name}]\nshape = {{ box = {{ half_extents = [{}, {}, {}] }} }}\nmass = 1.0\n\
             restitution = 0.5\nfriction = 0.5\n",
            h[0], h[1], h[2]
        )
    };
    let (a, t) = (HALF_INNER, 0.1);
    s += &slab("floor", [a + 2.0 * t, a + 2.0 * t, t]);
    s += &slab("wall_x", [t, a + 2.0 * t, HEIGHT / 2.0]);
    s += &slab("wall_y", [a, t, HEIGHT / 2.0]);
    s += &body("floor", [0.0, 0.0, -t], "fixed = true");
    s += &body("floor", [0.0, 0.0, HEIGHT + t], "fixed = true");
    s += &body("wall_x", [-a - t, 0.0, HEIGHT / 2.0], "fixed = true");
    s += &body("wall_x", [a + t, 0.0, HEIGHT / 2.0], "fixed = true");
    s += &body("wall_y", [0.0, -a - t, HEIGHT / 2.0], "fixed = true");
    s += &body("wall_y", [0.0, a + t, HEIGHT / 2.0], "fixed = true");
    for (k, b) in bodies.iter().enumerate() {
        let shape = match &b.shape {
            Shape::Box(h) => format!(
                "{{ box = {{ half_extents = [{}, {}, {}] }} }}",
                h[0], h[1], h[2]
            ),
            Shape::Prism {
                radius,
                half_height,
                sides,
            } => format!(
                "{{ cylinder = {{ radius = {radius}, half_height = {half_height}, sides = {sides} }} }}"
            ),
            Shape::Hull(points) => {
                let mut obj = String::new();
                for p in points {
                    let _ = writeln!(obj, "v {} {} {}", p[0], p[1], p[2]);
                }
                for i in 1..points.len() - 1 {
                    let _ = writeln!(obj, "f {} {} {}", i, i + 1, i + 2);
                }
                std::fs::write(dir.join(format!("hull{k}.obj")), obj).unwrap();
                format!("{{ mesh = {{ path = \"hull{k}.obj\", hull = true }} }}")
            }
        };
        let _ = write!(
            s,
            "[objects.b{k}]\nshape = {shape}\nmass = {}\nrestitution = {}\nfriction = {}\n",
            b.mass, b.restitution, b.friction
        );
        // A 3 × 3 grid of 0.4 m cells per layer: no two bodies overlap.
        let (col, row, layer) = (k % 3, (k / 3) % 3, k / 9);
        let p = [
            (col as f64 - 1.0) * 0.4,
            (row as f64 - 1.0) * 0.4,
            0.2 + 0.4 * layer as f64,
        ];
        let axis = Vector3::from(b.axis);
        let orientation = if axis.norm() > 1e-3 {
            q(axis, b.angle)
        } else {
            "[1.0, 0.0, 0.0, 0.0]".into()
        };
        s += &body(
            &format!("b{k}"),
            p,
            &format!(
                "orientation = {orientation}\nvelocity = [{}, {}, {}]\nangular_velocity = [{}, {}, {}]",
                b.velocity[0], b.velocity[1], b.velocity[2], b.spin[0], b.spin[1], b.spin[2]
            ),
        );
    }
    s
}

/// What one random scene did over its 2 s.
#[derive(Debug, Default)]
struct RandomOutcome {
    penetration: f64,
    /// Furthest any vertex got outside the container (m; ≤ 0 inside).
    escape: f64,
    gain: f64,
    rise: f64,
    rise_at: f64,
    scale: f64,
    accepted: u64,
    toi_events: u64,
    lcp_failures: usize,
    first_over: Option<f64>,
}

/// Runs a random scene: 2 to 12 random boxes, prisms and convex hulls of
/// random points, masses 0.1–100 kg, speeds up to 5 m/s, spins up to
/// 8 rad/s, any restitution and friction, in a closed container, for 2 s.
/// Panics on NaN (through `Watch`). `None`: a random hull was degenerate
/// (flat, too few points) and the loader refused it, as it should.
fn run_random_scene(bodies: &[RandomBody]) -> Option<RandomOutcome> {
    let dir = tempfile::tempdir().unwrap();
    let text = random_scene(bodies, dir.path());
    let scene = match rigidsim::scene::from_str(&text, &dir.path().join("random.toml"), dir.path())
    {
        Ok(s) => s,
        Err(e) if e.to_string().contains("objects.b") => return None,
        Err(e) => panic!("{e}\n{text}"),
    };
    let mut w = World::new(scene);
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    let mut out = RandomOutcome {
        scale: (6..w.state.bodies.len())
            .map(|i| {
                let o = w.object(i);
                w.state.bodies[i].kinetic_energy(o) + o.mass * G * HEIGHT
            })
            .sum(),
        escape: f64::NEG_INFINITY,
        ..Default::default()
    };
    while w.time() < 2.0 - 1e-9 {
        watch.step(&mut w, &mut exec);
        for i in 6..w.state.bodies.len() {
            for v in vertices(&w, i) {
                let out_by = (v.x.abs() - HALF_INNER)
                    .max(v.y.abs() - HALF_INNER)
                    .max(-v.z)
                    .max(v.z - HEIGHT);
                out.escape = out.escape.max(out_by);
            }
        }
    }
    out.penetration = w.diagnostics.max_penetration;
    out.gain = watch.gain;
    out.rise = watch.rise;
    out.rise_at = watch.rise_at;
    out.accepted = w.diagnostics.counters.overlaps_accepted;
    out.toi_events = w.diagnostics.counters.toi_events;
    out.lcp_failures = w.diagnostics.counters.solve.failed as usize;
    out.first_over = watch.first_over;
    // STRESS_DUMP=DIR keeps a scene whose overlap went past the tolerance or
    // that gained energy (with its hull files) for replay with the binary.
    if out.penetration > CONTACT_TOLERANCE || out.gain > 1e-9 * out.scale {
        if let Some(keep) = std::env::var_os("STRESS_DUMP") {
            let keep = std::path::PathBuf::from(keep);
            std::fs::create_dir_all(&keep).unwrap();
            std::fs::write(keep.join("random.toml"), &text).unwrap();
            for e in std::fs::read_dir(dir.path()).unwrap().flatten() {
                std::fs::copy(e.path(), keep.join(e.file_name())).unwrap();
            }
        }
    }
    Some(out)
}

/// The invariants on one random scene: no NaN, overlaps within
/// `pen_bound`, nothing out of the container by more than that, and (with
/// `energy`) the energy never above its start beyond rounding (1e-9 of the
/// energy scale: kinetic energy plus m·g·height of every body) and no one
/// step adding more than 1e-3 of the scale. (Steps do add a little: resting
/// forces are held constant over a step while the contact turns, O(dt)
/// work; 90 % of random scenes stay below 1e-5 of the scale. Above 1e-3 is
/// an explosion.)
fn check_random_scene(
    bodies: &[RandomBody],
    pen_bound: f64,
    energy: bool,
) -> Result<(), TestCaseError> {
    let Some(o) = run_random_scene(bodies) else {
        return Ok(());
    };
    prop_assert!(
        o.escape <= pen_bound,
        "a vertex {:e} m outside the container",
        o.escape
    );
    if !energy {
        return Ok(());
    }
    prop_assert!(
        o.rise <= 1e-3 * o.scale,
        "one step added {:e} J (t = {} s) of a scale of {:e} J",
        o.rise,
        o.rise_at,
        o.scale
    );
    prop_assert!(
        o.penetration <= pen_bound,
        "penetration {:e} m (above 10 µm from t = {:?}, {} overlaps accepted)",
        o.penetration,
        o.first_over,
        o.accepted
    );
    prop_assert!(
        o.gain <= 1e-9 * o.scale,
        "energy gain {:e} J of a scale of {:e} J",
        o.gain,
        o.scale
    );
    Ok(())
}

fn random_seed() -> proptest::test_runner::RngSeed {
    match std::env::var("STRESS_RANDOM_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
    {
        Some(seed) => proptest::test_runner::RngSeed::Fixed(seed),
        None if std::env::var_os("STRESS_RANDOM_SEED").is_some() => {
            proptest::test_runner::RngSeed::Random
        }
        None => proptest::test_runner::RngSeed::Fixed(8),
    }
}

fn random_cases() -> u32 {
    std::env::var("STRESS_RANDOM_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(24)
}

proptest! {
    // A fixed seed keeps CI repeatable; STRESS_RANDOM_SEED=N or =random explores.
    #![proptest_config(ProptestConfig {
        cases: random_cases(),
        max_shrink_iters: 50,
        rng_seed: random_seed(),
        failure_persistence: None,
        ..ProptestConfig::default()
    })]

    /// 24 random scenes (fixed seed): no NaN, nothing more than 1 cm out
    /// of the container (the worst of 300 scenes at 6fdb978: 5.6 mm).
    #[test]
    fn random_scenes_stay_finite_and_inside_the_container(
        bodies in prop::collection::vec(body_strategy(), 2..13)
    ) {
        check_random_scene(&bodies, 1e-2, false)?;
    }

    /// The same 24 scenes: no energy gain, no step adding more than 1e-3 of
    /// the energy scale, overlaps within a stated bound of 2 mm.
    /// (Ignored until the energy guard and the V-Clip bisection: at 1b7540f
    /// one step added 257 J to a scene of 1.55 kJ.)
    #[test]
    fn random_scenes_keep_the_invariants(bodies in prop::collection::vec(body_strategy(), 2..13)) {
        check_random_scene(&bodies, 2e-3, true)?;
    }

    /// The same 24 scenes within the 10 µm contact tolerance itself. At
    /// 1ca4036 the median scene reached 10.3 µm and the worst of the 300
    /// swept 1.47 mm (the tests below); the gap's curvature in the resting
    /// solve and the earlier impacts found in an event's group end that.
    #[test]
    fn random_scenes_keep_overlaps_within_the_contact_tolerance(
        bodies in prop::collection::vec(body_strategy(), 2..13)
    ) {
        check_random_scene(&bodies, CONTACT_TOLERANCE, true)?;
    }
}

/// Runs a saved random scene from tests/data for 2 s; returns the world,
/// the watch and the energy scale (as in `run_random_scene`).
fn replay(dir: &str) -> (World, Watch, f64) {
    let scene = rigidsim::scene::load(
        &std::path::Path::new("tests/data")
            .join(dir)
            .join("scene.toml"),
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let mut w = World::new(scene);
    let scale: f64 = (6..w.state.bodies.len())
        .map(|i| {
            let o = w.object(i);
            w.state.bodies[i].kinetic_energy(o) + o.mass * G * HEIGHT
        })
        .sum();
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    watch.run_until(&mut w, &mut exec, 2.0);
    println!(
        "{dir}: penetration {:.3e} m (over 10 µm from t = {:?}), {} TOI events (at most {} in a \
         step), {} overlaps accepted, energy gain {:.3e} J, largest one-step rise {:.3e} J at t = {:.2} s (scale {:.1} J)",
        w.diagnostics.max_penetration,
        watch.first_over,
        w.diagnostics.counters.toi_events,
        w.diagnostics.counters.max_events_in_step,
        w.diagnostics.counters.overlaps_accepted,
        watch.gain,
        watch.rise,
        watch.rise_at,
        scale
    );
    (w, watch, scale)
}

/// A replayed scene's energy: no step adds more than `rise_share` of its
/// scale, and it never gains over its start beyond rounding (1e-9 of it).
fn assert_replay_energy(watch: &Watch, scale: f64, rise_share: f64) {
    assert!(
        watch.rise <= rise_share * scale,
        "one step added {:e} J of {scale} J",
        watch.rise
    );
    assert!(watch.gain <= 1e-9 * scale, "energy gain {:e} J", watch.gain);
}

/// A hexagonal prism (body 6, 2.12 kg) spinning at about 16 rad/s and a
/// 0.15 kg hull (body 16). At 1b7540f the step of t = 0.63 s ended with a
/// 0.417 mm overlap after 34 time-of-impact events, none accepted; at
/// 6fdb978 the scene reached 0.60 mm with 5 overlaps accepted, at 1ca4036
/// 10.8 µm after 789 events; now 9.6 µm after 457.
#[test]
fn spinning_prism_and_light_hull_overlap_by_half_a_millimetre() {
    let (w, _, _) = replay("stress_spinning_prism_overlap");
    assert_penetration(&w, CONTACT_TOLERANCE, "spinning prism");
}

/// Two light hulls (body 11, 0.21 kg; body 16, 0.10 kg) spinning at up to
/// 20 rad/s in contact. At 1b7540f they needed more than the 256 impact
/// events a step allows in the step that ends at t = 0.55 s, and the 1.04 mm
/// overlap left was accepted; at 6fdb978 the scene reached 0.33 mm, at
/// 1ca4036 0.94 mm. Their edges slide across each other at m/s while both
/// spin: the gap curves in at 245 m/s², and with the resting solve blind to
/// that, it closed again 28 µs after each impact, 0.1 µm deeper each time
/// (256 events in the step from t = 0.54 s). Now 9.95 µm, at most 13
/// events in a step.
#[test]
fn light_spinning_hulls_use_up_the_event_budget_and_overlap() {
    let (w, _, _) = replay("stress_event_budget_overlap");
    assert_penetration(&w, CONTACT_TOLERANCE, "event budget");
    assert!(
        w.diagnostics.counters.max_events_in_step <= 64,
        "{} impact events in one step",
        w.diagnostics.counters.max_events_in_step
    );
}

/// A nut leaning on a fixed bolt and on the floor at one rim point, rocking
/// at up to 0.5 rad/s (taken from the 200-body floor pour, where such a nut
/// kept the pour from resting for 8 s). Rocking between two rim points must
/// lose energy at every impact and die out. At 1841018 it did not: every 4
/// steps the resting solve stopped the nut as it lifted off one rim point,
/// and the constant contact force of that step still carried it up by half
/// its starting velocity (about 9 µm); it fell back from there, gaining
/// 8.5e-6 J in 1 s. The resting solve now lets a contact that separates at
/// the step's start close again at up to that speed (`solver.rs`).
#[test]
fn rocking_nut_comes_to_rest() {
    let scene = rigidsim::scene::load(std::path::Path::new(
        "tests/data/stress_rocking_nut/scene.toml",
    ))
    .unwrap_or_else(|e| panic!("{e}"));
    let mut w = World::new(scene);
    let mut exec = Inline::default();
    let mut watch = Watch::new(&w);
    watch.run_until(&mut w, &mut exec, 1.0);
    assert!(
        watch.gain <= 1e-9,
        "energy rose {:e} J over the start",
        watch.gain
    );
    assert!(w.at_rest(), "still moving at t = {} s", w.time());
}

/// Eleven random bodies: in the step that ends at t = 0.45 s (86 impact
/// events, one overlap accepted) the energy rises by 2.35 MJ, body 12 (a
/// 94.8 kg hull) leaving at about 220 m/s.
#[test]
fn heavy_hull_gains_2_mj_in_one_step() {
    let (_, watch, scale) = replay("stress_energy_explosion");
    assert_replay_energy(&watch, scale, 1e-3);
}

/// Four random bodies: before 6fdb978 the step that ends at t = 0.13 s
/// added 88 kJ (a 12.5 kg pentagonal prism left at about 118 m/s).
#[test]
fn pentagonal_prism_does_not_gain_86_kj_at_0_13_s() {
    let (_, watch, scale) = replay("stress_prism_explosion_before_6fdb978");
    assert_replay_energy(&watch, scale, 1e-3);
}

/// Random sweep seed 1, scene 8: a 0.12 kg box (body 9) spinning at
/// 8 rad/s on an 18 kg hull (body 11) that tips on the floor at 3–4 rad/s.
/// At a986e02 the box sank 7.5 µm in the 8 ms after the pair was solved
/// (t = 0.69 s), then each impact of the next steps found it 0.1 µm deeper
/// than the last (`TOI_GAP`): 10.26 µm. Solving the island again once a
/// body has turned by `SPIN_TRUST` keeps it within the tolerance (9.74 µm).
#[test]
fn light_box_on_a_tipping_hull_stays_within_the_tolerance() {
    let (w, _, _) = replay("stress_tipping_hull_ratchet");
    assert_penetration(&w, CONTACT_TOLERANCE, "box on a tipping hull");
}

/// Random sweep seed 2, scene 52: a 6 kg pentagonal prism (body 6,
/// restitution 0.99) bounced up to 30 rad/s, lands on one corner whose gap
/// curves in at 175 m/s². At a986e02 the resting force that held it, kept
/// for the whole step while the corner swung off the floor, added 4.85 J
/// (2.6e-3 of the scene's energy scale) in the step from t = 0.12 s. Solved
/// again every `SPIN_TRUST` of turn, no step adds over 3.2e-8 of it.
#[test]
fn prism_spinning_on_a_corner_gains_nothing_from_its_resting_force() {
    let (_, watch, scale) = replay("stress_fast_prism_step_rise");
    assert_replay_energy(&watch, scale, 1e-6);
}

/// Random sweep seed 2, scene 79: eleven bodies. At a986e02 a pair's
/// overlap went past 10 µm from t = 1.19 s by the same ratchet as scene 8
/// of seed 1, and three impacts that made no progress were accepted:
/// 0.207 mm. `SPIN_TRUST` keeps it at 9.97 µm with nothing accepted.
#[test]
fn seed_two_scene_79_accepts_no_overlap() {
    let (w, _, _) = replay("stress_accepted_overlap_seed2");
    assert_eq!(
        w.diagnostics.counters.overlaps_accepted, 0,
        "overlaps accepted"
    );
    assert_penetration(&w, CONTACT_TOLERANCE, "seed 2 scene 79");
}

/// Random sweep seed 3, scene 169: the worst of 9 scenes in 1200 (seeds
/// 1–4) that ended past the tolerance at c471308, 10.14 µm, a pair that
/// closed again after each impact and ratcheted `TOI_GAP` deeper per event.
/// Near the tolerance an impact is now placed before a point passes
/// `CONTACT_TOLERANCE − RATCHET_GAP` (`allowed_depth`).
#[test]
fn seed_three_scene_169_stays_within_the_tolerance() {
    let (w, _, _) = replay("stress_tolerance_ratchet_seed3");
    assert_eq!(
        w.diagnostics.counters.overlaps_accepted, 0,
        "overlaps accepted"
    );
    assert_penetration(&w, CONTACT_TOLERANCE, "seed 3 scene 169");
}

/// Random sweep seed 4, scene 89: body 9 slides along wall 2, touching it
/// at rounding level, while the pair sinks into the wall 2.5 ms later in the
/// step. Each impact was bisected on V-Clip's "apart", whose verdict flips
/// at rounding level there: impacts 0.15 µs apart until the step's 256
/// events (then the group's, since each body's) ran out and the overlap
/// was accepted (34c71c7). A pair touching at the bisection's start is
/// bisected on its contact points' depth.
#[test]
fn body_touching_a_wall_does_not_exhaust_the_event_budget() {
    let (w, _, _) = replay("stress_touching_wall_event_budget");
    assert_eq!(
        w.diagnostics.counters.overlaps_accepted, 0,
        "overlaps accepted"
    );
    assert!(
        w.diagnostics.counters.max_events_in_step < EVENTS_PER_BODY as u64 / 4,
        "{} events in one step",
        w.diagnostics.counters.max_events_in_step
    );
    assert_penetration(&w, CONTACT_TOLERANCE, "seed 4 scene 89");
}

/// `STRESS_SWEEP=N cargo test --release --test stress random_scene_sweep --
/// --ignored --nocapture`: N random scenes (seed STRESS_RANDOM_SEED, default
/// 1), no assertion but NaN; prints the distribution of the invariants
/// (scripts/stress.sh runs it for docs/stability.md).
#[test]
#[ignore = "measurement, run by scripts/stress.sh"]
fn random_scene_sweep() {
    use proptest::strategy::ValueTree;
    let n: usize = std::env::var("STRESS_SWEEP")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(100);
    let seed: u64 = std::env::var("STRESS_RANDOM_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1);
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig {
        rng_seed: proptest::test_runner::RngSeed::Fixed(seed),
        ..ProptestConfig::default()
    });
    let strategy = prop::collection::vec(body_strategy(), 2..13);
    let mut outcomes = Vec::new();
    let mut refused = 0;
    // The scene whose one step added the most energy (relative to its scale).
    let mut worst: Option<(f64, Vec<RandomBody>)> = None;
    for _ in 0..n {
        let bodies = strategy.new_tree(&mut runner).unwrap().current();
        // STRESS_SWEEP_SCENE=k writes scene k (as numbered by
        // STRESS_SWEEP_VERBOSE) to STRESS_DUMP's folder.
        let index = outcomes.len() + refused;
        if let (Some(keep), Ok(k)) = (
            std::env::var_os("STRESS_DUMP"),
            std::env::var("STRESS_SWEEP_SCENE"),
        ) && k.parse() == Ok(index)
        {
            let keep = std::path::PathBuf::from(keep);
            std::fs::create_dir_all(&keep).unwrap();
            let text = random_scene(&bodies, &keep);
            std::fs::write(keep.join(format!("scene{index}.toml")), text).unwrap();
        }
        match run_random_scene(&bodies) {
            Some(o) => {
                if std::env::var_os("STRESS_SWEEP_VERBOSE").is_some() {
                    println!(
                        "scene {index}: penetration {:.3e} m, {} events, {} accepted, first over 10 µm at {:?}, largest one-step rise {:.2e} of the scale at {:.2} s, {} failed solves",
                        o.penetration,
                        o.toi_events,
                        o.accepted,
                        o.first_over,
                        o.rise / o.scale,
                        o.rise_at,
                        o.lcp_failures
                    );
                }
                let r = o.rise / o.scale;
                if worst.as_ref().is_none_or(|(w, _)| r > *w) {
                    worst = Some((r, bodies.clone()));
                }
                outcomes.push(o);
            }
            None => refused += 1,
        }
    }
    if let (Some(keep), Some((_, bodies))) = (std::env::var_os("STRESS_DUMP"), &worst) {
        // Its own folder: its hulls must not overwrite those of a scene
        // written above.
        let keep = std::path::PathBuf::from(keep).join("worst");
        std::fs::create_dir_all(&keep).unwrap();
        let text = random_scene(bodies, &keep);
        std::fs::write(keep.join("random.toml"), text).unwrap();
    }
    let rising = outcomes.iter().filter(|o| o.rise > 1e-9 * o.scale).count();
    let mut rises: Vec<f64> = outcomes.iter().map(|o| o.rise / o.scale).collect();
    rises.sort_by(f64::total_cmp);
    let rq = |p: f64| rises[((rises.len() - 1) as f64 * p).round() as usize];
    let mut pen: Vec<f64> = outcomes.iter().map(|o| o.penetration).collect();
    pen.sort_by(f64::total_cmp);
    let q = |p: f64| pen[((pen.len() - 1) as f64 * p).round() as usize];
    let over = |b: f64| pen.iter().filter(|&&x| x > b).count();
    let worst_gain = outcomes
        .iter()
        .map(|o| o.gain / o.scale)
        .fold(f64::NEG_INFINITY, f64::max);
    let worst_escape = outcomes
        .iter()
        .map(|o| o.escape)
        .fold(f64::NEG_INFINITY, f64::max);
    println!(
        "random sweep: {} scenes run ({refused} refused hulls), penetration median {:.2e} m, \
         90 % {:.2e}, 99 % {:.2e}, max {:.2e}; over 10 µm: {}, over 0.1 mm: {}, over 1 mm: {}; \
         scenes with accepted overlaps: {}; with LCP fallbacks: {}; worst escape {:.2e} m; \
         worst energy gain over the start {:.1e} of the scale; scenes where one step added \
         energy (over 1e-9 of the scale): {}; largest one-step rise per scene, relative to its \
         scale: median {:.1e}, 90 % {:.1e}, 99 % {:.1e}, max {:.1e}; over 1e-3: {}",
        outcomes.len(),
        q(0.5),
        q(0.9),
        q(0.99),
        q(1.0),
        over(CONTACT_TOLERANCE),
        over(1e-4),
        over(1e-3),
        outcomes.iter().filter(|o| o.accepted > 0).count(),
        outcomes.iter().filter(|o| o.lcp_failures > 0).count(),
        worst_escape,
        worst_gain,
        rising,
        rq(0.5),
        rq(0.9),
        rq(0.99),
        rq(1.0),
        rises.iter().filter(|&&r| r > 1e-3).count()
    );
}
