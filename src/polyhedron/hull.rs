//! Quickhull (Barber, Dobkin & Huhdanpaa 1996): the triangles of the convex
//! hull of a point set, for `ConvexPolyhedron::hull` to merge.

use std::collections::HashMap;

use nalgebra::Vector3;

use super::{HULL_REL_EPS, PolyhedronError, bbox_diagonal, coordinate_rounding};
use PolyhedronError as E;

/// A triangle of the hull being built, with the points outside it that it
/// is to take in. `alive` is false once a cone has replaced it.
struct HullFace {
    v: [usize; 3],
    normal: Vector3<f64>,
    offset: f64,
    outside: Vec<usize>,
    alive: bool,
}

impl HullFace {
    fn new(v: [usize; 3], pts: &[Vector3<f64>]) -> Self {
        let [a, b, c] = v.map(|i| pts[i]);
        // Of the three edge cross products, the one from the longest two
        // edges' shared vertex is the best conditioned; the plain one is fine
        // here because near-degenerate triangles are merged away later.
        let normal = (b - a).cross(&(c - a)).normalize();
        Self {
            v,
            normal,
            offset: normal.dot(&a),
            outside: Vec::new(),
            alive: true,
        }
    }

    fn distance(&self, p: &Vector3<f64>) -> f64 {
        self.normal.dot(p) - self.offset
    }
}

/// The hull's triangle on the left of each directed edge (tail, head).
type EdgeFaces = HashMap<(usize, usize), usize>;

/// Vertices and CCW face loops.
type Mesh = (Vec<Vector3<f64>>, Vec<Vec<usize>>);

/// Quickhull: returns the input points and CCW triangles of their hull.
pub(super) fn quickhull(points: &[Vector3<f64>]) -> Result<Mesh, PolyhedronError> {
    let eps = tolerance(points)?;
    let tetrahedron = initial_tetrahedron(points, eps)?;
    let (mut faces, mut edge_face) = tetrahedron_faces(points, tetrahedron, eps);
    let mut pending: Vec<usize> = (0..faces.len()).collect();
    let mut visible_mark: Vec<bool> = vec![false; faces.len()];
    while let Some(f) = pending.pop() {
        if !faces[f].alive || faces[f].outside.is_empty() {
            continue;
        }
        let apex = farthest_outside(&faces[f], points);
        let p = points[apex];
        let visible = visible_from(&faces, &edge_face, &mut visible_mark, f, p, eps)?;
        let horizon = horizon_of(&faces, &edge_face, &visible_mark, &visible)?;
        let orphans = remove_visible(&mut faces, &mut edge_face, &mut visible_mark, &visible);
        let first_new = faces.len();
        add_cone(
            &mut faces,
            &mut edge_face,
            &mut visible_mark,
            horizon,
            apex,
            points,
        );
        give_orphans_to_cone(&mut faces[first_new..], orphans, apex, points, eps);
        pending.extend(first_new..faces.len());
    }

    let tris = faces
        .iter()
        .filter(|f| f.alive)
        .map(|f| f.v.to_vec())
        .collect();
    Ok((points.to_vec(), tris))
}

/// The length within which a point counts as on a face plane:
/// `HULL_REL_EPS` of the bounding-box diagonal, at least the coordinates' rounding.
/// Refuses fewer than 4 points, non-finite ones, and points all at one place.
fn tolerance(points: &[Vector3<f64>]) -> Result<f64, PolyhedronError> {
    if points.len() < 4 {
        return Err(E::TooFewPoints {
            count: points.len(),
        });
    }
    for (i, v) in points.iter().enumerate() {
        if !v.iter().all(|c| c.is_finite()) {
            return Err(E::NonFinite { vertex: i });
        }
    }
    let scale = bbox_diagonal(points.iter());
    let eps = (HULL_REL_EPS * scale).max(coordinate_rounding(points.iter()));
    let coincident = E::DegenerateHull {
        shape: "coincident",
    };
    if scale == 0.0 {
        return Err(coincident);
    }
    Ok(eps)
}

/// Initial tetrahedron from extreme points: the two farthest apart of the
/// extremes along the axes, the point farthest from their line, the point
/// farthest from the plane of those three. Refuses points that are
/// (nearly) coincident, collinear or coplanar.
fn initial_tetrahedron(points: &[Vector3<f64>], eps: f64) -> Result<[usize; 4], PolyhedronError> {
    let coincident = E::DegenerateHull {
        shape: "coincident",
    };
    let mut extremes = Vec::new();
    for k in 0..3 {
        let lo = (0..points.len())
            .min_by(|&a, &b| points[a][k].total_cmp(&points[b][k]))
            .unwrap();
        let hi = (0..points.len())
            .max_by(|&a, &b| points[a][k].total_cmp(&points[b][k]))
            .unwrap();
        extremes.extend([lo, hi]);
    }
    let (mut i0, mut i1, mut best) = (0, 0, -1.0);
    for &a in &extremes {
        for &b in &extremes {
            let d = (points[a] - points[b]).norm();
            if d > best {
                (i0, i1, best) = (a, b, d);
            }
        }
    }
    if best <= eps {
        return Err(coincident);
    }
    let axis = (points[i1] - points[i0]) / best;
    let line_distance = |p: &Vector3<f64>| {
        let d = p - points[i0];
        (d - axis * d.dot(&axis)).norm()
    };
    let i2 = (0..points.len())
        .max_by(|&a, &b| line_distance(&points[a]).total_cmp(&line_distance(&points[b])))
        .unwrap();
    if line_distance(&points[i2]) <= eps {
        return Err(E::DegenerateHull { shape: "collinear" });
    }
    let n = (points[i1] - points[i0])
        .cross(&(points[i2] - points[i0]))
        .normalize();
    let plane_distance = |p: &Vector3<f64>| n.dot(&(p - points[i0]));
    let i3 = (0..points.len())
        .max_by(|&a, &b| {
            plane_distance(&points[a])
                .abs()
                .total_cmp(&plane_distance(&points[b]).abs())
        })
        .unwrap();
    if plane_distance(&points[i3]).abs() <= eps {
        return Err(E::DegenerateHull { shape: "coplanar" });
    }
    Ok([i0, i1, i2, i3])
}

/// The tetrahedron's four faces, wound outwards, and each other point put
/// in the outside set of the first face it lies outside of.
fn tetrahedron_faces(
    points: &[Vector3<f64>],
    [i0, i1, i2, i3]: [usize; 4],
    eps: f64,
) -> (Vec<HullFace>, EdgeFaces) {
    let mut faces: Vec<HullFace> = Vec::new();
    let mut edge_face: HashMap<(usize, usize), usize> = HashMap::new();
    let inside = (points[i0] + points[i1] + points[i2] + points[i3]) / 4.0;
    for tri in [[i0, i1, i2], [i0, i1, i3], [i0, i2, i3], [i1, i2, i3]] {
        let mut f = HullFace::new(tri, points);
        if f.distance(&inside) > 0.0 {
            f = HullFace::new([tri[0], tri[2], tri[1]], points);
        }
        let id = faces.len();
        for k in 0..3 {
            edge_face.insert((f.v[k], f.v[(k + 1) % 3]), id);
        }
        faces.push(f);
    }
    for (p, point) in points.iter().enumerate() {
        if [i0, i1, i2, i3].contains(&p) {
            continue;
        }
        if let Some(f) = faces.iter_mut().find(|f| f.distance(point) > eps) {
            f.outside.push(p);
        }
    }
    (faces, edge_face)
}

/// The point of the face's outside set farthest from its plane.
fn farthest_outside(face: &HullFace, points: &[Vector3<f64>]) -> usize {
    *face
        .outside
        .iter()
        .max_by(|&&a, &&b| {
            face.distance(&points[a])
                .total_cmp(&face.distance(&points[b]))
        })
        .unwrap()
}

/// The faces the apex sees, grown from f across shared edges; each is
/// marked in `visible_mark`.
fn visible_from(
    faces: &[HullFace],
    edge_face: &EdgeFaces,
    visible_mark: &mut [bool],
    f: usize,
    p: Vector3<f64>,
    eps: f64,
) -> Result<Vec<usize>, PolyhedronError> {
    let mut visible = vec![f];
    visible_mark[f] = true;
    let mut k = 0;
    while k < visible.len() {
        let g = visible[k];
        k += 1;
        let v = faces[g].v;
        for e in 0..3 {
            let Some(&h) = edge_face.get(&(v[(e + 1) % 3], v[e])) else {
                return Err(E::HullNumerics);
            };
            if !visible_mark[h] && faces[h].distance(&p) > eps {
                visible_mark[h] = true;
                visible.push(h);
            }
        }
    }
    Ok(visible)
}

/// The horizon must be one simple loop, or the new cone of faces
/// would not close up: each of its vertices starts exactly one edge.
/// Returns its edges, each as the visible face runs it.
fn horizon_of(
    faces: &[HullFace],
    edge_face: &EdgeFaces,
    visible_mark: &[bool],
    visible: &[usize],
) -> Result<Vec<(usize, usize)>, PolyhedronError> {
    let mut horizon = Vec::new();
    for &g in visible {
        let v = faces[g].v;
        for e in 0..3 {
            let (a, b) = (v[e], v[(e + 1) % 3]);
            let Some(&h) = edge_face.get(&(b, a)) else {
                return Err(E::HullNumerics);
            };
            if !visible_mark[h] {
                horizon.push((a, b));
            }
        }
    }
    let mut tails: Vec<usize> = horizon.iter().map(|&(a, _)| a).collect();
    tails.sort_unstable();
    if tails.windows(2).any(|w| w[0] == w[1]) {
        return Err(E::HullNumerics);
    }
    Ok(horizon)
}

/// Kills the visible faces, unmarks them, takes their edges out of
/// `edge_face`, and returns the points that were outside them.
fn remove_visible(
    faces: &mut [HullFace],
    edge_face: &mut EdgeFaces,
    visible_mark: &mut [bool],
    visible: &[usize],
) -> Vec<usize> {
    let mut orphans = Vec::new();
    for &g in visible {
        faces[g].alive = false;
        visible_mark[g] = false;
        let v = faces[g].v;
        for e in 0..3 {
            edge_face.remove(&(v[e], v[(e + 1) % 3]));
        }
        orphans.append(&mut faces[g].outside);
    }
    orphans
}

/// A new face from each horizon edge to the apex.
fn add_cone(
    faces: &mut Vec<HullFace>,
    edge_face: &mut EdgeFaces,
    visible_mark: &mut Vec<bool>,
    horizon: Vec<(usize, usize)>,
    apex: usize,
    points: &[Vector3<f64>],
) {
    for (a, b) in horizon {
        let id = faces.len();
        let nf = HullFace::new([a, b, apex], points);
        for k in 0..3 {
            edge_face.insert((nf.v[k], nf.v[(k + 1) % 3]), id);
        }
        faces.push(nf);
        visible_mark.push(false);
    }
}

/// Each point that was outside a removed face (the apex aside) goes to
/// the first new face it lies outside of; inside them all, it is inside
/// the hull.
fn give_orphans_to_cone(
    cone: &mut [HullFace],
    orphans: Vec<usize>,
    apex: usize,
    points: &[Vector3<f64>],
    eps: f64,
) {
    for q in orphans {
        if q == apex {
            continue;
        }
        if let Some(nf) = cone.iter_mut().find(|nf| nf.distance(&points[q]) > eps) {
            nf.outside.push(q);
        }
    }
}
