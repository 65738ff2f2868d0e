//! Broadphase with bounding spheres (SPEC 2.3): a pair of bodies is a
//! candidate when any sphere of one overlaps any sphere of the other.
//!
//! Sort and sweep along the axis where the sphere centres spread most: sort
//! the spheres' intervals [c − r, c + r] on that axis, sweep keeping the
//! intervals still open, and test the 3-D overlap only for those. Cost is
//! O(n log n + k) for n spheres and k axis overlaps, instead of O(n²).

use nalgebra::Vector3;

/// One world-space sphere of one body.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
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
    let starts: Vec<f64> = order.iter().map(|&i| lo(i)).collect();
    let mut pairs = Vec::new();
    // Each interval against the ones that start inside it (they come next in
    // the sorted order): every overlapping pair on the axis is visited once,
    // and nothing is scanned that does not overlap.
    for (k, &i) in order.iter().enumerate() {
        let pi = &proxies[i];
        let end = pi.center[axis] + pi.radius;
        for (&j, &start) in order[k + 1..].iter().zip(&starts[k + 1..]) {
            if start > end {
                break;
            }
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
    }
    pairs.sort_unstable();
    pairs.dedup();
    pairs
}

/// Pairs of a sphere of `moving` with one of `fixed`, as (fixed body,
/// moving body), and pairs among `moving` (as `candidate_pairs` gives them),
/// together, sorted and without duplicates; two spheres of `fixed` are never
/// tested. For a few moving spheres against a crowd: `fixed` is sorted
/// once along its widest axis, and each moving sphere looks at the spheres
/// that start within its reach there (O((m + f) log f + k)), where the
/// full sweep would walk every pair of the crowd.
pub fn crossing_pairs(fixed: &[SphereProxy], moving: &[SphereProxy]) -> Vec<(u32, u32)> {
    let mut pairs = candidate_pairs(moving, |_, _| true);
    if fixed.is_empty() || moving.is_empty() {
        return pairs;
    }
    // The few spheres far larger than the rest (a floor, a wall) are
    // tested against every moving sphere; the window below is as wide as
    // the largest of the others.
    let mut radii: Vec<f64> = fixed.iter().map(|p| p.radius).collect();
    let middle = radii.len() / 2;
    let median = *radii.select_nth_unstable_by(middle, f64::total_cmp).1;
    let big = |p: &SphereProxy| p.radius > 8.0 * median;
    let axis = widest_axis(fixed);
    let lo = |p: &SphereProxy| p.center[axis] - p.radius;
    let mut order: Vec<usize> = (0..fixed.len()).filter(|&i| !big(&fixed[i])).collect();
    order.sort_unstable_by(|&i, &j| lo(&fixed[i]).total_cmp(&lo(&fixed[j])).then(i.cmp(&j)));
    let large: Vec<usize> = (0..fixed.len()).filter(|&i| big(&fixed[i])).collect();
    let starts: Vec<f64> = order.iter().map(|&i| lo(&fixed[i])).collect();
    let widest = order.iter().map(|&i| fixed[i].radius).fold(0.0, f64::max);
    for m in moving {
        // A sphere of the window reaches m on the axis only if it starts
        // within [m.lo − 2·widest, m.hi].
        let from = starts.partition_point(|&x| x < lo(m) - 2.0 * widest);
        let to = starts.partition_point(|&x| x <= m.center[axis] + m.radius);
        for &i in order[from..to].iter().chain(&large) {
            let f = &fixed[i];
            let reach = f.radius + m.radius;
            if (f.center - m.center).norm_squared() <= reach * reach {
                pairs.push((f.body, m.body));
            }
        }
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
