//! Broadphase with bounding spheres (SPEC 2.3): a pair of bodies is a
//! candidate when any sphere of one overlaps any sphere of the other.
//!
//! Sort and sweep along the axis where the sphere centres spread most: sort
//! the spheres' intervals [c − r, c + r] on that axis, sweep keeping the
//! intervals still open, and test the 3-D overlap only for those. Cost is
//! O(n log n + k) for n spheres and k axis overlaps, instead of O(n²).

use nalgebra::Vector3;

/// One world-space sphere of one body.
#[derive(Clone, Copy, Debug)]
pub struct SphereProxy {
    pub body: u32,
    pub center: Vector3<f64>,
    pub radius: f64,
}

/// Candidate body pairs `(a, b)` with `a < b`, sorted and without duplicates.
/// `keep(a, b)` filters pairs that need no test (two fixed bodies, two
/// sleeping bodies of the same resting system, …).
pub fn candidate_pairs(
    proxies: &[SphereProxy],
    keep: impl Fn(u32, u32) -> bool,
) -> Vec<(u32, u32)> {
    if proxies.len() < 2 {
        return Vec::new();
    }
    let axis = widest_axis(proxies);
    let mut order: Vec<usize> = (0..proxies.len()).collect();
    let lo = |i: usize| proxies[i].center[axis] - proxies[i].radius;
    order.sort_unstable_by(|&i, &j| lo(i).total_cmp(&lo(j)).then(i.cmp(&j)));
    let mut open: Vec<usize> = Vec::new();
    let mut pairs = Vec::new();
    for &i in &order {
        let start = lo(i);
        open.retain(|&j| proxies[j].center[axis] + proxies[j].radius >= start);
        let pi = &proxies[i];
        for &j in &open {
            let pj = &proxies[j];
            if pi.body == pj.body {
                continue;
            }
            let reach = pi.radius + pj.radius;
            if (pi.center - pj.center).norm_squared() <= reach * reach {
                let pair = (pi.body.min(pj.body), pi.body.max(pj.body));
                if keep(pair.0, pair.1) {
                    pairs.push(pair);
                }
            }
        }
        open.push(i);
    }
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// Brute-force all-pairs reference (tests and tiny scenes).
pub fn candidate_pairs_brute_force(
    proxies: &[SphereProxy],
    keep: impl Fn(u32, u32) -> bool,
) -> Vec<(u32, u32)> {
    let mut pairs = Vec::new();
    for i in 0..proxies.len() {
        for j in i + 1..proxies.len() {
            let (pi, pj) = (&proxies[i], &proxies[j]);
            if pi.body == pj.body {
                continue;
            }
            let reach = pi.radius + pj.radius;
            if (pi.center - pj.center).norm_squared() <= reach * reach {
                let pair = (pi.body.min(pj.body), pi.body.max(pj.body));
                if keep(pair.0, pair.1) {
                    pairs.push(pair);
                }
            }
        }
    }
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

fn widest_axis(proxies: &[SphereProxy]) -> usize {
    let n = proxies.len() as f64;
    let mean = proxies.iter().map(|p| p.center).sum::<Vector3<f64>>() / n;
    let var = proxies
        .iter()
        .map(|p| (p.center - mean).component_mul(&(p.center - mean)))
        .sum::<Vector3<f64>>();
    var.imax()
}
