//! Contact systems ("islands", SPEC 2.3 fig. 3.9): bodies connected directly
//! or indirectly by contacts must be solved together. Fixed and driven bodies
//! have infinite mass and do not join islands (a floor does not tie together
//! everything that rests on it).

use crate::body::BodyId;

/// Union–find over body indices with path halving.
pub struct DisjointSets {
    parent: Vec<u32>,
}

impl DisjointSets {
    pub fn new(n: usize) -> Self {
        DisjointSets {
            parent: (0..n as u32).collect(),
        }
    }

    pub fn find(&mut self, mut x: u32) -> u32 {
        while self.parent[x as usize] != x {
            let grand = self.parent[self.parent[x as usize] as usize];
            self.parent[x as usize] = grand;
            x = grand;
        }
        x
    }

    /// Joins two sets; the smaller index becomes the root, so roots are the
    /// lowest body id of their set whatever the order of the calls.
    pub fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            let (lo, hi) = (ra.min(rb), ra.max(rb));
            self.parent[hi as usize] = lo;
        }
    }
}

/// Groups contacts into islands. `links[i]` are the two bodies of contact i
/// and `joins(body)` says whether a body takes part in islands (dynamic).
/// Returns, per island, its bodies (ascending) and its contacts (ascending
/// index); islands are ordered by their lowest body id, so the result never
/// depends on hashing or on the order results arrived from other ranks.
pub fn build_islands(
    body_count: usize,
    links: &[(BodyId, BodyId)],
    joins: impl Fn(BodyId) -> bool,
) -> Vec<(Vec<BodyId>, Vec<usize>)> {
    let mut sets = DisjointSets::new(body_count);
    for &(a, b) in links {
        if joins(a) && joins(b) {
            sets.union(a.0, b.0);
        }
    }
    let mut by_root: std::collections::BTreeMap<u32, (Vec<BodyId>, Vec<usize>)> =
        Default::default();
    for (i, &(a, b)) in links.iter().enumerate() {
        let anchor = if joins(a) { a } else { b };
        if !joins(anchor) {
            continue;
        }
        let root = sets.find(anchor.0);
        let entry = by_root.entry(root).or_default();
        entry.1.push(i);
        for body in [a, b] {
            if joins(body) {
                entry.0.push(body);
            }
        }
    }
    by_root
        .into_values()
        .map(|(mut bodies, contacts)| {
            bodies.sort_unstable();
            bodies.dedup();
            (bodies, contacts)
        })
        .collect()
}
