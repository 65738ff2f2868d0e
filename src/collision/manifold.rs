//! Contact points of two convex polyhedra that touch or barely overlap
//! (SPEC 2.3, fig. 3.8): a vertex contact gives 1 point, an edge contact the
//! 2 edge ends clipped to the other feature, a face contact the vertices of
//! the touching polygon.
//!
//! The contact normal n (out of B towards A) comes from V-Clip's witness
//! points when the pair is clearly apart, otherwise from a separating-axis
//! test, which is exact for the small overlaps the time-of-impact bisection
//! leaves. Each body then offers the feature it turns towards the other
//! along n: a face if one is within `FACE_CONTACT_ANGLE` of facing it, else
//! an edge within that angle of lying across n, else a vertex. Points come
//! from clipping one feature against the other's Voronoi side planes
//! (Sutherland–Hodgman for faces); only those within `tolerance` of the
//! closest one are kept, so a face that is nearly but not quite flat on
//! another degrades to its touching edge or corner.

use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};

use super::sat::separating_axis;
pub use super::vclip::{FACE_CONTACT_COS, FACE_CONTACT_SIN};
use super::vclip::{Feature, Proximity, closest_segment_points};
use crate::polyhedron::ConvexPolyhedron;

/// A face counts as facing the other body, and an edge as lying across the
/// normal, within this angle (radians, ≈ 0.57°). Large enough for a box
/// settling on a floor under solver drift, small enough that the faces of a
/// 100-sided prism (3.6° apart) stay distinct; points of a face that is
/// tilted within it but gapes by more than `tolerance` are dropped anyway.
pub const FACE_CONTACT_ANGLE: f64 = 0.01;

/// Points closer than this fraction of the smaller polyhedron's size are
/// merged (clipping a polygon at its own corners repeats them).
pub const DUPLICATE_REL_TOL: f64 = 1e-6;

/// The contact points must reach the pair's overlap along the normal to
/// within this fraction of the smaller polyhedron's size (rounding, well
/// below the 0.1 µm an impact's bisection resolves).
pub const OVERLAP_HELD_REL: f64 = 1e-9;

/// Witness points closer than this fraction of the smaller polyhedron's size
/// do not give a trustworthy direction; the separating-axis test does.
pub const NORMAL_FROM_POINTS_REL: f64 = 1e-6;

/// One contact point.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContactPoint {
    /// World position, midway between the two surfaces.
    pub point: Vector3<f64>,
    /// Unit, world frame, pointing out of B towards A.
    pub normal: Vector3<f64>,
    /// Signed gap along `normal`; negative is overlap.
    pub separation: f64,
    /// How the normal turns as the bodies do: the gap's second derivative
    /// has a term in the normal's rate (see `NormalTurn`).
    pub turns: NormalTurn,
}

/// Which features the contact normal belongs to, so the contact solve can
/// tell how fast it turns: A's (its face, or whatever feature B's vertex
/// touches), B's, or the cross product of two edges, one on each body
/// (world directions). Two edges sliding across each other while both
/// bodies spin bend the gap at up to 2·ṅ·(relative velocity): 245 m/s² for
/// two light hulls spinning at 20 rad/s (docs/stability.md, *Regression scenes*).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum NormalTurn {
    WithA,
    WithB,
    Edges(Vector3<f64>, Vector3<f64>),
}

/// Contact points of A and B given their V-Clip `proximity`. Empty when they
/// are apart by more than `tolerance`.
pub fn contact_points(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
    proximity: &Proximity,
    tolerance: f64,
) -> Vec<ContactPoint> {
    if !proximity.penetrating && proximity.distance > tolerance {
        return Vec::new();
    }
    let size = a.scale().min(b.scale());
    let n = if proximity.penetrating {
        let sat = separating_axis(a, pose_a, b, pose_b);
        let mut points = points_along(a, pose_a, b, pose_b, &sat.normal, tolerance);
        // The points must hold the overlap along the axis. Along an axis
        // that is (or reproduces) a face normal each body offers a face,
        // and where the overlap is two edges crossing beside those faces,
        // their clipped points miss it: 0.34–0.48 mm of overlap went unseen
        // behind a point 13.7 µm apart until it jumped into view, and the
        // jump could not be bisected (random sweep seed 4, scene 113). The
        // best edge pair's closest points are then a point.
        let deepest = closest_separation(&points);
        if deepest > sat.separation + OVERLAP_HELD_REL * size
            && let Some((i, j, sep)) = sat.best_edges
            && sep < 0.0
        {
            let ends = |p: &ConvexPolyhedron, pose: &Isometry3<f64>, e: u32| {
                let ed = p.edges()[e as usize];
                let v = |k: u32| pose * nalgebra::Point3::from(p.vertices()[k as usize]);
                (v(ed.tail).coords, v(ed.head).coords)
            };
            let (p0, p1) = ends(a, pose_a, i);
            let (q0, q1) = ends(b, pose_b, j);
            let (pa, pb) = closest_segment_points(&p0, &p1, &q0, &q1);
            let n = sat.normal;
            points.push(ContactPoint {
                point: (pa + pb) / 2.0,
                normal: n,
                separation: n.dot(&(pa - pb)),
                turns: NormalTurn::Edges(p1 - p0, q1 - q0),
            });
            let closest = closest_separation(&points);
            points.retain(|c| c.separation <= closest + tolerance);
        }
        return points;
    } else if proximity.distance > NORMAL_FROM_POINTS_REL * size {
        (proximity.point_a - proximity.point_b) / proximity.distance
    } else {
        // Touching: every direction in the overlap of the two features'
        // normal cones separates them, and the separating-axis test returns
        // one at the rim of that set. The smallest features holding the
        // touching point name the natural one, unless that point is a vertex
        // on a vertex, so it must still pass as a separating axis.
        let slack = 2.0 * NORMAL_FROM_POINTS_REL * size;
        match touching_normal(a, pose_a, b, pose_b, &proximity.point_b) {
            Some(m) if separation_along(a, pose_a, b, pose_b, &m) >= -slack => m,
            _ => separating_axis(a, pose_a, b, pose_b).normal,
        }
    };
    points_along(a, pose_a, b, pose_b, &n, tolerance)
}

/// Contact points of A and B along the normal `n` (out of B towards A):
/// the features each turns towards the other, clipped against each other.
fn points_along(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
    n: &Vector3<f64>,
    tolerance: f64,
) -> Vec<ContactPoint> {
    let n = *n;
    let size = a.scale().min(b.scale());
    // The features facing each other, and the lowest vertex of A and the
    // highest of B along n.
    let (fa, low_a) = Support::of(a, pose_a, &-n);
    let (fb, high_b) = Support::of(b, pose_b, &n);
    let onto_b_level = |x: Vector3<f64>| x - n * n.dot(&(x - high_b));
    let onto_a_level = |y: Vector3<f64>| y + n * n.dot(&(low_a - y));

    let turns = match (&fa, &fb) {
        (Support::Face(_, na, _), Support::Face(_, nb, _)) => {
            if na.dot(&n).abs() > nb.dot(&n).abs() {
                NormalTurn::WithA
            } else {
                NormalTurn::WithB
            }
        }
        (Support::Face(..), Support::Edge(..)) | (_, Support::Vertex(_)) => NormalTurn::WithA,
        (Support::Edge(p0, p1), Support::Edge(q0, q1))
            if (p1 - p0).normalize().cross(&(q1 - q0).normalize()).norm() > FACE_CONTACT_SIN =>
        {
            NormalTurn::Edges(p1 - p0, q1 - q0)
        }
        _ => NormalTurn::WithB,
    };
    let mut pairs: Vec<(Vector3<f64>, Vector3<f64>)> = match (&fa, &fb) {
        (Support::Face(pa, na, oa), Support::Face(pb, nb, ob)) => {
            if na.dot(&n).abs() > nb.dot(&n).abs() {
                clip_polygon(pb.clone(), pa, na)
                    .into_iter()
                    .map(|y| (along_to_plane(y, &n, na, *oa), y))
                    .collect()
            } else {
                clip_polygon(pa.clone(), pb, nb)
                    .into_iter()
                    .map(|x| (x, along_to_plane(x, &n, nb, *ob)))
                    .collect()
            }
        }
        (Support::Face(pa, na, oa), Support::Edge(q0, q1)) => clip_segment(q0, q1, pa, na)
            .into_iter()
            .map(|y| (along_to_plane(y, &n, na, *oa), y))
            .collect(),
        (Support::Edge(p0, p1), Support::Face(pb, nb, ob)) => clip_segment(p0, p1, pb, nb)
            .into_iter()
            .map(|x| (x, along_to_plane(x, &n, nb, *ob)))
            .collect(),
        (Support::Edge(p0, p1), Support::Edge(q0, q1)) => edge_edge(p0, p1, q0, q1),
        (Support::Vertex(x), _) => vec![(*x, onto_b_level(*x))],
        (_, Support::Vertex(y)) => vec![(onto_a_level(*y), *y)],
    };
    if pairs.is_empty() {
        // Clipping can come back empty only through rounding at a corner.
        pairs.push((low_a, onto_b_level(low_a)));
    }

    let points: Vec<ContactPoint> = pairs
        .into_iter()
        .map(|(pa, pb)| ContactPoint {
            point: (pa + pb) / 2.0,
            normal: n,
            separation: n.dot(&(pa - pb)),
            turns,
        })
        .collect();
    let closest = closest_separation(&points);
    let merge = DUPLICATE_REL_TOL * size;
    let mut kept: Vec<ContactPoint> = Vec::with_capacity(points.len());
    for c in points {
        if c.separation <= closest + tolerance
            && kept.iter().all(|k| (k.point - c.point).norm() > merge)
        {
            kept.push(c);
        }
    }
    kept
}

/// The smallest separation of `points` (the deepest overlap, negated).
fn closest_separation(points: &[ContactPoint]) -> f64 {
    points
        .iter()
        .map(|c| c.separation)
        .fold(f64::INFINITY, f64::min)
}

/// `min_A(n·x) − max_B(n·x)`, world direction `n`.
fn separation_along(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
    n: &Vector3<f64>,
) -> f64 {
    let low_a = pose_a * nalgebra::Point3::from(a.support(&(pose_a.rotation.inverse() * -n)));
    let high_b = pose_b * nalgebra::Point3::from(b.support(&(pose_b.rotation.inverse() * n)));
    n.dot(&(low_a - high_b))
}

/// Contact normal of two bodies touching at `point`: each offers the
/// smallest feature holding the point (on one face plane: that face; on two:
/// their edge; on more: a vertex). A face gives its own normal; two crossing
/// edges their cross product; otherwise the bisector of the two normal cones
/// (a cone's axis is the sum of the normals of the faces around the
/// feature), kept perpendicular to an edge if there is one. Points the
/// cones' sum cannot fix (vertex on vertex) still need the caller's check.
fn touching_normal(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
    point: &Vector3<f64>,
) -> Option<Vector3<f64>> {
    let fa = feature_at(a, pose_a, point);
    let fb = feature_at(b, pose_b, point);
    let normal = |p: &ConvexPolyhedron, pose: &Isometry3<f64>, f: u32| {
        pose.rotation * p.faces()[f as usize].normal
    };
    let cone = |p: &ConvexPolyhedron, pose: &Isometry3<f64>, f: Feature| -> Vector3<f64> {
        match f {
            Feature::Face(i) => normal(p, pose, i),
            Feature::Edge(e) => {
                let ed = p.edges()[e as usize];
                normal(p, pose, ed.left) + normal(p, pose, ed.right)
            }
            // Each face around a vertex holds two of its edges: counting
            // both faces of every edge counts each face twice.
            Feature::Vertex(v) => p
                .vertex_edges(v as usize)
                .iter()
                .map(|&e| {
                    let ed = p.edges()[e as usize];
                    normal(p, pose, ed.left) + normal(p, pose, ed.right)
                })
                .sum(),
        }
    };
    let direction = |p: &ConvexPolyhedron, pose: &Isometry3<f64>, e: u32| {
        pose.rotation * p.edge_direction(e as usize)
    };
    match (fa, fb) {
        (_, Feature::Face(f)) => return Some(normal(b, pose_b, f)),
        (Feature::Face(f), _) => return Some(-normal(a, pose_a, f)),
        (Feature::Edge(i), Feature::Edge(j)) => {
            let w = direction(a, pose_a, i).cross(&direction(b, pose_b, j));
            if w.norm() > FACE_CONTACT_SIN {
                let w = w.normalize();
                // Out of B is along B's cone and against A's.
                let m = cone(b, pose_b, fb) - cone(a, pose_a, fa);
                return Some(if w.dot(&m) >= 0.0 { w } else { -w });
            }
        }
        _ => {}
    }
    let mut m = cone(b, pose_b, fb) - cone(a, pose_a, fa);
    for (p, pose, f) in [(a, pose_a, fa), (b, pose_b, fb)] {
        if let Feature::Edge(e) = f {
            let u = direction(p, pose, e);
            m -= u * m.dot(&u);
        }
    }
    m.try_normalize(1e-12)
}

/// The smallest feature of `p` holding the boundary point `x` (world).
fn feature_at(p: &ConvexPolyhedron, pose: &Isometry3<f64>, x: &Vector3<f64>) -> Feature {
    let local = pose.inverse_transform_point(&(*x).into()).coords;
    let eps = NORMAL_FROM_POINTS_REL * p.scale();
    let on: Vec<u32> = (0..p.face_count() as u32)
        .filter(|&f| {
            let face = &p.faces()[f as usize];
            (face.normal.dot(&local) - face.offset).abs() <= eps
        })
        .collect();
    if on.len() == 1 {
        return Feature::Face(on[0]);
    }
    if on.len() == 2
        && let Some(e) = p.faces()[on[0] as usize].edges.iter().find(|&&e| {
            let ed = p.edges()[e as usize];
            ed.left == on[1] || ed.right == on[1]
        })
    {
        return Feature::Edge(*e);
    }
    let v = (0..p.vertex_count())
        .min_by(|&i, &j| {
            (p.vertices()[i] - local)
                .norm_squared()
                .total_cmp(&(p.vertices()[j] - local).norm_squared())
        })
        .unwrap_or(0);
    Feature::Vertex(v as u32)
}

/// The feature a body turns towards the other, world frame.
enum Support {
    Vertex(Vector3<f64>),
    Edge(Vector3<f64>, Vector3<f64>),
    /// Polygon (CCW about its normal), unit normal, plane offset.
    Face(Vec<Vector3<f64>>, Vector3<f64>, f64),
}

impl Support {
    /// The feature of `p` extreme along world direction `d`, and the
    /// extreme vertex itself.
    fn of(
        p: &ConvexPolyhedron,
        pose: &Isometry3<f64>,
        d: &Vector3<f64>,
    ) -> (Support, Vector3<f64>) {
        let dl = pose.rotation.inverse() * d;
        let v = p.support_index(&dl);
        let world = |i: usize| pose.rotation * p.vertices()[i] + pose.translation.vector;
        // The faces and edges that can face `d` are those around the
        // extreme vertex: its normal cone contains d.
        let mut face = (f64::NEG_INFINITY, 0usize);
        let mut edge = (f64::INFINITY, 0usize);
        for &e in p.vertex_edges(v) {
            let ed = p.edges()[e as usize];
            for f in [ed.left, ed.right] {
                let c = p.faces()[f as usize].normal.dot(&dl);
                if c > face.0 {
                    face = (c, f as usize);
                }
            }
            let s = p.edge_direction(e as usize).dot(&dl).abs();
            if s < edge.0 {
                edge = (s, e as usize);
            }
        }
        if face.0 >= FACE_CONTACT_COS {
            let f = &p.faces()[face.1];
            let normal = pose.rotation * f.normal;
            let polygon = f.vertices.iter().map(|&i| world(i)).collect();
            let offset = f.offset + normal.dot(&pose.translation.vector);
            return (Support::Face(polygon, normal, offset), world(v));
        }
        if edge.0 <= FACE_CONTACT_SIN {
            let ed = p.edges()[edge.1];
            return (
                Support::Edge(world(ed.tail as usize), world(ed.head as usize)),
                world(v),
            );
        }
        (Support::Vertex(world(v)), world(v))
    }
}

/// Moves `x` along `n` onto the plane `m · y = offset`.
fn along_to_plane(
    x: Vector3<f64>,
    n: &Vector3<f64>,
    m: &Vector3<f64>,
    offset: f64,
) -> Vector3<f64> {
    x + n * ((offset - m.dot(&x)) / m.dot(n))
}

/// Inward side planes (m, c), `m · x ≥ c` inside, of a CCW polygon with
/// normal `normal`: its interior lies to the left of each edge, along
/// `normal × edge`.
fn side_planes(polygon: &[Vector3<f64>], normal: &Vector3<f64>) -> Vec<(Vector3<f64>, f64)> {
    (0..polygon.len())
        .map(|i| {
            let p = polygon[i];
            let q = polygon[(i + 1) % polygon.len()];
            let m = normal.cross(&(q - p)).normalize();
            (m, m.dot(&p))
        })
        .collect()
}

/// Sutherland–Hodgman: `subject` clipped to the prism over `clipper`.
fn clip_polygon(
    mut subject: Vec<Vector3<f64>>,
    clipper: &[Vector3<f64>],
    normal: &Vector3<f64>,
) -> Vec<Vector3<f64>> {
    for (m, c) in side_planes(clipper, normal) {
        if subject.is_empty() {
            break;
        }
        let mut out = Vec::with_capacity(subject.len() + 1);
        for i in 0..subject.len() {
            let p = subject[i];
            let q = subject[(i + 1) % subject.len()];
            let (dp, dq) = (m.dot(&p) - c, m.dot(&q) - c);
            if dp >= 0.0 {
                out.push(p);
            }
            if (dp >= 0.0) != (dq >= 0.0) {
                out.push(p + (q - p) * (dp / (dp - dq)));
            }
        }
        subject = out;
    }
    subject
}

/// Segment `p0 p1` clipped to the prism over `clipper`: its surviving ends.
fn clip_segment(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    clipper: &[Vector3<f64>],
    normal: &Vector3<f64>,
) -> Vec<Vector3<f64>> {
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    for (m, c) in side_planes(clipper, normal) {
        let (d0, d1) = (m.dot(p0) - c, m.dot(p1) - c);
        if d0 < 0.0 && d1 < 0.0 {
            return Vec::new();
        }
        if d0 < 0.0 {
            lo = lo.max(d0 / (d0 - d1));
        } else if d1 < 0.0 {
            hi = hi.min(d0 / (d0 - d1));
        }
    }
    if lo > hi {
        return Vec::new();
    }
    vec![p0 + (p1 - p0) * lo, p0 + (p1 - p0) * hi]
}

/// Two edges: their common stretch when (nearly) parallel, else their
/// closest points.
fn edge_edge(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let len = (p1 - p0).norm();
    let u = (p1 - p0) / len;
    let v = (q1 - q0).normalize();
    if u.cross(&v).norm() <= FACE_CONTACT_SIN {
        let (t0, t1) = ((q0 - p0).dot(&u), (q1 - p0).dot(&u));
        let lo = t0.min(t1).max(0.0);
        let hi = t0.max(t1).min(len);
        if lo <= hi {
            let on_q = |x: Vector3<f64>| q0 + v * (x - q0).dot(&v);
            return [lo, hi]
                .into_iter()
                .map(|t| {
                    let x = p0 + u * t;
                    (x, on_q(x))
                })
                .collect();
        }
    }
    vec![closest_segment_points(p0, p1, q0, q1)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math;

    #[test]
    fn face_contact_cosine_and_sine_are_the_angles_to_the_bit() {
        assert_eq!(
            FACE_CONTACT_COS.to_bits(),
            math::cos(FACE_CONTACT_ANGLE).to_bits()
        );
        assert_eq!(
            FACE_CONTACT_SIN.to_bits(),
            math::sin(FACE_CONTACT_ANGLE).to_bits()
        );
    }

    #[test]
    fn polygon_clip_of_overlapping_squares_is_their_intersection() {
        let sq = |cx: f64, cy: f64| {
            vec![
                Vector3::new(cx - 1.0, cy - 1.0, 0.0),
                Vector3::new(cx + 1.0, cy - 1.0, 0.0),
                Vector3::new(cx + 1.0, cy + 1.0, 0.0),
                Vector3::new(cx - 1.0, cy + 1.0, 0.0),
            ]
        };
        let out = clip_polygon(sq(0.0, 0.0), &sq(1.0, 1.0), &Vector3::z());
        assert_eq!(out.len(), 4);
        for p in &out {
            assert!(p.x >= -1e-15 && p.x <= 1.0 + 1e-15 && p.y >= -1e-15 && p.y <= 1.0 + 1e-15);
        }
    }
}
