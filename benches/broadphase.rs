//! Broadphase time for 100 / 1 000 / 10 000 bodies (issue 3), sort and sweep
//! against the brute-force all-pairs check, on a pile-like random scene
//! (bodies of ~4 cm at the density of a settled heap).
//!
//! `cargo bench --bench broadphase` (add `-- --tiny` for a quick smoke run).

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};
use rigidsim::collision::broadphase::{SphereProxy, candidate_pairs, candidate_pairs_brute_force};
use std::time::Instant;

fn scene(bodies: u32) -> Vec<SphereProxy> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(bodies as u64);
    // Keep the number of bodies per cubic metre constant: a heap of 4 cm parts.
    let side = (bodies as f64 / 2000.0).cbrt().max(0.2);
    (0..bodies)
        .flat_map(|body| {
            let c = Vector3::from_fn(|_, _| rng.random::<f64>() * side);
            // Two spheres per body, like a bolt's head and shaft.
            [
                SphereProxy {
                    body,
                    center: c,
                    radius: 0.02,
                },
                SphereProxy {
                    body,
                    center: c + Vector3::new(0.0, 0.0, 0.025),
                    radius: 0.015,
                },
            ]
        })
        .collect()
}

/// Median seconds of `runs` calls after one warm-up.
fn time(runs: usize, mut f: impl FnMut() -> usize) -> (f64, usize) {
    let mut pairs = f();
    let mut t: Vec<f64> = (0..runs)
        .map(|_| {
            let clock = Instant::now();
            pairs = f();
            clock.elapsed().as_secs_f64()
        })
        .collect();
    t.sort_by(f64::total_cmp);
    (t[t.len() / 2], pairs)
}

fn main() {
    let tiny = std::env::args().any(|a| a == "--tiny");
    let sizes: &[u32] = if tiny { &[100] } else { &[100, 1_000, 10_000] };
    let runs = if tiny { 1 } else { 11 };
    println!(
        "{:>8} {:>8} {:>14} {:>16} {:>8}",
        "bodies", "pairs", "sweep (ms)", "all pairs (ms)", "ratio"
    );
    for &n in sizes {
        let proxies = scene(n);
        let (sweep, pairs) = time(runs, || candidate_pairs(&proxies, |_, _| true).len());
        let brute_runs = if n > 2_000 { 1 } else { runs };
        let (brute, brute_pairs) = time(brute_runs, || {
            candidate_pairs_brute_force(&proxies, |_, _| true).len()
        });
        assert_eq!(pairs, brute_pairs);
        println!(
            "{:>8} {:>8} {:>14.3} {:>16.3} {:>7.1}x",
            n,
            pairs,
            sweep * 1e3,
            brute * 1e3,
            brute / sweep
        );
    }
}
