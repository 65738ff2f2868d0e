//! V-Clip: closest features, distance and penetration of two convex
//! polyhedra (Mirtich, MERL TR-97-05; Ericson, *Real-Time Collision
//! Detection* §9.2.1; the seed thesis, appendix A).
//!
//! The algorithm keeps one feature (vertex, edge or face) of each polyhedron.
//! By theorem 1, if the closest points of the two features lie in each
//! other's Voronoi regions, they are the closest points of the polyhedra.
//! Each state (V-V, V-E, V-F, E-E, E-F) checks that condition and, if it
//! fails, moves one feature to a neighbour so that the feature distance
//! either drops, or stays the same while the feature dimension drops. The
//! pair (distance, dimension) therefore never repeats, so in exact
//! arithmetic there are no cycles.
//!
//! Edge tests clip the edge `e(λ) = t + λ (h − t)`, `λ ∈ [0, 1]`, against
//! the planes of the other feature X's region, leaving `[λ_lo, λ_hi]` with
//! the neighbours `N_lo`, `N_hi` across the clipping planes. The distance
//! `D(λ) = min_{x∈X} |e(λ) − x|` is convex in λ, so whether its minimum lies
//! inside the clipped interval follows from the sign of `D'` at its ends:
//!
//! ```text
//!   sign D'(λ) = sign( u · (e(λ) − x*(λ)) ),  u = h − t,  x* the point of X nearest e(λ)
//!   X vertex v:  u · (e(λ) − v)
//!   X face F:    (u · n_F) · sign(n_F · e(λ) − offset_F)
//! ```
//!
//! `D'(λ_lo) > 0` means the minimum lies below `λ_lo`, across the plane of
//! `N_lo`, and X moves to `N_lo`; `D'(λ_hi) < 0` likewise moves X to `N_hi`.
//!
//! The original compares with exact zero. Here plane distances, slopes and
//! height differences within a few ulps of the coordinates' magnitude count
//! as zero (`ROUNDING_ULPS`), which is what the theory's tie-breaks assume:
//! degenerate contacts (a box resting on a box, an edge through an edge)
//! otherwise read a sign from rounding noise and cycle. Should the walk still
//! cycle, it is bounded and then falls back to an exhaustive search that is
//! slow but always right.
//!
//! Features that meet (distance 0) cannot tell touching from overlapping; a
//! separating-axis test (`super::sat`) settles those.

use nalgebra::{Isometry3, Vector3};
use serde::{Deserialize, Serialize};

use super::sat::AxisKind;
pub use super::sat::separating_axis;
use super::sat::xf;
use crate::polyhedron::{ConvexPolyhedron, VoronoiPlane};

pub use super::sat::{FACE_CONTACT_COS, FACE_CONTACT_SIN};

/// A vertex, edge or face of one polyhedron, by index into its tables.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Feature {
    Vertex(u32),
    Edge(u32),
    Face(u32),
}

/// The closest features of polyhedra A and B. Plain data: cached per pair
/// between frames and sent between ranks as a warm start.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct FeaturePair {
    pub a: Feature,
    pub b: Feature,
}

/// Result of a V-Clip query.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Proximity {
    /// Euclidean distance when separated (≥ 0). When penetrating, ≤ 0: the
    /// depth of the witness vertex or edge end below the witness face's plane
    /// (a local estimate, not the minimum translation distance), or the SAT
    /// overlap when the answer came from the fallback.
    pub distance: f64,
    pub penetrating: bool,
    /// The features reached; feed them back as the next warm start.
    pub features: FeaturePair,
    /// Witness point on A, world frame. Separated: the closest point.
    pub point_a: Vector3<f64>,
    /// Witness point on B, world frame; `|point_a − point_b| = |distance|`.
    pub point_b: Vector3<f64>,
    /// Number of V-Clip state evaluations.
    pub iterations: u32,
    /// True when the walk hit its iteration bound and the exhaustive search
    /// answered instead.
    pub fell_back: bool,
}

/// The iteration bound `closest_features` uses: twice the total feature
/// count, at least 500. A converging walk needs a few dozen states even on a
/// cold start; the bound only stops floating-point cycles.
pub fn default_iteration_limit(a: &ConvexPolyhedron, b: &ConvexPolyhedron) -> u32 {
    (2 * (a.feature_count() + b.feature_count())).max(500) as u32
}

/// Closest features of A and B (or a penetration witness), starting from
/// `warm_start` when it names valid features of these polyhedra, otherwise
/// from the vertices of each that face the other's centre.
pub fn closest_features(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
    warm_start: Option<FeaturePair>,
) -> Proximity {
    let limit = default_iteration_limit(a, b);
    closest_features_with_limit(a, pose_a, b, pose_b, warm_start, limit)
}

/// `closest_features` with an explicit iteration bound, after which the
/// exhaustive fallback answers (`fell_back` is then set). Exposed so tests
/// can force the fallback.
pub fn closest_features_with_limit(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
    warm_start: Option<FeaturePair>,
    max_iterations: u32,
) -> Proximity {
    let b_to_a = pose_a.inv_mul(pose_b);
    let magnitude = b_to_a.translation.vector.norm() + a.local_extent() + b.local_extent();
    let noise = ROUNDING_ULPS * f64::EPSILON * magnitude;
    let sa = Side {
        poly: a,
        from_other: b_to_a,
        noise,
    };
    let sb = Side {
        poly: b,
        from_other: b_to_a.inverse(),
        noise,
    };
    let mut pair = warm_start
        .and_then(|p| validated(a, b, p))
        .unwrap_or_else(|| cold_start(&sa, &sb));
    let mut iterations = 0;
    let found = loop {
        if iterations == max_iterations {
            return Proximity {
                iterations,
                fell_back: true,
                ..exhaustive(a, pose_a, b, pose_b)
            };
        }
        iterations += 1;
        match step(&sa, &sb, pair) {
            Step::P(f) => pair.a = f,
            Step::Q(f) => pair.b = f,
            Step::Done => match witness(a, pose_a, b, pose_b, pair) {
                Some((point_a, point_b)) => {
                    break Proximity {
                        distance: (point_a - point_b).norm(),
                        penetrating: false,
                        features: pair,
                        point_a,
                        point_b,
                        iterations,
                        fell_back: false,
                    };
                }
                None => {
                    return Proximity {
                        iterations,
                        fell_back: true,
                        ..exhaustive(a, pose_a, b, pose_b)
                    };
                }
            },
            Step::Contact(c) => {
                break Proximity {
                    distance: c.depth,
                    penetrating: c.penetrating,
                    features: FeaturePair { a: c.p, b: c.q },
                    point_a: xf(pose_a, &c.on_p),
                    point_b: xf(pose_b, &c.on_q),
                    iterations,
                    fell_back: false,
                };
            }
        }
    };
    // Features that meet (distance 0) say nothing about the interiors: two
    // cubes meeting corner to corner and two identical cubes at one pose
    // both end on coincident vertices. The separating-axis test decides, up
    // to `VCLIP_CHECKED_REL` of the size apart.
    let size = a.scale().min(b.scale());
    if !found.penetrating
        && found.distance <= VCLIP_CHECKED_REL * size
        && let Some(deep) = sat_penetration(a, pose_a, b, pose_b, -TOUCHING_REL_TOL * size)
    {
        return Proximity { iterations, ..deep };
    }
    found
}

/// Distances within this fraction of the smaller polyhedron's size of zero
/// are rounding-level: such a pair touches, and is called penetrating only
/// if the separating-axis test finds an overlap deeper than this.
pub const TOUCHING_REL_TOL: f64 = 1e-12;

/// A V-Clip answer "apart" by at most this fraction of the smaller
/// polyhedron's size is checked by the separating-axis test: features that
/// nearly meet pass V-Clip's Voronoi tests whatever the interiors do, so a
/// pair whose edges nearly cross can be called apart while it overlaps. At
/// this distance an impact's bisection ends anyway (`TOI_GAP`, 0.1 µm).
pub const VCLIP_CHECKED_REL: f64 = 1e-6;

/// One polyhedron of the pair, with the map from the other's local frame
/// into its own.
struct Side<'a> {
    poly: &'a ConvexPolyhedron,
    from_other: Isometry3<f64>,
    /// Rounding level of lengths in either local frame (see `ROUNDING_ULPS`).
    noise: f64,
}

impl Side<'_> {
    fn vertex(&self, v: u32) -> Vector3<f64> {
        self.poly.vertices()[v as usize]
    }
}

/// Plane distances, distance derivatives and height differences within this
/// many ulps of the coordinates' magnitude (the pair's offset plus each
/// polyhedron's farthest vertex from its origin) count as zero. The theory's tie-breaks rely on exact zeros, e.g. an edge exactly
/// parallel to a face has zero slope where it leaves the face's prism; read
/// from rounding noise, such a sign sends the walk back and forth between
/// the face and its edge forever.
pub const ROUNDING_ULPS: f64 = 16.0;

/// Outcome of one state evaluation. `P`/`Q` replace the first or second
/// feature of the state function's arguments.
enum Step {
    P(Feature),
    Q(Feature),
    Done,
    Contact(Contact),
}

/// The features meet; points are in their own polyhedron's local frame.
struct Contact {
    p: Feature,
    q: Feature,
    on_p: Vector3<f64>,
    on_q: Vector3<f64>,
    depth: f64,
    penetrating: bool,
}

impl Step {
    fn swapped(self) -> Step {
        match self {
            Step::P(f) => Step::Q(f),
            Step::Q(f) => Step::P(f),
            Step::Done => Step::Done,
            Step::Contact(c) => Step::Contact(Contact {
                p: c.q,
                q: c.p,
                on_p: c.on_q,
                on_q: c.on_p,
                ..c
            }),
        }
    }
}

/// The separating-axis answer when A and B overlap by more than `-below`
/// (`below` ≤ 0): depth, the deepest vertex (or edge pair) and its
/// projection onto the other body's face (or edge).
pub(super) fn sat_penetration(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
    below: f64,
) -> Option<Proximity> {
    let sat = separating_axis(a, pose_a, b, pose_b);
    if sat.largest() >= below {
        return None;
    }
    let b_to_a = pose_a.inv_mul(pose_b);
    let bv: Vec<Vector3<f64>> = b.vertices().iter().map(|v| xf(&b_to_a, v)).collect();
    let world = |x: &Vector3<f64>| xf(pose_a, x);
    let done = |depth, fa, fb, pa: Vector3<f64>, pb: Vector3<f64>| Proximity {
        distance: depth,
        penetrating: true,
        features: FeaturePair { a: fa, b: fb },
        point_a: world(&pa),
        point_b: world(&pb),
        iterations: 0,
        fell_back: false,
    };
    let n = pose_a.rotation.inverse() * sat.normal;
    let depth = sat.separation;
    Some(match sat.kind {
        AxisKind::FaceB(j) => {
            let va = a.support_index(&-n);
            let x = a.vertices()[va];
            done(
                depth,
                Feature::Vertex(va as u32),
                Feature::Face(j),
                x,
                x - n * depth,
            )
        }
        AxisKind::FaceA(i) => {
            let vb = (0..bv.len())
                .max_by(|&l, &r| bv[l].dot(&n).total_cmp(&bv[r].dot(&n)))
                .unwrap_or(0);
            let y = bv[vb];
            done(
                depth,
                Feature::Face(i),
                Feature::Vertex(vb as u32),
                y + n * depth,
                y,
            )
        }
        AxisKind::Edges(i, j) => {
            let ea = a.edges()[i as usize];
            let eb = b.edges()[j as usize];
            let (pa, pb) = closest_segment_points(
                &a.vertices()[ea.tail as usize],
                &a.vertices()[ea.head as usize],
                &bv[eb.tail as usize],
                &bv[eb.head as usize],
            );
            done(depth, Feature::Edge(i), Feature::Edge(j), pa, pb)
        }
    })
}

fn validated(a: &ConvexPolyhedron, b: &ConvexPolyhedron, pair: FeaturePair) -> Option<FeaturePair> {
    let ok = |p: &ConvexPolyhedron, f: Feature| match f {
        Feature::Vertex(i) => (i as usize) < p.vertex_count(),
        Feature::Edge(i) => (i as usize) < p.edge_count(),
        Feature::Face(i) => (i as usize) < p.face_count(),
    };
    if !ok(a, pair.a) || !ok(b, pair.b) {
        return None;
    }
    // No state handles two faces; any vertex of A's face is an equally valid start.
    if let (Feature::Face(fa), Feature::Face(_)) = (pair.a, pair.b) {
        let v = a.faces()[fa as usize].vertices[0] as u32;
        return Some(FeaturePair {
            a: Feature::Vertex(v),
            b: pair.b,
        });
    }
    Some(pair)
}

fn cold_start(a: &Side, b: &Side) -> FeaturePair {
    let b_centre_in_a = xf(&a.from_other, &b.poly.centroid());
    let a_centre_in_b = xf(&b.from_other, &a.poly.centroid());
    FeaturePair {
        a: Feature::Vertex(a.poly.support_index(&(b_centre_in_a - a.poly.centroid())) as u32),
        b: Feature::Vertex(b.poly.support_index(&(a_centre_in_b - b.poly.centroid())) as u32),
    }
}

fn step(a: &Side, b: &Side, pair: FeaturePair) -> Step {
    use Feature::*;
    match (pair.a, pair.b) {
        (Vertex(i), Vertex(j)) => vertex_vertex(a, b, i, j),
        (Vertex(i), Edge(j)) => vertex_edge(a, b, i, j),
        (Edge(i), Vertex(j)) => vertex_edge(b, a, j, i).swapped(),
        (Vertex(i), Face(j)) => vertex_face(a, b, i, j),
        (Face(i), Vertex(j)) => vertex_face(b, a, j, i).swapped(),
        (Edge(i), Edge(j)) => edge_edge(a, b, i, j),
        (Edge(i), Face(j)) => edge_face(a, b, i, j),
        (Face(i), Edge(j)) => edge_face(b, a, j, i).swapped(),
        // Unreachable: no transition produces it and `validated` removes it.
        (Face(i), Face(_)) => Step::P(Vertex(a.poly.faces()[i as usize].vertices[0] as u32)),
    }
}

/// The feature across plane `k` of an edge's region: tail, head, left, right.
fn edge_neighbor(k: usize, plane: &VoronoiPlane) -> Feature {
    if k < 2 {
        Feature::Vertex(plane.neighbor)
    } else {
        Feature::Face(plane.neighbor)
    }
}

/// V-V: each vertex must lie inside the other's region, bounded by one plane
/// per incident edge. Crossing a plane means the edge is strictly closer.
fn vertex_vertex(p: &Side, q: &Side, vp: u32, vq: u32) -> Step {
    let xq = xf(&p.from_other, &q.vertex(vq));
    for plane in p.poly.vertex_voronoi_planes(vp as usize) {
        if plane.signed_distance(&xq) < -p.noise {
            return Step::P(Feature::Edge(plane.neighbor));
        }
    }
    let xp = xf(&q.from_other, &p.vertex(vp));
    for plane in q.poly.vertex_voronoi_planes(vq as usize) {
        if plane.signed_distance(&xp) < -q.noise {
            return Step::Q(Feature::Edge(plane.neighbor));
        }
    }
    Step::Done
}

/// V-E, vertex of P against edge of Q.
fn vertex_edge(p: &Side, q: &Side, v: u32, e: u32) -> Step {
    // V against VR(E). The vertex planes come first: beyond one, the edge's
    // nearest point to V is that end vertex (same distance, lower dimension).
    // Beyond a face plane only, moving into the face strictly lowers it.
    let x = xf(&q.from_other, &p.vertex(v));
    for (k, plane) in q.poly.edge_voronoi_planes(e as usize).iter().enumerate() {
        if plane.signed_distance(&x) < -q.noise {
            return Step::Q(edge_neighbor(k, plane));
        }
    }
    // E against VR(V).
    let edge = q.poly.edges()[e as usize];
    let t = xf(&p.from_other, &q.vertex(edge.tail));
    let h = xf(&p.from_other, &q.vertex(edge.head));
    let planes = p.poly.vertex_voronoi_planes(v as usize);
    let c = clip(planes, &t, &h, p.noise);
    if let Some(k) = c.excluded_by {
        return Step::P(Feature::Edge(planes[k].neighbor));
    }
    let vx = p.vertex(v);
    let u = h - t;
    if let Some(k) = c.lo_plane
        && u.dot(&(t + u * c.lo - vx)) > p.noise * u.norm()
    {
        return Step::P(Feature::Edge(planes[k].neighbor));
    }
    if let Some(k) = c.hi_plane
        && u.dot(&(t + u * c.hi - vx)) < -p.noise * u.norm()
    {
        return Step::P(Feature::Edge(planes[k].neighbor));
    }
    // Also reached by a compound exclusion whose derivatives both vanish,
    // which needs E to pass through V: distance 0, a correct answer.
    Step::Done
}

/// V-F, vertex of P against face of Q.
fn vertex_face(p: &Side, q: &Side, v: u32, f: u32) -> Step {
    let x = xf(&q.from_other, &p.vertex(v));
    let side = q.poly.face_voronoi_planes(f as usize);
    if side
        .iter()
        .any(|plane| plane.signed_distance(&x) < -q.noise)
    {
        // V is outside F's prism, so F's nearest point to V is on F's
        // boundary: move to the boundary feature holding it (same distance,
        // lower dimension). Mirtich takes the most violated plane instead;
        // the nearest feature costs the same loop and keeps the distance.
        return Step::Q(nearest_boundary_feature(q.poly, side, |t, h| {
            let (c, lambda) = closest_on_segment(&x, t, h);
            ((x - c).norm_squared(), lambda)
        }));
    }
    let face = &q.poly.faces()[f as usize];
    let d = snap(face.normal.dot(&x) - face.offset, q.noise);
    if d == 0.0 {
        return Step::Done;
    }
    // F in VR(V)? The nearest point of F, x − d n, is in V's region iff no
    // incident edge of V moves towards F's plane: for each edge leaving V
    // towards w, d(w) must not be closer to 0 on the same side.
    for &e in p.poly.vertex_edges(v as usize) {
        let edge = p.poly.edges()[e as usize];
        let other = if edge.tail == v { edge.head } else { edge.tail };
        let w = xf(&q.from_other, &p.vertex(other));
        let dw = face.normal.dot(&w) - face.offset;
        if (d > 0.0 && dw < d - p.noise) || (d < 0.0 && dw > d + p.noise) {
            return Step::P(Feature::Edge(e));
        }
    }
    if d > 0.0 {
        return Step::Done;
    }
    // Local minimum: V lies under F and every incident edge leads away from
    // F's plane. Either some face plane of Q has V outside it (move there and
    // go on), or V is inside every one of them, i.e. inside Q.
    let (g, dmax) = q
        .poly
        .faces()
        .iter()
        .enumerate()
        .map(|(g, fg)| (g, fg.normal.dot(&x) - fg.offset))
        .max_by(|l, r| l.1.total_cmp(&r.1))
        .unwrap_or((f as usize, d));
    if dmax > q.noise {
        return Step::Q(Feature::Face(g as u32));
    }
    let fg = &q.poly.faces()[g];
    Step::Contact(Contact {
        p: Feature::Vertex(v),
        q: Feature::Face(g as u32),
        on_p: p.vertex(v),
        on_q: x - fg.normal * dmax,
        depth: if dmax < -q.noise { dmax } else { 0.0 },
        penetrating: dmax < -q.noise,
    })
}

/// E-E: each edge is clipped against the other's region.
fn edge_edge(p: &Side, q: &Side, ep: u32, eq: u32) -> Step {
    let edge_q = q.poly.edges()[eq as usize];
    let s0 = xf(&p.from_other, &q.vertex(edge_q.tail));
    let s1 = xf(&p.from_other, &q.vertex(edge_q.head));
    if let Some(f) = edge_against_edge_region(p.poly, ep, &s0, &s1, p.noise) {
        return Step::P(f);
    }
    let edge_p = p.poly.edges()[ep as usize];
    let r0 = xf(&q.from_other, &p.vertex(edge_p.tail));
    let r1 = xf(&q.from_other, &p.vertex(edge_p.head));
    if let Some(f) = edge_against_edge_region(q.poly, eq, &r0, &r1, q.noise) {
        return Step::Q(f);
    }
    Step::Done
}

/// Clips segment `s0 s1` (in `poly`'s frame) against VR(e) of `poly`: the
/// two vertex planes first, then the two face planes. Returns the feature
/// `e` should move to, if any.
fn edge_against_edge_region(
    poly: &ConvexPolyhedron,
    e: u32,
    s0: &Vector3<f64>,
    s1: &Vector3<f64>,
    noise: f64,
) -> Option<Feature> {
    let planes = poly.edge_voronoi_planes(e as usize);
    let u = s1 - s0;
    // sign D'(λ) with X = e: u · (s(λ) − nearest point of e). On a vertex
    // plane the nearest point is that vertex; on a face plane it is the
    // projection onto e's line and the difference is along n_F, which gives
    // the face formula of the module doc. Rounding-level values read as 0.
    let flat = noise * u.norm();
    let slope = |lambda: f64| {
        let s = s0 + u * lambda;
        let t = poly.vertices()[poly.edges()[e as usize].tail as usize];
        let dir = poly.edge_direction(e as usize);
        let along = (s - t).dot(&dir).clamp(0.0, poly.edge_length(e as usize));
        let g = u.dot(&(s - t - dir * along));
        if g.abs() <= flat { 0.0 } else { g }
    };
    let mut c = Clip::whole();
    for (k, plane) in planes.iter().enumerate().take(2) {
        if c.cut(k, plane, s0, s1, noise) {
            return Some(edge_neighbor(k, plane));
        }
    }
    let (vlo, vhi, vlo_k, vhi_k) = (c.lo, c.hi, c.lo_plane, c.hi_plane);
    let mut compound = c.lo > c.hi;
    for (k, plane) in planes.iter().enumerate().skip(2) {
        if compound {
            break;
        }
        if c.cut(k, plane, s0, s1, noise) {
            // The segment is wholly on the face's side, yet its nearest point
            // may be an end vertex of e (where the face's angle can be acute,
            // so moving into the face need not help). Vertices win.
            if let Some(j) = vlo_k
                && slope(vlo) > 0.0
            {
                return Some(edge_neighbor(j, &planes[j]));
            }
            if let Some(j) = vhi_k
                && slope(vhi) < 0.0
            {
                return Some(edge_neighbor(j, &planes[j]));
            }
            return Some(edge_neighbor(k, plane));
        }
        compound = c.lo > c.hi;
    }
    let Clip {
        lo,
        hi,
        lo_plane: lo_k,
        hi_plane: hi_k,
        ..
    } = c;
    if compound {
        // The segment misses VR(e), entering the plane of N_hi's region
        // before leaving N_lo's. Convexity of D puts its minimum on the side
        // the derivative points to; vertex neighbours are tested first.
        let (lk, hk) = (lo_k?, hi_k?);
        // Flat at both crossings: the segment runs through e's line.
        if slope(lo) == 0.0 && slope(hi) == 0.0 {
            return None;
        }
        let pick = |k: usize| Some(edge_neighbor(k, &planes[k]));
        return if lk < 2 {
            pick(if slope(lo) >= 0.0 { lk } else { hk })
        } else if hk < 2 {
            pick(if slope(hi) <= 0.0 { hk } else { lk })
        } else {
            pick(if slope(lo) > 0.0 { lk } else { hk })
        };
    }
    if let Some(k) = lo_k
        && slope(lo) > 0.0
    {
        return Some(edge_neighbor(k, &planes[k]));
    }
    if let Some(k) = hi_k
        && slope(hi) < 0.0
    {
        return Some(edge_neighbor(k, &planes[k]));
    }
    None
}

/// E-F, edge of P against face of Q. Never a final state when separated:
/// if E does not meet F, the distance is linear in λ over the clipped
/// interval and is smaller at one of its ends.
fn edge_face(p: &Side, q: &Side, e: u32, f: u32) -> Step {
    let edge = p.poly.edges()[e as usize];
    let (tp, hp) = (p.vertex(edge.tail), p.vertex(edge.head));
    let s0 = xf(&q.from_other, &tp);
    let s1 = xf(&q.from_other, &hp);
    let side = q.poly.face_voronoi_planes(f as usize);
    let c = clip(side, &s0, &s1, q.noise);
    if c.excluded_by.is_some() || c.lo > c.hi {
        // E misses F's prism, so F's nearest point to E is on F's boundary:
        // move F to the boundary feature holding it (same distance, lower
        // dimension). Mirtich's implementation walks the boundary instead.
        return Step::Q(nearest_boundary_feature(q.poly, side, |t, h| {
            let (a, b, _, lambda) = closest_segment_params(&s0, &s1, t, h);
            ((a - b).norm_squared(), lambda)
        }));
    }
    let face = &q.poly.faces()[f as usize];
    let d0 = face.normal.dot(&s0) - face.offset;
    let d1 = face.normal.dot(&s1) - face.offset;
    // Rounding-level heights count as on the plane: an edge through F's rim
    // otherwise alternates between F and the rim edge.
    let dlo = snap(d0 + c.lo * (d1 - d0), p.noise);
    let dhi = snap(d0 + c.hi * (d1 - d0), p.noise);
    if (dlo <= 0.0 && dhi >= 0.0) || (dlo >= 0.0 && dhi <= 0.0) {
        // The clipped edge reaches F's plane inside F's prism: E meets F.
        let touching = dlo >= 0.0 && dhi >= 0.0;
        let (lambda, depth) = if touching {
            (if dlo == 0.0 { c.lo } else { c.hi }, 0.0)
        } else if dlo < dhi {
            (c.lo, dlo)
        } else {
            (c.hi, dhi)
        };
        return Step::Contact(Contact {
            p: Feature::Edge(e),
            q: Feature::Face(f),
            on_p: tp + (hp - tp) * lambda,
            on_q: s0 + (s1 - s0) * lambda - face.normal * depth,
            depth,
            penetrating: !touching,
        });
    }
    // |d| shrinks towards the lower end when d grows along the edge above
    // the plane, or falls along it below. Decided from the whole edge, not
    // the clipped ends, which coincide when the edge only grazes the prism.
    let rising = snap(d1 - d0, p.noise);
    let towards_lo = if dlo > 0.0 {
        rising >= 0.0
    } else {
        rising <= 0.0
    };
    let next = if towards_lo {
        c.lo_plane.map(|k| Step::Q(Feature::Edge(side[k].neighbor)))
    } else {
        c.hi_plane.map(|k| Step::Q(Feature::Edge(side[k].neighbor)))
    };
    next.unwrap_or(Step::P(Feature::Vertex(if towards_lo {
        edge.tail
    } else {
        edge.head
    })))
}

/// The edge or vertex on a face's boundary (its side planes `side`) nearest
/// to a point or segment. `measure(tail, head)` gives the squared distance
/// to one boundary edge and the parameter of the nearest point on it. A
/// nearest point at an edge's end makes that vertex the answer: when two
/// edges tie at their shared vertex, either edge could send the walk back to
/// the face (the derivative at the vertex plane vanishes for parallel
/// edges), the vertex cannot.
fn nearest_boundary_feature(
    poly: &ConvexPolyhedron,
    side: &[VoronoiPlane],
    measure: impl Fn(&Vector3<f64>, &Vector3<f64>) -> (f64, f64),
) -> Feature {
    let mut best = (f64::INFINITY, 0u32, 0.5);
    for plane in side {
        let edge = poly.edges()[plane.neighbor as usize];
        let t = &poly.vertices()[edge.tail as usize];
        let h = &poly.vertices()[edge.head as usize];
        let (d2, lambda) = measure(t, h);
        if d2 < best.0 {
            best = (d2, plane.neighbor, lambda);
        }
    }
    let (_, e, lambda) = best;
    let edge = poly.edges()[e as usize];
    if lambda <= 0.0 {
        Feature::Vertex(edge.tail)
    } else if lambda >= 1.0 {
        Feature::Vertex(edge.head)
    } else {
        Feature::Edge(e)
    }
}

/// A signed distance within rounding of zero is zero: regions are closed,
/// and a point on a shared boundary belongs to both neighbours, as in exact
/// arithmetic. Otherwise an edge lying in a Voronoi plane (a box edge over a
/// box face) gets clipped at a λ chosen by rounding noise.
#[inline]
fn snap(d: f64, noise: f64) -> f64 {
    if d.abs() <= noise { 0.0 } else { d }
}

/// Segment `s0 s1` clipped against a region's planes: the part with every
/// signed distance ≥ 0 is `[lo, hi]`; `lo > hi` means it misses (compound
/// exclusion); `excluded_by` names a plane that both ends lie behind (simple
/// exclusion).
struct Clip {
    lo: f64,
    hi: f64,
    lo_plane: Option<usize>,
    hi_plane: Option<usize>,
    excluded_by: Option<usize>,
}

impl Clip {
    /// The whole segment, `[0, 1]`, before any plane.
    fn whole() -> Clip {
        Clip {
            lo: 0.0,
            hi: 1.0,
            lo_plane: None,
            hi_plane: None,
            excluded_by: None,
        }
    }

    /// Narrows `[lo, hi]` to the side of plane `k` with signed distance
    /// ≥ 0 (distances within `noise` of zero `snap` to it). True where both
    /// ends lie behind the plane (simple exclusion, noted in `excluded_by`),
    /// leaving `[lo, hi]` as it was.
    fn cut(
        &mut self,
        k: usize,
        plane: &VoronoiPlane,
        s0: &Vector3<f64>,
        s1: &Vector3<f64>,
        noise: f64,
    ) -> bool {
        let (d0, d1) = (
            snap(plane.signed_distance(s0), noise),
            snap(plane.signed_distance(s1), noise),
        );
        if d0 < 0.0 && d1 < 0.0 {
            self.excluded_by = Some(k);
            return true;
        }
        if d0 < 0.0 {
            let l = d0 / (d0 - d1);
            if l > self.lo {
                (self.lo, self.lo_plane) = (l, Some(k));
            }
        } else if d1 < 0.0 {
            let l = d0 / (d0 - d1);
            if l < self.hi {
                (self.hi, self.hi_plane) = (l, Some(k));
            }
        }
        false
    }
}

fn clip(planes: &[VoronoiPlane], s0: &Vector3<f64>, s1: &Vector3<f64>, noise: f64) -> Clip {
    let mut c = Clip::whole();
    for (k, plane) in planes.iter().enumerate() {
        if c.cut(k, plane, s0, s1, noise) {
            return c;
        }
        if c.lo > c.hi {
            return c;
        }
    }
    c
}

/// World closest points of a final feature pair.
fn witness(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
    pair: FeaturePair,
) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let segment = |p: &ConvexPolyhedron, pose: &Isometry3<f64>, f: Feature| match f {
        Feature::Vertex(v) => {
            let x = xf(pose, &p.vertices()[v as usize]);
            Some((x, x))
        }
        Feature::Edge(e) => {
            let edge = p.edges()[e as usize];
            Some((
                xf(pose, &p.vertices()[edge.tail as usize]),
                xf(pose, &p.vertices()[edge.head as usize]),
            ))
        }
        Feature::Face(_) => None,
    };
    let onto_face = |p: &ConvexPolyhedron, pose: &Isometry3<f64>, f: u32, x: Vector3<f64>| {
        let face = &p.faces()[f as usize];
        let n = pose.rotation * face.normal;
        let off = face.offset + n.dot(&pose.translation.vector);
        x - n * (n.dot(&x) - off)
    };
    match (pair.a, pair.b) {
        (Feature::Vertex(_), Feature::Face(f)) => {
            let (x, _) = segment(a, pose_a, pair.a)?;
            Some((x, onto_face(b, pose_b, f, x)))
        }
        (Feature::Face(f), Feature::Vertex(_)) => {
            let (y, _) = segment(b, pose_b, pair.b)?;
            Some((onto_face(a, pose_a, f, y), y))
        }
        (fa, fb) => {
            let (p0, p1) = segment(a, pose_a, fa)?;
            let (q0, q1) = segment(b, pose_b, fb)?;
            Some(closest_segment_points(&p0, &p1, &q0, &q1))
        }
    }
}

/// Point of segment `a b` nearest `x`, and its parameter in [0, 1].
pub fn closest_on_segment(
    x: &Vector3<f64>,
    a: &Vector3<f64>,
    b: &Vector3<f64>,
) -> (Vector3<f64>, f64) {
    let u = b - a;
    let uu = u.norm_squared();
    if uu == 0.0 {
        return (*a, 0.0);
    }
    let t = ((x - a).dot(&u) / uu).clamp(0.0, 1.0);
    (a + u * t, t)
}

/// Closest points of segments `p0 p1` and `q0 q1` (Ericson §5.1.9), with
/// (near-)parallel segments handled by clamping from an end point.
pub fn closest_segment_points(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>) {
    let (p, q, _, _) = closest_segment_params(p0, p1, q0, q1);
    (p, q)
}

/// `closest_segment_points` with the parameters s, t ∈ [0, 1] of the two
/// points along their segments.
pub fn closest_segment_params(
    p0: &Vector3<f64>,
    p1: &Vector3<f64>,
    q0: &Vector3<f64>,
    q1: &Vector3<f64>,
) -> (Vector3<f64>, Vector3<f64>, f64, f64) {
    let d1 = p1 - p0;
    let d2 = q1 - q0;
    let r = p0 - q0;
    let a = d1.norm_squared();
    let e = d2.norm_squared();
    let f = d2.dot(&r);
    let (s, t);
    if a == 0.0 && e == 0.0 {
        (s, t) = (0.0, 0.0);
    } else if a == 0.0 {
        (s, t) = (0.0, (f / e).clamp(0.0, 1.0));
    } else {
        let c = d1.dot(&r);
        if e == 0.0 {
            (s, t) = ((-c / a).clamp(0.0, 1.0), 0.0);
        } else {
            let b = d1.dot(&d2);
            let denom = a * e - b * b;
            // For parallel segments any s works; start from s = 0 and let
            // the clamping below find the overlap's end.
            let s0 = if denom > 1e-14 * a * e {
                ((b * f - c * e) / denom).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let t0 = (b * s0 + f) / e;
            if t0 < 0.0 {
                (s, t) = ((-c / a).clamp(0.0, 1.0), 0.0);
            } else if t0 > 1.0 {
                (s, t) = (((b - c) / a).clamp(0.0, 1.0), 1.0);
            } else {
                (s, t) = (s0, t0);
            }
        }
    }
    (p0 + d1 * s, q0 + d2 * t, s, t)
}

/// The fallback: exact by exhaustion. Penetration from the separating-axis
/// test; otherwise the minimum over vertex-face, face-vertex and edge-edge
/// pairs, which covers every way the closest points of two convex
/// polyhedra can lie.
pub fn exhaustive(
    a: &ConvexPolyhedron,
    pose_a: &Isometry3<f64>,
    b: &ConvexPolyhedron,
    pose_b: &Isometry3<f64>,
) -> Proximity {
    if let Some(deep) = sat_penetration(a, pose_a, b, pose_b, 0.0) {
        return deep;
    }
    let b_to_a = pose_a.inv_mul(pose_b);
    let bv: Vec<Vector3<f64>> = b.vertices().iter().map(|v| xf(&b_to_a, v)).collect();
    let world = |x: &Vector3<f64>| xf(pose_a, x);
    let done = |distance, penetrating, fa, fb, pa: Vector3<f64>, pb: Vector3<f64>| Proximity {
        distance,
        penetrating,
        features: FeaturePair { a: fa, b: fb },
        point_a: world(&pa),
        point_b: world(&pb),
        iterations: 0,
        fell_back: false,
    };

    let mut best = (
        f64::INFINITY,
        Feature::Vertex(0),
        Feature::Vertex(0),
        Vector3::zeros(),
        Vector3::zeros(),
    );
    let mut consider = |d2: f64, fa, fb, pa, pb| {
        if d2 < best.0 {
            best = (d2, fa, fb, pa, pb);
        }
    };
    for (i, ea) in a.edges().iter().enumerate() {
        let (p0, p1) = (
            a.vertices()[ea.tail as usize],
            a.vertices()[ea.head as usize],
        );
        for (j, eb) in b.edges().iter().enumerate() {
            let (pa, pb) =
                closest_segment_points(&p0, &p1, &bv[eb.tail as usize], &bv[eb.head as usize]);
            consider(
                (pa - pb).norm_squared(),
                Feature::Edge(i as u32),
                Feature::Edge(j as u32),
                pa,
                pb,
            );
        }
    }
    // A vertex in a face's prism counts when above the face plane, or below
    // it by rounding only (the test above found no overlap); deeper below, it
    // is under the far side of that polyhedron, not near this face.
    let below = -TOUCHING_REL_TOL * a.scale().min(b.scale());
    let a_to_b = b_to_a.inverse();
    for (j, face) in b.faces().iter().enumerate() {
        for (i, x) in a.vertices().iter().enumerate() {
            let xb = xf(&a_to_b, x);
            let d = face.normal.dot(&xb) - face.offset;
            if d >= below
                && b.face_voronoi_planes(j)
                    .iter()
                    .all(|p| p.signed_distance(&xb) >= 0.0)
            {
                let pb = xf(&b_to_a, &(xb - face.normal * d));
                consider(
                    d * d,
                    Feature::Vertex(i as u32),
                    Feature::Face(j as u32),
                    *x,
                    pb,
                );
            }
        }
    }
    for (i, face) in a.faces().iter().enumerate() {
        for (j, y) in bv.iter().enumerate() {
            let d = face.normal.dot(y) - face.offset;
            if d >= below
                && a.face_voronoi_planes(i)
                    .iter()
                    .all(|p| p.signed_distance(y) >= 0.0)
            {
                consider(
                    d * d,
                    Feature::Face(i as u32),
                    Feature::Vertex(j as u32),
                    y - face.normal * d,
                    *y,
                );
            }
        }
    }
    let (_, fa, fb, pa, pb) = best;
    // Report the lowest-dimensional pair, so the cached warm start is the
    // one V-Clip itself would end on.
    let fa = lower_feature(a, fa, &pa);
    let fb = lower_feature(b, fb, &xf(&b_to_a.inverse(), &pb));
    done((pa - pb).norm(), false, fa, fb, pa, pb)
}

/// An edge whose witness point is one of its ends becomes that vertex.
fn lower_feature(p: &ConvexPolyhedron, f: Feature, x: &Vector3<f64>) -> Feature {
    if let Feature::Edge(e) = f {
        let edge = p.edges()[e as usize];
        for v in [edge.tail, edge.head] {
            if (p.vertices()[v as usize] - x).norm() <= 1e-12 * p.scale() {
                return Feature::Vertex(v);
            }
        }
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn segments_closest_points_cover_parallel_and_degenerate_cases() {
        let z = Vector3::zeros();
        let x = Vector3::x();
        let (p, q) = closest_segment_points(
            &z,
            &x,
            &Vector3::new(0.5, 1.0, 0.0),
            &Vector3::new(2.0, 1.0, 0.0),
        );
        assert!(((p - q).norm() - 1.0).abs() < 1e-15);
        let (p, q) = closest_segment_points(
            &z,
            &z,
            &Vector3::new(0.5, 1.0, 0.0),
            &Vector3::new(0.5, 1.0, 0.0),
        );
        assert_eq!((p, q), (z, Vector3::new(0.5, 1.0, 0.0)));
        let (p, q) = closest_segment_points(
            &z,
            &x,
            &Vector3::new(3.0, 0.0, 1.0),
            &Vector3::new(3.0, 0.0, 2.0),
        );
        assert_eq!((p, q), (x, Vector3::new(3.0, 0.0, 1.0)));
    }
}
