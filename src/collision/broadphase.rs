//! Broadphase with bounding spheres (SPEC 2.3): a pair of bodies is a
//! candidate when any sphere of one overlaps any sphere of the other.
//!
//! Sort and sweep along the axis where the sphere centres spread most: sort
//! the spheres' intervals [c − r, c + r] on that axis, sweep keeping the
//! intervals still open, and test the 3-D overlap only for those. Cost is
//! O(n log n + k) for n spheres and k axis overlaps, instead of O(n²). The
//! sweep runs over one sphere per body enclosing its own; only the bodies
//! whose enclosures meet have their spheres tested against each other.

use nalgebra::Vector3;

/// One world-space sphere of one body.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
pub struct SphereProxy {
    pub body: u32,
    pub center: Vector3<f64>,
    pub radius: f64,
}

/// Candidate body pairs `(a, b)` with `a < b`, sorted and without duplicates.
/// `keep(a, b)` filters pairs that need no test (two fixed, two sleeping
/// bodies of the same resting system, …).
///
/// Two levels: a sort and sweep over one enclosing sphere per body, then,
/// for the body pairs whose enclosures meet, the bodies' own spheres. A nut
/// or a bolt has 30 to 50 spheres (one per part, more along a shaft): swept
/// one by one, each would meet its own body's spheres and every sphere of
/// its neighbours on the axis. The answer is the same set as the sweep over
/// every sphere (`candidate_pairs_brute_force`): the enclosures only decide
/// which sphere pairs are tested.
pub fn candidate_pairs(
    proxies: &[SphereProxy],
    keep: impl Fn(u32, u32) -> bool,
) -> Vec<(u32, u32)> {
    let bodies = Enclosures::of(proxies);
    let mut scratch = Vec::new();
    let mut pairs = Vec::new();
    for (x, y) in sweep(&bodies.spheres) {
        if bodies.meet(x, y, &mut scratch) {
            let (a, b) = (bodies.spheres[x].body, bodies.spheres[y].body);
            let pair = (a.min(b), a.max(b));
            if keep(pair.0, pair.1) {
                pairs.push(pair);
            }
        }
    }
    pairs.sort_unstable();
    pairs
}

/// One sphere per body enclosing all of that body's spheres, and which of
/// the proxies are whose.
struct Enclosures<'a> {
    proxies: &'a [SphereProxy],
    /// Indices into `proxies`, by body (in order of first appearance).
    order: Vec<usize>,
    /// The enclosure of each body, and its proxies as a range of `order`.
    spheres: Vec<SphereProxy>,
    ranges: Vec<std::ops::Range<usize>>,
}

impl<'a> Enclosures<'a> {
    fn of(proxies: &'a [SphereProxy]) -> Self {
        let mut order: Vec<usize> = (0..proxies.len()).collect();
        // Proxies usually come grouped by body already; a stable sort keeps
        // them so and groups any that are not.
        if !proxies.windows(2).all(|w| w[0].body <= w[1].body) {
            order.sort_by_key(|&i| proxies[i].body);
        }
        let (mut spheres, mut ranges) = (Vec::new(), Vec::new());
        let mut from = 0;
        while from < order.len() {
            let body = proxies[order[from]].body;
            let to = from + order[from..].partition_point(|&i| proxies[i].body == body);
            let own = order[from..to].iter().map(|&i| &proxies[i]);
            spheres.push(enclosing(body, own));
            ranges.push(from..to);
            from = to;
        }
        Enclosures {
            proxies,
            order,
            spheres,
            ranges,
        }
    }

    fn own(&self, x: usize) -> impl Iterator<Item = &SphereProxy> + Clone {
        self.order[self.ranges[x].clone()]
            .iter()
            .map(|&i| &self.proxies[i])
    }

    /// Whether a sphere of body `x` meets one of body `y`. A sphere that
    /// meets one of the other body's spheres meets that body's enclosure,
    /// so only those are paired up.
    fn meet(&self, x: usize, y: usize, scratch: &mut Vec<SphereProxy>) -> bool {
        let (ex, ey) = (&self.spheres[x], &self.spheres[y]);
        scratch.clear();
        scratch.extend(self.own(y).filter(|t| overlap(t, ex)).copied());
        if scratch.is_empty() {
            return false;
        }
        self.own(x)
            .filter(|s| overlap(s, ey))
            .any(|s| scratch.iter().any(|t| overlap(s, t)))
    }
}

/// A sphere around `spheres` (of one body): centred on their bounding box,
/// reaching the farthest of them, with room for rounding so that a sphere
/// meeting one of them always meets it.
fn enclosing<'a>(body: u32, spheres: impl Iterator<Item = &'a SphereProxy> + Clone) -> SphereProxy {
    let mut it = spheres.clone();
    let Some(first) = it.next() else {
        unreachable!("a body's range holds at least one proxy")
    };
    if it.next().is_none() {
        return *first;
    }
    let r = Vector3::repeat(first.radius);
    let (mut lo, mut hi) = (first.center - r, first.center + r);
    for s in spheres.clone() {
        let r = Vector3::repeat(s.radius);
        lo = lo.inf(&(s.center - r));
        hi = hi.sup(&(s.center + r));
    }
    let center = 0.5 * (lo + hi);
    let reach = spheres
        .map(|s| (s.center - center).norm() + s.radius)
        .fold(0.0, f64::max);
    SphereProxy {
        body,
        center,
        radius: reach * (1.0 + 1e-9) + 1e-12 * (1.0 + center.norm()),
    }
}

/// The test every candidate comes from: the spheres touch or overlap.
fn overlap(p: &SphereProxy, q: &SphereProxy) -> bool {
    let reach = p.radius + q.radius;
    (p.center - q.center).norm_squared() <= reach * reach
}

/// Index pairs `(i, j)` of overlapping spheres of different bodies, each
/// once: sort the spheres' intervals [c − r, c + r] along the axis where
/// the centres spread most, and test each against the ones that start
/// inside it (they come next in the sorted order).
fn sweep(proxies: &[SphereProxy]) -> Vec<(usize, usize)> {
    if proxies.len() < 2 {
        return Vec::new();
    }
    let axis = widest_axis(proxies);
    let mut order: Vec<usize> = (0..proxies.len()).collect();
    let lo = |i: usize| proxies[i].center[axis] - proxies[i].radius;
    order.sort_unstable_by(|&i, &j| lo(i).total_cmp(&lo(j)).then(i.cmp(&j)));
    let starts: Vec<f64> = order.iter().map(|&i| lo(i)).collect();
    let mut pairs = Vec::new();
    for (k, &i) in order.iter().enumerate() {
        let pi = &proxies[i];
        let end = pi.center[axis] + pi.radius;
        for (&j, &start) in order[k + 1..].iter().zip(&starts[k + 1..]) {
            if start > end {
                break;
            }
            if pi.body != proxies[j].body && overlap(pi, &proxies[j]) {
                pairs.push((i, j));
            }
        }
    }
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
    // The crowd's bodies by their enclosing spheres (as in
    // `candidate_pairs`); a body's own spheres are tested only when its
    // enclosure meets the moving sphere.
    let bodies = Enclosures::of(fixed);
    let enclosures = &bodies.spheres;
    // The few enclosures far larger than the rest (a floor, a wall) are
    // tested against every moving sphere; the window below is as wide as
    // the largest of the others.
    let mut radii: Vec<f64> = enclosures.iter().map(|p| p.radius).collect();
    let middle = radii.len() / 2;
    let median = *radii.select_nth_unstable_by(middle, f64::total_cmp).1;
    let big = |p: &SphereProxy| p.radius > 8.0 * median;
    let axis = widest_axis(enclosures);
    let lo = |p: &SphereProxy| p.center[axis] - p.radius;
    let mut order: Vec<usize> = (0..enclosures.len())
        .filter(|&i| !big(&enclosures[i]))
        .collect();
    order.sort_unstable_by(|&i, &j| {
        lo(&enclosures[i])
            .total_cmp(&lo(&enclosures[j]))
            .then(i.cmp(&j))
    });
    let large: Vec<usize> = (0..enclosures.len())
        .filter(|&i| big(&enclosures[i]))
        .collect();
    let starts: Vec<f64> = order.iter().map(|&i| lo(&enclosures[i])).collect();
    let widest = order
        .iter()
        .map(|&i| enclosures[i].radius)
        .fold(0.0, f64::max);
    for m in moving {
        // An enclosure of the window reaches m on the axis only if it
        // starts within [m.lo − 2·widest, m.hi].
        let from = starts.partition_point(|&x| x < lo(m) - 2.0 * widest);
        let to = starts.partition_point(|&x| x <= m.center[axis] + m.radius);
        for &x in order[from..to].iter().chain(&large) {
            if overlap(&enclosures[x], m) && bodies.own(x).any(|f| overlap(f, m)) {
                pairs.push((enclosures[x].body, m.body));
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
