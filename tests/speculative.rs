//! The contact model's dial (`world.speculative_speed`): approaches solved
//! at the step by speculative contacts instead of exact impact events, end
//! to end. The exact model's cases with the dial on are in
//! `tests/physics_exact.rs`.

mod common;

use common::{FLOOR, run_until, world};
use rigidsim::collision::narrowphase::CONTACT_TOLERANCE;
use rigidsim::step::Inline;

const G: f64 = 9.81;

/// A 10 cm cube `gap` above the floor, falling at `speed`, with the dial at
/// `speculative_speed` and `pile_bodies` (dt = 0.01 s).
fn falling_cube(
    gap: f64,
    speed: f64,
    restitution: f64,
    speculative_speed: f64,
    pile_bodies: u32,
) -> rigidsim::step::World {
    world(&format!(
        r#"
        [world]
        dt = 0.01
        duration = 1.0
        speculative_speed = {speculative_speed}
        pile_bodies = {pile_bodies}
        {FLOOR}
        [objects.cube]
        shape = {{ box = {{ half_extents = [0.05, 0.05, 0.05] }} }}
        mass = 1.0
        restitution = {restitution}
        friction = 0.0
        [[bodies]]
        object = "cube"
        position = [0.0, 0.0, {z}]
        velocity = [0.0, 0.0, -{speed}]
        "#,
        z = 0.05 + gap
    ))
}

/// A slow approach (3 cm/s, below g·dt/2 = 4.9 cm/s: it cannot bounce)
/// 0.6 mm above the floor: with the dial on, no impact event; the cube ends
/// the step inside the touching band, never overlapping past the
/// tolerance, and its push counts as one and no ghost. The exact model
/// takes it as one event.
#[test]
fn a_slow_approach_is_solved_at_the_step_without_an_event() {
    for (dial, events) in [(0.0, 1), (0.049, 0)] {
        let mut w = falling_cube(6e-4, 0.03, 0.0, dial, 8);
        let mut exec = Inline::default();
        w.step(&mut exec).unwrap();
        assert_eq!(w.diagnostics.counters.toi_events, events, "dial {dial}");
        // The exact model's event rolls back the cube alone.
        let rollback = [events, 0, 0, 0, 0];
        assert_eq!(
            w.diagnostics.counters.toi_events_by_rollback, rollback,
            "dial {dial}"
        );
        // It met the floor from apart: no overlap of a touching pair.
        assert_eq!(w.diagnostics.counters.overlap_repairs, 0, "dial {dial}");
        // The speculative contact pushed, and the pair ended touching.
        let pushes = u64::from(dial > 0.0);
        assert_eq!(
            w.diagnostics.counters.speculative_pushes, pushes,
            "dial {dial}"
        );
        assert_eq!(w.diagnostics.counters.speculative_ghosts, 0, "dial {dial}");
        let gap = w.state.bodies[1].state.position.z - 0.05;
        assert!(
            (0.0..=CONTACT_TOLERANCE).contains(&gap),
            "dial {dial}: gap {gap:e}"
        );
        run_until(&mut w, &mut exec, 0.5);
        assert!(
            w.diagnostics.max_penetration <= CONTACT_TOLERANCE,
            "dial {dial}"
        );
        assert_eq!(w.diagnostics.counters.overlaps_accepted, 0);
        let gap = w.state.bodies[1].state.position.z - 0.05;
        assert!(
            (0.0..=CONTACT_TOLERANCE).contains(&gap),
            "dial {dial}: rests at {gap:e}"
        );
    }
}

/// A bouncing approach (1 m/s, e = 0.5) 5 mm above the floor, in a "pile"
/// of one (`pile_bodies = 1`): the speculative contact stops it at the
/// floor in the first step and it leaves at e times its approach in the
/// next, where it met the floor: no event, no overlap, and an apex within
/// 0.5 % of the exact bounce's (it leaves up to a step late, at e times the
/// speed it met the floor with: its start speed and gravity over the gap).
#[test]
fn a_deferred_bounce_leaves_from_where_the_bodies_meet() {
    let (e, v0, gap) = (0.5, 1.0, 5e-3);
    let mut w = falling_cube(gap, v0, e, 1.0, 1);
    let mut exec = Inline::default();
    w.step(&mut exec).unwrap();
    let touching = w.state.bodies[1].state.position.z - 0.05;
    assert!(
        (0.0..=CONTACT_TOLERANCE).contains(&touching),
        "after the stop: gap {touching:e}"
    );
    // Up past the apex (0.06 s after the touch).
    let mut apex: f64 = 0.0;
    while w.time() < 0.1 {
        w.step(&mut exec).unwrap();
        apex = apex.max(w.state.bodies[1].state.position.z - 0.05);
    }
    assert_eq!(w.diagnostics.counters.toi_events, 0);
    assert!(w.diagnostics.max_penetration <= CONTACT_TOLERANCE);
    let v_touch = (v0 * v0 + 2.0 * G * gap).sqrt();
    let exact = (e * v_touch).powi(2) / (2.0 * G);
    assert!(
        ((apex - exact) / exact).abs() < 0.005,
        "apex {apex} m against {exact} m"
    );
}
