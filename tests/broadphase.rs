//! Broadphase (issue 3): sort and sweep must report exactly the brute-force
//! set of overlapping sphere pairs.

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rigidsim::collision::broadphase::{
    SphereProxy, candidate_pairs, candidate_pairs_brute_force, crossing_pairs,
};

fn random_scene(bodies: u32, seed: u64, spread: f64) -> Vec<SphereProxy> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut proxies = Vec::new();
    for body in 0..bodies {
        let centre = Vector3::from_fn(|_, _| rng.random::<f64>() * spread);
        // One to three spheres per body, like a long body's chain of spheres.
        for _ in 0..rng.random_range(1..=3) {
            proxies.push(SphereProxy {
                body,
                center: centre + Vector3::from_fn(|_, _| rng.random::<f64>() * 0.2),
                radius: 0.05 + rng.random::<f64>() * 0.3,
            });
        }
    }
    proxies
}

#[test]
fn sort_and_sweep_equals_brute_force_on_random_scenes_of_1000_bodies() {
    for (seed, spread) in [(1, 10.0), (2, 5.0), (3, 2.0), (4, 30.0)] {
        let proxies = random_scene(1000, seed, spread);
        let fast = candidate_pairs(&proxies, |_, _| true);
        let slow = candidate_pairs_brute_force(&proxies, |_, _| true);
        assert_eq!(fast, slow, "seed {seed}, spread {spread}");
        assert!(!fast.is_empty());
    }
}

/// Bodies of many spheres each (a nut's ring of parts, a bolt's head and
/// shaft), given in no particular order, with one large sphere among them
/// (a floor): the enclosing spheres of the first level must not lose a
/// pair the sphere-by-sphere check finds.
#[test]
fn bodies_of_many_spheres_in_any_order_give_the_brute_force_pairs() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut proxies = Vec::new();
    for body in 0..150 {
        let centre = Vector3::from_fn(|_, _| rng.random::<f64>() * 0.2);
        let count = rng.random_range(1..=40);
        for k in 0..count {
            let angle = k as f64 * std::f64::consts::TAU / count as f64;
            let ring = Vector3::new(angle.cos(), angle.sin(), 0.0) * 0.02;
            proxies.push(SphereProxy {
                body,
                center: centre + ring,
                radius: 0.002 + rng.random::<f64>() * 0.01,
            });
        }
    }
    proxies.push(SphereProxy {
        body: 150,
        center: Vector3::new(0.1, 0.1, -1.0),
        radius: 1.05,
    });
    // Shuffle, so that one body's spheres are scattered through the list.
    for i in (1..proxies.len()).rev() {
        proxies.swap(i, rng.random_range(0..=i));
    }
    let fast = candidate_pairs(&proxies, |_, _| true);
    assert_eq!(fast, candidate_pairs_brute_force(&proxies, |_, _| true));
    assert!(
        fast.len() > 300,
        "{} pairs: the scene must be crowded",
        fast.len()
    );
    assert!(fast.iter().any(|&(_, b)| b == 150));
}

/// The leak check's pairs: every moving sphere against a crowd of bodies
/// of many spheres (and a floor), plus the pairs among the moving ones,
/// exactly as sphere by sphere.
#[test]
fn crossing_pairs_equal_the_sphere_by_sphere_pairs() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12);
    let mut ring = |body: u32, count: usize, spread: f64| -> Vec<SphereProxy> {
        let centre = Vector3::from_fn(|_, _| rng.random::<f64>() * spread);
        (0..count)
            .map(|k| {
                let angle = k as f64 * std::f64::consts::TAU / count as f64;
                SphereProxy {
                    body,
                    center: centre + Vector3::new(angle.cos(), 0.0, angle.sin()) * 0.02,
                    radius: 0.003 + 0.008 * (k % 3) as f64,
                }
            })
            .collect()
    };
    let mut fixed: Vec<SphereProxy> = (0..200)
        .flat_map(|b| ring(b, 1 + b as usize % 37, 0.3))
        .collect();
    fixed.push(SphereProxy {
        body: 200,
        center: Vector3::new(0.15, 0.15, -1.0),
        radius: 1.02,
    });
    let moving: Vec<SphereProxy> = (0..30).flat_map(|b| ring(300 + b, 5, 0.3)).collect();
    let mut expected = candidate_pairs_brute_force(&moving, |_, _| true);
    for f in &fixed {
        for m in &moving {
            let reach = f.radius + m.radius;
            if (f.center - m.center).norm_squared() <= reach * reach {
                expected.push((f.body, m.body));
            }
        }
    }
    expected.sort_unstable();
    expected.dedup();
    assert!(
        expected.len() > 40,
        "{} pairs: the scene must be crowded",
        expected.len()
    );
    assert_eq!(crossing_pairs(&fixed, &moving), expected);
}

#[test]
fn filter_removes_pairs_and_pairs_are_sorted_without_duplicates() {
    let proxies = random_scene(500, 7, 4.0);
    // Keep only pairs with an even body: the filter is applied to every pair.
    let keep = |a: u32, b: u32| a % 2 == 0 || b % 2 == 0;
    let fast = candidate_pairs(&proxies, keep);
    assert_eq!(fast, candidate_pairs_brute_force(&proxies, keep));
    assert!(fast.windows(2).all(|w| w[0] < w[1]));
    assert!(fast.iter().all(|&(a, b)| a < b && keep(a, b)));
}

#[test]
fn touching_spheres_count_and_separated_ones_do_not() {
    let s = |body, x: f64| SphereProxy {
        body,
        center: Vector3::new(x, 0.0, 0.0),
        radius: 0.5,
    };
    // 0 and 1 touch exactly; 2 is 1e-9 too far from 1.
    let proxies = [s(0, 0.0), s(1, 1.0), s(2, 2.0 + 1e-9)];
    assert_eq!(candidate_pairs(&proxies, |_, _| true), vec![(0, 1)]);
}

/// SPEC 2.6: pairs that touched and are separating skip the end-of-step
/// V-Clip test when a plane along their old normal proves them apart. The
/// proof is exact, so the bundled dynamic scenes and three hard random scenes
/// end bit for bit where they end with the skip off (the only state the skip
/// leaves different is a skipped pair's V-Clip warm start), and it fires.
#[test]
fn separating_pair_skip_changes_no_result_and_fires() {
    use rigidsim::step::{Inline, World};
    let mut fired = 0;
    for (name, seconds) in [
        ("bouncing_cube", 3.0),
        ("newtons_cradle", 2.0),
        ("nuts_and_bolts", 2.5),
        ("load_profile", 3.0),
        ("sliding_box", 2.0),
        ("resting_stack", 1.0),
        // Random spinning hulls and prisms in a closed box (tests/stress.rs).
        ("../tests/data/stress_event_budget_overlap/scene", 1.0),
        ("../tests/data/stress_spinning_prism_overlap/scene", 1.0),
        ("../tests/data/stress_energy_explosion/scene", 1.0),
    ] {
        let path = std::path::Path::new("scenes").join(format!("{name}.toml"));
        let run = |skip: bool| {
            let scene = rigidsim::scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
            let mut w = World::new(scene);
            w.settings.skip_separating = skip;
            let mut exec = Inline::default();
            while w.time() < seconds - 1e-9 {
                w.step(&mut exec).unwrap();
            }
            w
        };
        let (with, without) = (run(true), run(false));
        assert_eq!(with.state_hash(), without.state_hash(), "{name}");
        assert_eq!(without.diagnostics.counters.pairs_skipped_separating, 0);
        assert!(
            with.diagnostics.counters.pair_tests <= without.diagnostics.counters.pair_tests,
            "{name}: the skip must not add tests"
        );
        println!(
            "{name}: {} of {} end-of-step tests skipped",
            with.diagnostics.counters.pairs_skipped_separating,
            without.diagnostics.counters.pair_tests
        );
        fired += with.diagnostics.counters.pairs_skipped_separating;
    }
    assert!(fired > 0, "no pair was skipped in any scene");
}
