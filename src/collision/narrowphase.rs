//! Exact collision of one body pair: V-Clip on every pair of convex parts
//! whose part spheres overlap, contact points for the touching ones.
//!
//! A `PairTask` carries the two poses and the cached closest features of each
//! part pair, so any rank can run it and hand back the new features: the
//! thesis's hash table of feature pairs stays valid wherever a pair is sent.

use super::manifold::{self, ContactPoint};
use super::patch::reduce_to_patches;
use super::vclip::{self, FeaturePair, Proximity};
use crate::body::{BodyId, ObjectDef};
use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Gap below which two surfaces count as touching, metres.
///
/// Bodies are kept apart by time-of-impact bisection, which stops within half
/// of this gap, so touching bodies sit at gaps in [0, δ] and rounding leaves
/// overlaps far below δ. 10 µm is invisible at the thesis's scale (bodies of
/// 4 cm to 2 m), far above double-precision rounding at those sizes (~1e-15 m),
/// and small enough that a resting body does not visibly float.
pub const CONTACT_TOLERANCE: f64 = 1e-5;

/// Points apart by more than this are near points, not contacts: a
/// contact may lie up to the tolerance past the pair's closest point, which
/// is itself within the tolerance.
pub const NEAR_FROM: f64 = 2.0 * CONTACT_TOLERANCE;

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
    /// Also give the points of part pairs apart by up to this (metres), past
    /// the contact tolerance, as `PairResult::near`: the speculative contacts
    /// of the next step's contact solve. At most the tolerance: none.
    pub near_distance: f64,
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
    /// Points apart by more than the contact tolerance and at most
    /// `PairTask::near_distance` (empty where that is not asked for).
    pub near: Vec<ContactPoint>,
    pub features: Vec<CachedFeatures>,
    pub iterations: u32,
    pub part_pairs_tested: u32,
    /// From B's closest point to A's, of the closest part pair found apart
    /// (zero when none was): a separating direction to try first.
    pub closest_axis: Vector3<f64>,
}

impl PairResult {
    /// Overlap beyond what counts as touching: time of impact must roll back.
    pub fn needs_rollback(&self, tolerance: f64) -> bool {
        self.penetrating && (self.contacts.is_empty() || self.depth > tolerance)
    }
}

/// Runs V-Clip on the part pairs of one body pair.
pub fn query_pair(objects: &[ObjectDef], task: &PairTask) -> PairResult {
    let (oa, ob) = (
        &objects[task.object_a as usize],
        &objects[task.object_b as usize],
    );
    let mut out = PairResult {
        distance: f64::INFINITY,
        ..Default::default()
    };
    let warm = WarmStarts::of(task);
    let reach = task.contact_tolerance.max(task.near_distance);
    for (ia, ib) in scan_parts(oa, ob, task, reach, false).close {
        let prox = part_proximity(oa, ob, task, &warm, (ia, ib));
        add_part_pair(&mut out, oa, ob, task, ia, ib, &prox);
    }
    out.contacts = reduce_to_patches(std::mem::take(&mut out.contacts));
    out.near = reduce_to_patches(std::mem::take(&mut out.near));
    out
}

/// `min_A(n·x) − max_B(n·x)` over every part of both bodies, world
/// direction `n`: when positive, a plane normal to `n` separates the bodies
/// and this is a lower bound on their distance.
pub fn separation_along(
    (oa, pose_a): (&ObjectDef, &Isometry3<f64>),
    (ob, pose_b): (&ObjectDef, &Isometry3<f64>),
    n: &Vector3<f64>,
) -> f64 {
    let (na, nb) = (pose_a.rotation.inverse() * n, pose_b.rotation.inverse() * n);
    let low_a = -highest_along(oa, &-na) + n.dot(&pose_a.translation.vector);
    let high_b = highest_along(ob, &nb) + n.dot(&pose_b.translation.vector);
    low_a - high_b
}

/// max over the object's parts of (support along `d`)·`d`, local frame. A
/// part whose bounding sphere lies wholly below the highest found so far
/// (by more than rounding) cannot raise it and is passed over; the maximum
/// is exact in any order, so the answer is a full scan's to the bit.
fn highest_along(object: &ObjectDef, d: &Vector3<f64>) -> f64 {
    let length = d.norm();
    let mut high = f64::NEG_INFINITY;
    for p in &object.parts {
        let reach = p.sphere.radius * length;
        let top = p.sphere.center.dot(d) + reach;
        if top < high - 1e-9 * (reach + p.sphere.center.norm() * length) {
            continue;
        }
        high = high.max(p.hull.support(d).dot(d));
    }
    high
}

/// V-Clip alone on the close part pairs, without contact points: `None`
/// when a part pair overlaps, else the smallest gap over them (+∞ when none
/// is close) with the closest part pair's axis, as `query_pair` gives them
/// (`PairResult::closest_axis`: the same V-Clip walks from the same warm
/// starts). Beside it, the far part pairs' sphere gap (`far_part_gap`) from
/// the same pass over the part pairs (`scan_parts`): the time-of-impact
/// search asks both of every sample, and two passes (each part sphere's
/// centre placed, every part pair's distance) were a tenth of a pour's
/// first second.
pub fn probe_apart_and_far_gap(
    objects: &[ObjectDef],
    task: &PairTask,
) -> (Option<(f64, Vector3<f64>)>, f64) {
    let (oa, ob) = (
        &objects[task.object_a as usize],
        &objects[task.object_b as usize],
    );
    let scan = scan_parts(oa, ob, task, task.contact_tolerance, true);
    let warm = WarmStarts::of(task);
    let (mut gap, mut axis) = (f64::INFINITY, Vector3::zeros());
    for pair in scan.close {
        let prox = part_proximity(oa, ob, task, &warm, pair);
        if prox.penetrating {
            return (None, scan.far_gap);
        }
        if prox.distance < gap {
            gap = prox.distance;
            axis = prox.point_a - prox.point_b;
        }
    }
    (Some((gap, axis)), scan.far_gap)
}

/// A task's part pairs, sorted by their spheres: the close ones
/// (within a reach) and the gap of the others (`far_part_gap`).
struct PartScan {
    close: Vec<(usize, usize)>,
    far_gap: f64,
}

/// B's part spheres' centres placed by the task's pose, B's origin there,
/// and the radius about it that holds every one of those spheres.
struct PlacedSpheres {
    centres: Vec<Point3<f64>>,
    origin: Point3<f64>,
    reach: f64,
}

impl PlacedSpheres {
    fn of(ob: &ObjectDef, task: &PairTask) -> Self {
        PlacedSpheres {
            centres: ob
                .parts
                .iter()
                .map(|pb| task.pose_b * Point3::from(pb.sphere.center))
                .collect(),
            origin: Point3::from(task.pose_b.translation.vector),
            reach: ob
                .parts
                .iter()
                .map(|pb| pb.sphere.center.norm() + pb.sphere.radius)
                .fold(0.0, f64::max),
        }
    }
}

/// The part pairs whose spheres come within the contact tolerance and,
/// with `far_gap`, the same loop as `part_sphere_gap(…,
/// task.contact_tolerance)` for the others (+∞ without): a part pair's
/// squared centre distance serves both (nalgebra's `norm` is the square
/// root of `norm_squared`). An A part too far from all of B to lower the
/// gap (`part_sphere_gap`'s skip) is still scanned for close pairs, unless
/// it is further than the tolerance (plus `CLOSE_MARGIN`) from them all.
fn scan_parts(
    oa: &ObjectDef,
    ob: &ObjectDef,
    task: &PairTask,
    within: f64,
    far_gap: bool,
) -> PartScan {
    let b = PlacedSpheres::of(ob, task);
    let beyond = within;
    let mut close = Vec::new();
    let mut gap = f64::INFINITY;
    for (ia, pa) in oa.parts.iter().enumerate() {
        let ca = task.pose_a * Point3::from(pa.sphere.center);
        let nearest = (ca - b.origin).norm() - pa.sphere.radius - b.reach;
        let gap_skips = !far_gap || nearest >= gap;
        let none_close = nearest > within + CLOSE_MARGIN;
        if gap_skips && none_close {
            continue;
        }
        for (ib, (pb, cb)) in ob.parts.iter().zip(&b.centres).enumerate() {
            let d2 = (ca - cb).norm_squared();
            let reach = pa.sphere.radius + pb.sphere.radius + within;
            if !none_close && d2 <= reach * reach {
                close.push((ia, ib));
            }
            if !gap_skips {
                let g = d2.sqrt() - pa.sphere.radius - pb.sphere.radius;
                if g > beyond {
                    gap = gap.min(g);
                }
            }
        }
    }
    PartScan {
        close,
        far_gap: gap,
    }
}

/// A lower bound on the gap between the part pairs that `query_pair` and
/// `probe_apart_and_far_gap` do not test (their part spheres are further apart than
/// the contact tolerance): the smallest gap between such part spheres; +∞
/// when every part pair is close. With the V-Clip distance of the close
/// pairs it bounds the bodies' distance from below far more tightly than
/// their enclosing spheres do (a nut's 32 wedges against a bolt's parts).
pub fn far_part_gap(objects: &[ObjectDef], task: &PairTask) -> f64 {
    part_sphere_gap(objects, task, task.contact_tolerance)
}

/// The smallest gap between the part spheres of the two bodies, over the
/// part pairs whose gap exceeds `beyond` (`f64::NEG_INFINITY`: every part
/// pair, a lower bound on the bodies' distance that needs no V-Clip query).
pub fn part_sphere_gap(objects: &[ObjectDef], task: &PairTask, beyond: f64) -> f64 {
    let (oa, ob) = (
        &objects[task.object_a as usize],
        &objects[task.object_b as usize],
    );
    // B's part spheres all lie within `b.reach` of B's origin: a part of A
    // that far from all of them already is skipped whole.
    let b = PlacedSpheres::of(ob, task);
    let mut gap = f64::INFINITY;
    for pa in &oa.parts {
        let ca = task.pose_a * Point3::from(pa.sphere.center);
        let nearest = (ca - b.origin).norm() - pa.sphere.radius - b.reach;
        if nearest >= gap {
            continue;
        }
        for (pb, cb) in ob.parts.iter().zip(&b.centres) {
            let g = (ca - cb).norm() - pa.sphere.radius - pb.sphere.radius;
            if g > beyond {
                gap = gap.min(g);
            }
        }
    }
    gap
}

/// An A part whose sphere is further than the contact tolerance plus this
/// from the sphere around all of B's parts has no close part pair, and its
/// row of B's parts is left unscanned. The margin (1 nm) is nine orders of
/// magnitude above the rounding of these distances (a few 1e-18 m on bodies
/// of centimetres), so no pair the full scan would call close is left out.
const CLOSE_MARGIN: f64 = 1e-9;

/// A task's cached features, looked up by part pair. `query_pair` writes
/// them in part-pair order, so a binary search finds one; whether they are in
/// order is checked once per query, not once per part pair.
struct WarmStarts<'a> {
    cache: &'a [CachedFeatures],
    sorted: bool,
}

impl<'a> WarmStarts<'a> {
    fn of(task: &'a PairTask) -> Self {
        WarmStarts {
            cache: &task.warm,
            sorted: task.warm.is_sorted_by_key(|c| (c.part_a, c.part_b)),
        }
    }

    fn get(&self, ia: usize, ib: usize) -> Option<FeaturePair> {
        let key = (ia as u16, ib as u16);
        if self.sorted {
            self.cache
                .binary_search_by_key(&key, |c| (c.part_a, c.part_b))
                .ok()
                .map(|k| self.cache[k].features)
        } else {
            self.cache
                .iter()
                .find(|c| (c.part_a, c.part_b) == key)
                .map(|c| c.features)
        }
    }
}

/// V-Clip on one part pair, from its cached features.
fn part_proximity(
    oa: &ObjectDef,
    ob: &ObjectDef,
    task: &PairTask,
    warm: &WarmStarts,
    (ia, ib): (usize, usize),
) -> Proximity {
    let (pa, pb) = (&oa.parts[ia], &ob.parts[ib]);
    vclip::closest_features(
        &pa.hull,
        &task.pose_a,
        &pb.hull,
        &task.pose_b,
        warm.get(ia, ib),
    )
}

/// Adds one part pair's proximity, and its contact points when touching,
/// to `out`.
fn add_part_pair(
    out: &mut PairResult,
    oa: &ObjectDef,
    ob: &ObjectDef,
    task: &PairTask,
    ia: usize,
    ib: usize,
    prox: &Proximity,
) {
    out.iterations += prox.iterations;
    out.part_pairs_tested += 1;
    out.features.push(CachedFeatures {
        part_a: ia as u16,
        part_b: ib as u16,
        features: prox.features,
    });
    if !prox.penetrating && prox.distance < out.distance {
        out.closest_axis = prox.point_a - prox.point_b;
    }
    out.distance = out.distance.min(if prox.penetrating {
        prox.distance.min(0.0)
    } else {
        prox.distance
    });
    out.penetrating |= prox.penetrating;
    let touching = prox.penetrating || prox.distance <= task.contact_tolerance;
    let near = task.near_distance > task.contact_tolerance;
    if !(touching || near && prox.distance <= task.near_distance) {
        return;
    }
    let (ha, hb) = (&oa.parts[ia].hull, &ob.parts[ib].hull);
    let tolerance = task.contact_tolerance.max(task.near_distance);
    let points = manifold::contact_points(ha, &task.pose_a, hb, &task.pose_b, prox, tolerance);
    let (contacts, near_points) = if near {
        split_near(points, touching, task)
    } else {
        (points, Vec::new())
    };
    for p in reduce_to_patches(contacts) {
        out.depth = out.depth.max(-p.separation);
        out.contacts.push(p);
    }
    out.near.extend(reduce_to_patches(near_points));
}

/// A part pair's points found within the near distance, split into its
/// contacts (where it touches: the points within the contact tolerance of
/// the closest, as a query within the tolerance keeps them) and its near
/// points (apart by more than `NEAR_FROM`, for a task's own tolerance).
fn split_near(
    points: Vec<ContactPoint>,
    touching: bool,
    task: &PairTask,
) -> (Vec<ContactPoint>, Vec<ContactPoint>) {
    let closest = points
        .iter()
        .map(|p| p.separation)
        .fold(f64::INFINITY, f64::min);
    let (mut contacts, mut near) = (Vec::new(), Vec::new());
    for p in points {
        if touching && p.separation <= closest + task.contact_tolerance {
            contacts.push(p);
        } else if p.separation > 2.0 * task.contact_tolerance && p.separation <= task.near_distance
        {
            near.push(p);
        }
    }
    (contacts, near)
}
