//! Exact collision of one body pair: V-Clip on every pair of convex parts
//! whose part spheres overlap, contact points for the touching ones.
//!
//! A `PairTask` carries the two poses and the cached closest features of each
//! part pair, so any rank can run it and hand back the new features: the
//! thesis's hash table of feature pairs stays valid wherever a pair is sent.

use super::manifold::{self, ContactPoint};
use super::vclip::{self, FeaturePair};
use crate::body::{BodyId, ObjectDef};
use nalgebra::{Isometry3, Point3};
use serde::{Deserialize, Serialize};

/// Gap below which two surfaces count as touching, metres.
///
/// Bodies are kept apart by time-of-impact bisection, which stops within half
/// of this gap, so touching bodies sit at gaps in [0, δ] and rounding leaves
/// overlaps far below δ. 10 µm is invisible at the thesis's scale (bodies of
/// 4 cm to 2 m), far above double-precision rounding at those sizes (~1e-15 m),
/// and small enough that a resting body does not visibly float.
pub const CONTACT_TOLERANCE: f64 = 1e-5;

/// Contact points kept per part pair. A flat 40-sided cap on a floor gives 40
/// points, but 8 well-spread ones carry the same support polygon, and the
/// LCP's cost grows with the cube of its rows.
pub const MAX_POINTS_PER_PART_PAIR: usize = 8;

/// Keeps at most `max` points: the deepest, then the extreme point of the
/// patch in each of `max − 1` directions spread around the contact plane, so
/// the support polygon (what keeps a body from tipping) is preserved.
pub fn reduce_contacts(points: Vec<ContactPoint>, max: usize) -> Vec<ContactPoint> {
    if points.len() <= max || max == 0 {
        return points;
    }
    let n = points[0].normal;
    let helper = if n.x.abs() < 0.6 {
        nalgebra::Vector3::x()
    } else {
        nalgebra::Vector3::y()
    };
    let u = (helper - n * n.dot(&helper)).normalize();
    let v = n.cross(&u);
    let deepest = (0..points.len())
        .min_by(|&i, &j| {
            points[i]
                .separation
                .total_cmp(&points[j].separation)
                .then(i.cmp(&j))
        })
        .unwrap_or(0);
    let mut keep = vec![deepest];
    for k in 0..max - 1 {
        let angle = std::f64::consts::TAU * k as f64 / (max - 1) as f64;
        let dir = u * angle.cos() + v * angle.sin();
        let best = (0..points.len())
            .max_by(|&i, &j| {
                dir.dot(&points[i].point)
                    .total_cmp(&dir.dot(&points[j].point))
                    .then(j.cmp(&i))
            })
            .unwrap_or(0);
        if !keep.contains(&best) {
            keep.push(best);
        }
    }
    keep.sort_unstable();
    keep.into_iter().map(|i| points[i]).collect()
}

/// Closest features of one part pair, cached between frames.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct CachedFeatures {
    pub part_a: u16,
    pub part_b: u16,
    pub features: FeaturePair,
}

/// Exact-collision work for one body pair (collision request, SPEC 3.4).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct PairTask {
    pub a: BodyId,
    pub b: BodyId,
    pub object_a: u32,
    pub object_b: u32,
    pub pose_a: Isometry3<f64>,
    pub pose_b: Isometry3<f64>,
    pub warm: Vec<CachedFeatures>,
    /// Generate contact points for part pairs closer than this.
    pub contact_tolerance: f64,
}

/// Result for one body pair (collision reply).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PairResult {
    /// Smallest gap over the tested part pairs (≤ 0 when penetrating); +∞ when
    /// no part pair was close enough to test.
    pub distance: f64,
    /// Deepest overlap of the contact points (≥ 0), 0 when apart.
    pub depth: f64,
    pub penetrating: bool,
    pub contacts: Vec<ContactPoint>,
    pub features: Vec<CachedFeatures>,
    pub iterations: u32,
    pub part_pairs_tested: u32,
}

impl PairResult {
    /// Overlap beyond what counts as touching: time of impact must roll back.
    pub fn needs_rollback(&self, tolerance: f64) -> bool {
        self.penetrating && (self.contacts.is_empty() || self.depth > tolerance)
    }
}

/// Runs V-Clip on the part pairs of one body pair.
pub fn query_pair(objects: &[ObjectDef], task: &PairTask) -> PairResult {
    let oa = &objects[task.object_a as usize];
    let ob = &objects[task.object_b as usize];
    let mut out = PairResult {
        distance: f64::INFINITY,
        ..Default::default()
    };
    let margin = task.contact_tolerance;
    for (ia, pa) in oa.parts.iter().enumerate() {
        let ca = task.pose_a * Point3::from(pa.sphere.center);
        for (ib, pb) in ob.parts.iter().enumerate() {
            let cb = task.pose_b * Point3::from(pb.sphere.center);
            let reach = pa.sphere.radius + pb.sphere.radius + margin;
            if (ca - cb).norm_squared() > reach * reach {
                continue;
            }
            let warm = task
                .warm
                .iter()
                .find(|c| c.part_a as usize == ia && c.part_b as usize == ib)
                .map(|c| c.features);
            let prox =
                vclip::closest_features(&pa.hull, &task.pose_a, &pb.hull, &task.pose_b, warm);
            out.iterations += prox.iterations;
            out.part_pairs_tested += 1;
            out.features.push(CachedFeatures {
                part_a: ia as u16,
                part_b: ib as u16,
                features: prox.features,
            });
            out.distance = out.distance.min(if prox.penetrating {
                prox.distance.min(0.0)
            } else {
                prox.distance
            });
            out.penetrating |= prox.penetrating;
            if prox.penetrating || prox.distance <= task.contact_tolerance {
                let points = manifold::contact_points(
                    &pa.hull,
                    &task.pose_a,
                    &pb.hull,
                    &task.pose_b,
                    &prox,
                    task.contact_tolerance,
                );
                for p in reduce_contacts(points, MAX_POINTS_PER_PART_PAIR) {
                    out.depth = out.depth.max(-p.separation);
                    out.contacts.push(p);
                }
            }
        }
    }
    out
}
