//! The separating-axis test of two convex polyhedra: the axis of least
//! overlap (or greatest separation) over both polyhedra's face normals and
//! the edge-edge axes that form faces of their Minkowski difference
//! (Gregorius, GDC 2013). V-Clip reports a penetration from it
//! (`super::vclip`); a leaf of `collision/` beside the polyhedron.

use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};

use crate::polyhedron::ConvexPolyhedron;

/// The cosine and sine of `FACE_CONTACT_ANGLE` (`math::cos`, `math::sin`,
/// to the bit: a test checks them). Written out because the `libm` crate's
/// functions, unlike the C library's, are not folded at compile time: as
/// calls they ran at every use, twice in each `Support::of`.
pub const FACE_CONTACT_COS: f64 = 0.9999500004166653;
pub const FACE_CONTACT_SIN: f64 = 0.009999833334166664;

#[inline]
pub(super) fn xf(iso: &Isometry3<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    iso.rotation * v + iso.translation.vector
}

/// Which kind of axis a separating-axis test settled on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum AxisKind {
    FaceA(u32),
    FaceB(u32),
    /// Cross product of edge `.0` of A and edge `.1` of B.
    Edges(u32, u32),
}

/// The axis of least overlap (or greatest separation) of two convex
/// polyhedra.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeparatingAxis {
    /// Unit, world frame, pointing out of B towards A.
    pub normal: Vector3<f64>,
    /// `min_A(n·x) − max_B(n·x)`: negative is the overlap along `normal`.
    /// When negative it is the penetration depth (minimum translation
    /// distance); when positive a lower bound on the distance.
    pub separation: f64,
    pub kind: AxisKind,
    /// The best edge axis's pair (edge of A, edge of B) and separation,
    /// whether chosen or not; `None` when no edge pair spans one.
    pub best_edges: Option<(u32, u32, f64)>,
}

impl SeparatingAxis {
    /// The largest separation over every axis tested, before face axes are
    /// preferred (`EDGE_AXIS_REL_BIAS`): the pair is apart exactly when it
    /// is positive. `separation` may be negative by up to the bias while an
    /// edge axis separates the pair.
    pub fn largest(&self) -> f64 {
        self.best_edges
            .map_or(self.separation, |(_, _, edge)| edge.max(self.separation))
    }
}

/// An edge axis within `FACE_CONTACT_ANGLE` of the best face axis must beat
/// it by this fraction of the smaller polyhedron's size to be chosen: at
/// equal overlap, face axes give stable face contacts, and nearly parallel
/// edge pairs only reproduce face normals. Edge axes in other directions
/// need only beat it.
pub const EDGE_AXIS_REL_BIAS: f64 = 1e-6;

/// Separating-axis test over the face normals of both polyhedra and the
/// edge-edge axes that form faces of the Minkowski difference A − B
/// (Gregorius, GDC 2013): an edge pair whose arcs on the Gauss maps of A
/// and −B cross. Those are the only edge axes that can realise the minimum
/// overlap, and for them the overlap is the distance between the edge lines
/// along the axis, so the test costs O(F_A V_B + F_B V_A + E_A E_B).
pub fn separating_axis(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
) -> SeparatingAxis {
    // Everything in A's local frame.
    let b_to_a = pose_a.inv_mul(pose_b);
    let bv: Vec<Vector3<f64>> = b.vertices().iter().map(|v| xf(&b_to_a, v)).collect();
    let bn: Vec<Vector3<f64>> = b
        .faces()
        .iter()
        .map(|f| b_to_a.rotation * f.normal)
        .collect();

    let mut best_face = (f64::NEG_INFINITY, Vector3::zeros(), AxisKind::FaceB(0));
    // B's faces first: ties go to B, whose face is then the reference.
    for (j, face) in b.faces().iter().enumerate() {
        let n = bn[j];
        let off = n.dot(&bv[face.vertices[0]]);
        if let Some(sep) = separation_beyond(a.vertices(), &n, off, best_face.0) {
            best_face = (sep, n, AxisKind::FaceB(j as u32));
        }
    }
    for (i, face) in a.faces().iter().enumerate() {
        let m = face.normal;
        if let Some(sep) = separation_beyond(&bv, &m, face.offset, best_face.0) {
            best_face = (sep, -m, AxisKind::FaceA(i as u32));
        }
    }

    let mut best_edge = (f64::NEG_INFINITY, Vector3::zeros(), AxisKind::Edges(0, 0));
    let ca = a.centroid();
    // Each B edge's arc b1→b2 on the Gauss map of −B and its plane's
    // normal, once per call instead of once per edge pair.
    let b_arcs: Vec<GaussArc> = b
        .edges()
        .iter()
        .map(|eb| GaussArc::new(-bn[eb.left as usize], -bn[eb.right as usize]))
        .collect();
    // Which side of the current A arc's plane each face normal of −B lies
    // on (b·n_a): one product per face of B, then two look-ups per edge
    // pair reject the arcs that cannot cross, which is nearly all of them.
    let mut side = vec![0.0; bn.len()];
    for (i, ea) in a.edges().iter().enumerate() {
        let arc_a = GaussArc::new(
            a.faces()[ea.left as usize].normal,
            a.faces()[ea.right as usize].normal,
        );
        for (s, n) in side.iter_mut().zip(&bn) {
            *s = (-n).dot(&arc_a.normal);
        }
        let ua = a.edge_direction(i);
        let pa = a.vertices()[ea.tail as usize];
        for (j, eb) in b.edges().iter().enumerate() {
            let (b1a, b2a) = (side[eb.left as usize], side[eb.right as usize]);
            if b1a * b2a >= 0.0 || !arc_a.crosses(&b_arcs[j], b1a, b2a) {
                continue;
            }
            let ub = b_to_a.rotation * b.edge_direction(j);
            let w = ua.cross(&ub);
            let len = w.norm();
            // Parallel edges span no new direction: their Minkowski face is
            // degenerate and its normal is already a face axis.
            if len < 1e-9 {
                continue;
            }
            let mut w = w / len;
            if w.dot(&(pa - ca)) < 0.0 {
                w = -w;
            }
            // w points out of A at edge i; the support of A − B along w is
            // w·(p_a − p_b), so A and B overlap along n = −w by that much.
            let sep = w.dot(&(bv[eb.tail as usize] - pa));
            if sep > best_edge.0 {
                best_edge = (sep, -w, AxisKind::Edges(i as u32, j as u32));
            }
        }
    }
    // The bias is for edge axes that reproduce the face's normal (parallel
    // edges on a face); an edge axis in another direction is a different
    // contact, and the smaller overlap wins: a box's corner edge against a
    // hull's bottom edge, both on a floor, overlapped 0.750 µm across the
    // edges and 0.776 µm along the hull's face 15° away, whose contact
    // points missed the overlap (docs/stability.md, *Regression scenes*).
    let reproduces_face = best_edge.1.dot(&best_face.1) >= FACE_CONTACT_COS;
    let bias = if reproduces_face {
        EDGE_AXIS_REL_BIAS * a.scale().min(b.scale())
    } else {
        0.0
    };
    let (separation, n, kind) = if best_edge.0 > best_face.0 + bias {
        best_edge
    } else {
        best_face
    };
    SeparatingAxis {
        normal: pose_a.rotation * n,
        separation,
        kind,
        best_edges: match best_edge {
            (sep, _, AxisKind::Edges(i, j)) if sep > f64::NEG_INFINITY => Some((i, j, sep)),
            _ => None,
        },
    }
}

/// `min over points of n·x − offset` where it exceeds `best`, else None.
/// A face axis that cannot beat the best one so far is left as soon as
/// one point shows it (most do at once); the minimum is exact whatever the
/// order, so an axis that can is found with the same separation as by a
/// full scan.
fn separation_beyond(
    points: &[Vector3<f64>],
    n: &Vector3<f64>,
    offset: f64,
    best: f64,
) -> Option<f64> {
    let mut least = f64::INFINITY;
    for x in points {
        least = least.min(n.dot(x));
        if least - offset <= best {
            return None;
        }
    }
    Some(least - offset)
}

/// A great arc a1→a2 (shorter than π) on a Gauss map, with the normal
/// of its plane.
struct GaussArc {
    from: Vector3<f64>,
    to: Vector3<f64>,
    normal: Vector3<f64>,
}

impl GaussArc {
    fn new(from: Vector3<f64>, to: Vector3<f64>) -> GaussArc {
        GaussArc {
            from,
            to,
            normal: from.cross(&to),
        }
    }

    /// Does this arc a cross the arc b, given b's ends' products with this
    /// arc's plane normal (b1·n_a, b2·n_a), of opposite signs? a1, a2 must
    /// also lie on opposite sides of the plane of arc b; the arc-b point on
    /// circle a, r ∝ b1 |b2·n_a| + b2 |b1·n_a|, must then be the crossing on
    /// arc a rather than its antipode, i.e. lie on the side of a1 + a2.
    fn crosses(&self, b: &GaussArc, b1a: f64, b2a: f64) -> bool {
        let (a1b, a2b) = (self.from.dot(&b.normal), self.to.dot(&b.normal));
        if a1b * a2b >= 0.0 {
            return false;
        }
        let mid = self.from + self.to;
        b.from.dot(&mid) * b2a.abs() + b.to.dot(&mid) * b1a.abs() > 0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    fn random_hull(seed: &mut u64, n: usize) -> ConvexPolyhedron {
        let pts: Vec<Vector3<f64>> = (0..n)
            .map(|_| Vector3::new(lcg(seed) - 0.5, lcg(seed) - 0.5, lcg(seed) - 0.5))
            .collect();
        ConvexPolyhedron::hull(&pts).unwrap()
    }

    fn random_pose(seed: &mut u64, spread: f64) -> Isometry3<f64> {
        let axis = Vector3::new(lcg(seed) - 0.5, lcg(seed) - 0.5, lcg(seed) - 0.5);
        let rot = UnitQuaternion::from_scaled_axis(axis * 6.0);
        let t = Vector3::new(lcg(seed) - 0.5, lcg(seed) - 0.5, lcg(seed) - 0.5) * spread;
        Isometry3::from_parts(t.into(), rot)
    }

    /// All edge pairs, with supports computed in full, against the pruned test.
    #[test]
    fn minkowski_pruned_sat_matches_full_sat() {
        let mut seed = 7;
        for _ in 0..200 {
            let a = random_hull(&mut seed, 12);
            let b = random_hull(&mut seed, 12);
            let pa = random_pose(&mut seed, 1.0);
            let pb = random_pose(&mut seed, 1.0);
            let sat = separating_axis(&a, &pa, &b, &pb);
            let av: Vec<_> = a.vertices().iter().map(|v| xf(&pa, v)).collect();
            let bv: Vec<_> = b.vertices().iter().map(|v| xf(&pb, v)).collect();
            let sep = |n: Vector3<f64>| {
                let min_a = av.iter().map(|x| n.dot(x)).fold(f64::INFINITY, f64::min);
                let max_b = bv
                    .iter()
                    .map(|x| n.dot(x))
                    .fold(f64::NEG_INFINITY, f64::max);
                min_a - max_b
            };
            let mut full = f64::NEG_INFINITY;
            for f in a.faces() {
                full = full.max(sep(-(pa.rotation * f.normal)));
            }
            for f in b.faces() {
                full = full.max(sep(pb.rotation * f.normal));
            }
            for (i, _) in a.edges().iter().enumerate() {
                for (j, _) in b.edges().iter().enumerate() {
                    let w = (pa.rotation * a.edge_direction(i))
                        .cross(&(pb.rotation * b.edge_direction(j)));
                    if w.norm() > 1e-9 {
                        let w = w.normalize();
                        full = full.max(sep(w)).max(sep(-w));
                    }
                }
            }
            if full < 0.0 {
                // Overlapping: the pruned test finds the same least overlap.
                assert!(
                    (sat.separation - full).abs() < 1e-9,
                    "{} vs {}",
                    sat.separation,
                    full
                );
            } else {
                assert!(sat.separation <= full + 1e-9 && sat.separation > 0.0);
            }
            assert!((sep(sat.normal) - sat.separation).abs() < 1e-9);
        }
    }
}
