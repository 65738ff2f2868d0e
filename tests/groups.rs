//! Interaction groups: a group's step reads only its own input, so bodies
//! far from each other step exactly (to the bit) as they would alone, and
//! a group re-run after a path left it gives what one group from the
//! start gives.

mod common;

use common::{run_until, world};
use rigidsim::step::{Inline, World};

const OBJECTS: &str = r#"
[world]
dt = 0.01
duration = 3.0
[objects.floor]
shape = { box = { half_extents = [2.0, 2.0, 0.1] } }
mass = 1.0
restitution = 0.8
friction = 0.5
[objects.nut]
shape = { nut = { across_flats = 0.04, thickness = 0.016, hole_radius = 0.011, sides = 12 } }
density = 7850.0
restitution = 0.8
friction = 0.5
[objects.bolt]
shape = { bolt = { head_across_flats = 0.03, head_height = 0.012, shaft_radius = 0.009, shaft_length = 0.04, sides = 12 } }
density = 7850.0
restitution = 0.8
friction = 0.5
[[bodies]]
object = "floor"
position = [0.0, 0.0, -0.1]
fixed = true
"#;

/// A little pile at `x`: bodies dropped onto each other and the floor,
/// spinning, so that they collide, rest, sleep and wake.
fn pile(x: f64) -> String {
    let mut s = String::new();
    for k in 0..5 {
        let object = if k % 2 == 0 { "nut" } else { "bolt" };
        let (dx, dy) = [
            (0.0, 0.0),
            (0.015, 0.01),
            (-0.01, 0.012),
            (0.005, -0.015),
            (0.0, 0.005),
        ][k];
        s += &format!(
            "[[bodies]]\nobject = \"{object}\"\nposition = [{}, {dy}, {}]\n\
             orientation = [0.9, 0.3, 0.2, 0.25]\nangular_velocity = [{}, 2.0, -1.0]\n\
             velocity = [0.0, 0.0, -{}]\n",
            x + dx,
            0.05 + 0.06 * k as f64,
            1.5 + k as f64,
            0.5 * k as f64,
        );
    }
    s
}

/// A pour of 40 bodies, and two late bodies that land on it once it
/// rests (from 12 m and 16 m, landing at 1.6 s and 1.8 s).
fn pour_with_late_bodies() -> String {
    format!(
        "{OBJECTS}[[scatter]]\nobjects = [\"nut\", \"bolt\"]\ncount = 40\n\
         min = [-0.15, -0.15, 0.05]\nmax = [0.15, 0.15, 0.6]\nseed = 3\nrandom_orientation = true\n\
         [[bodies]]\nobject = \"bolt\"\nposition = [0.02, 0.0, 12.0]\n\
         [[bodies]]\nobject = \"nut\"\nposition = [-0.05, 0.03, 16.0]\n"
    )
}

fn run(scene: &str) -> World {
    let mut w = world(scene);
    run_until(&mut w, &mut Inline::default(), 2.0);
    w
}

fn bits(w: &World, i: usize) -> Vec<u64> {
    let s = &w.state.bodies[i].state;
    s.position
        .iter()
        .chain(s.orientation.coords.iter())
        .chain(s.velocity.iter())
        .chain(s.angular_momentum.iter())
        .map(|x| x.to_bits())
        .collect()
}

/// Two piles 1 m apart on one floor, stepped together, end exactly as each
/// pile stepped alone: what a group computes does not depend on what else
/// the world holds (no shared event budget, no shared event clock for spin
/// re-solves, no shared broadphase).
#[test]
fn far_apart_piles_step_to_the_bit_as_if_alone() {
    let left = run(&format!("{OBJECTS}{}", pile(-0.5)));
    let right = run(&format!("{OBJECTS}{}", pile(0.5)));
    let both = run(&format!("{OBJECTS}{}{}", pile(-0.5), pile(0.5)));
    assert!(
        both.diagnostics.counters.toi_events > 20,
        "the piles must collide: {} events",
        both.diagnostics.counters.toi_events
    );
    assert!(both.diagnostics.counters.groups > 0);
    for i in 1..=5 {
        assert_eq!(bits(&both, i), bits(&left, i), "left pile, body {i}");
        assert_eq!(
            bits(&both, 5 + i),
            bits(&right, i),
            "right pile, body {i} (body {} together)",
            5 + i
        );
    }
    assert_eq!(
        both.diagnostics.counters.toi_events,
        left.diagnostics.counters.toi_events + right.diagnostics.counters.toi_events
    );
}

/// A pour (and two late bodies that land on it once it rests, from 12 m and
/// 16 m) whose bodies chain into groups differently with each margin (the
/// share of its radius by which a predicted sphere grows when the groups
/// are formed) ends on one state hash: merging bodies that never meet into
/// one group changes nothing. (The 200-body pour of `scripts/bench_pour.sh`
/// once ended differently with the margin: a woken resting body's group
/// did not hold the fixed bodies near it, and a spin re-solve waited for
/// the group's latest event rather than its own bodies'.)
#[test]
fn a_pour_ends_the_same_whatever_the_group_margin() {
    let scene = pour_with_late_bodies();
    let run_with = |margin: f64| {
        let mut w = world(&scene);
        w.settings.group_margin = margin;
        run_until(&mut w, &mut Inline::default(), 2.2);
        w
    };
    let reference = run_with(0.0);
    assert!(
        reference.diagnostics.counters.toi_events > 500,
        "{:?}",
        reference.diagnostics.counters
    );
    assert!(
        reference.diagnostics.counters.wakes > 0,
        "nothing woke: {:?}",
        reference.diagnostics.counters
    );
    // Every event is counted once by the bodies it rolled back, and a
    // pour's events roll back more than one body.
    let rollback = reference.diagnostics.counters.toi_events_by_rollback;
    assert_eq!(
        rollback.iter().sum::<u64>(),
        reference.diagnostics.counters.toi_events
    );
    assert!(rollback[1..].iter().sum::<u64>() > 0, "{rollback:?}");
    // Some events repair a touching pair (a rocking body's other corner
    // landing); most are bodies meeting from apart.
    let repairs = reference.diagnostics.counters.overlap_repairs;
    assert!(repairs > 0 && 2 * repairs < reference.diagnostics.counters.toi_events);
    for margin in [0.02, rigidsim::step::GROUP_MARGIN, 1.0] {
        let w = run_with(margin);
        assert_eq!(w.state_hash(), reference.state_hash(), "margin {margin}");
        assert_eq!(
            w.diagnostics.counters.toi_events,
            reference.diagnostics.counters.toi_events
        );
        assert_eq!(w.diagnostics.counters.toi_events_by_rollback, rollback);
        assert_eq!(w.diagnostics.counters.overlap_repairs, repairs);
        if margin == 1.0 {
            assert!(
                w.diagnostics.counters.groups < reference.diagnostics.counters.groups,
                "the margin must merge groups: {} against {}",
                w.diagnostics.counters.groups,
                reference.diagnostics.counters.groups
            );
        }
    }
}

/// The same pour with its large groups split into the parts that interact
/// within each step (`StepSettings::split_groups`) ends on the very state of the
/// pour stepped whole: every pair between parts whose paths met was found
/// by the check between parts, and the parts that met stepped again as
/// one. The split must have happened and merged parts, or the comparison
/// proves nothing. (A part searches each pair's time of impact whole, a
/// whole group only as far as its next event needs, `PairBook::earliest`:
/// this also holds that the two give the same answers.)
#[test]
fn a_pour_ends_the_same_with_its_groups_split() {
    let scene = pour_with_late_bodies();
    let run_with = |split: bool| {
        let mut w = world(&scene);
        w.settings.split_groups = split;
        run_until(&mut w, &mut Inline::default(), 2.2);
        w
    };
    let whole = run_with(false);
    let split = run_with(true);
    assert!(
        whole.diagnostics.counters.largest_group >= rigidsim::step::SPLIT_MIN_MEMBERS as u64,
        "no group large enough to split: {:?}",
        whole.diagnostics.counters
    );
    assert!(
        split.diagnostics.counters.largest_group < whole.diagnostics.counters.largest_group,
        "the split made no smaller groups: {} against {}",
        split.diagnostics.counters.largest_group,
        whole.diagnostics.counters.largest_group
    );
    assert!(
        split.diagnostics.counters.group_reruns > 0,
        "no parts met (the check between parts was not exercised): {:?}",
        split.diagnostics.counters
    );
    assert_eq!(split.state_hash(), whole.state_hash());
    assert_eq!(
        split.diagnostics.counters.toi_events,
        whole.diagnostics.counters.toi_events
    );
    assert_eq!(split.diagnostics.counters.overlaps_accepted, 0);
}
