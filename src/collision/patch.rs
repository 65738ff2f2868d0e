//! A body pair's contact points reduced to its contact patches, exactly.
//!
//! Points that share a normal form one patch. A normal row at a point inside
//! the patch's convex hull (in the contact plane) is a convex combination of
//! the rows at the hull's vertices: its normal speed is the same combination
//! of theirs, and any normal force on it is a combination of forces on them.
//! Keeping the hull's vertices therefore keeps the set of normal wrenches the
//! patch can press with, and its support polygon, exactly; the deepest point
//! is kept too, so the overlap the contact solve mends is the one measured.
//!
//! Friction, one pair of rows per kept point along that point's own slip
//! direction, keeps the patch's total friction bound (μ times its total
//! normal force), but not where inside the patch that friction acts: a patch
//! spinning about its normal meets the torsional friction of its hull's
//! vertices, which lie farther out than the points dropped.

use super::manifold::ContactPoint;
use nalgebra::Vector3;

/// Contact normals closer than this (1 − cos of about 45 µrad) share a patch:
/// coincident up to the rounding of the features' directions, far below the
/// 9° between neighbouring faces of the thesis's 40-sided bolt shaft.
pub const SAME_NORMAL: f64 = 1e-9;

/// A point within this fraction of the patch's size² of the line through
/// two hull vertices counts as on it (rounding), so is not a vertex.
const COLLINEAR_REL: f64 = 1e-12;

/// The points of one body pair reduced to the hull vertices and the deepest
/// point of each patch, patch by patch (in the order of their first
/// points), each patch's in the order they came: the result depends on the
/// points alone, and a patch's points are consecutive.
pub fn reduce_to_patches(points: Vec<ContactPoint>) -> Vec<ContactPoint> {
    if points.len() <= 2 {
        return points;
    }
    let normals: Vec<Vector3<f64>> = points.iter().map(|p| p.normal).collect();
    let mut keep = Vec::with_capacity(points.len());
    for patch in patches(&normals) {
        let at: Vec<Vector3<f64>> = patch.iter().map(|&i| points[i].point).collect();
        let depth: Vec<f64> = patch.iter().map(|&i| points[i].separation).collect();
        keep.extend(kept_points(&at, &normals[patch[0]], &depth).map(|k| patch[k]));
    }
    keep.into_iter().map(|i| points[i]).collect()
}

/// Whether two unit contact normals share a patch (`SAME_NORMAL`).
pub fn same_normal(n: &Vector3<f64>, m: &Vector3<f64>) -> bool {
    n.dot(m) >= 1.0 - SAME_NORMAL
}

/// Indices of the points grouped by shared normal, each group in the order
/// its points came, groups in the order of their first point.
pub fn patches(normals: &[Vector3<f64>]) -> Vec<Vec<usize>> {
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (i, n) in normals.iter().enumerate() {
        match groups.iter_mut().find(|g| same_normal(&normals[g[0]], n)) {
            Some(g) => g.push(i),
            None => groups.push(vec![i]),
        }
    }
    groups
}

/// Of one patch's points (normal `normal`, gaps `separation`), the indices
/// of its hull's vertices in the contact plane and of its deepest point,
/// ascending.
pub fn kept_points(
    points: &[Vector3<f64>],
    normal: &Vector3<f64>,
    separation: &[f64],
) -> impl Iterator<Item = usize> {
    let mut keep = hull_vertices(points, normal);
    let deepest =
        (0..points.len()).min_by(|&i, &j| separation[i].total_cmp(&separation[j]).then(i.cmp(&j)));
    keep.extend(deepest);
    keep.sort_unstable();
    keep.dedup();
    keep.into_iter()
}

/// Indices of the vertices of the points' convex hull projected on the
/// plane normal to `normal` (Andrew's monotone chain). Points on a hull
/// edge, or repeating a vertex, are not vertices. A patch of collinear
/// points gives its two ends; a patch of one point, that point.
fn hull_vertices(points: &[Vector3<f64>], normal: &Vector3<f64>) -> Vec<usize> {
    if points.len() <= 2 {
        return (0..points.len()).collect();
    }
    let (u, v) = plane_axes(normal);
    let flat: Vec<(f64, f64)> = points.iter().map(|p| (u.dot(p), v.dot(p))).collect();
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&i, &j| {
        flat[i]
            .0
            .total_cmp(&flat[j].0)
            .then(flat[i].1.total_cmp(&flat[j].1))
            .then(i.cmp(&j))
    });
    let (first, last) = (flat[order[0]], flat[order[order.len() - 1]]);
    let size2 = (last.0 - first.0).powi(2) + (last.1 - first.1).powi(2);
    let slack = COLLINEAR_REL * size2.max(f64::MIN_POSITIVE);
    let turns_left = |o: usize, a: usize, b: usize| {
        let (o, a, b) = (flat[o], flat[a], flat[b]);
        (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0) > slack
    };
    let mut hull: Vec<usize> = Vec::with_capacity(2 * points.len());
    for pass in [order.clone(), order.into_iter().rev().collect()] {
        let floor = hull.len();
        for i in pass {
            while hull.len() >= floor + 2
                && !turns_left(hull[hull.len() - 2], hull[hull.len() - 1], i)
            {
                hull.pop();
            }
            hull.push(i);
        }
        hull.pop();
    }
    hull.sort_unstable();
    hull.dedup();
    hull
}

/// Two unit axes spanning the plane normal to the unit `n`.
fn plane_axes(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let helper = if n.x.abs() < 0.6 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let u = (helper - n * n.dot(&helper)).normalize();
    (u, n.cross(&u))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::collision::manifold::NormalTurn;

    fn at(x: f64, y: f64, separation: f64) -> ContactPoint {
        ContactPoint {
            point: Vector3::new(x, y, 0.0),
            normal: Vector3::z(),
            separation,
            turns: NormalTurn::WithB,
        }
    }

    #[test]
    fn a_patch_keeps_its_hull_and_its_deepest_point() {
        // A square's corners, its edge midpoints, its centre (deepest) and
        // a point inside.
        let mut points: Vec<ContactPoint> = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
            .iter()
            .map(|&(x, y)| at(x, y, 0.0))
            .collect();
        points.push(at(0.5, 0.0, 0.0));
        points.push(at(1.0, 0.5, 0.0));
        points.push(at(0.5, 0.5, -1e-6));
        points.push(at(0.2, 0.7, 0.0));
        let kept = reduce_to_patches(points.clone());
        assert_eq!(
            kept,
            [points[0], points[1], points[2], points[3], points[6]]
        );
    }

    #[test]
    fn a_many_sided_patch_is_not_capped() {
        let points: Vec<ContactPoint> = (0..40)
            .map(|k| {
                let a = std::f64::consts::TAU * k as f64 / 40.0;
                at(crate::math::cos(a), crate::math::sin(a), 0.0)
            })
            .collect();
        assert_eq!(reduce_to_patches(points.clone()), points);
    }

    #[test]
    fn patches_with_other_normals_are_kept_apart() {
        let mut points: Vec<ContactPoint> = (0..5).map(|k| at(k as f64, 0.0, 0.0)).collect();
        let turned = nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), 0.1);
        for p in points.clone() {
            points.push(ContactPoint {
                normal: turned * p.normal,
                ..p
            });
        }
        // Each is a segment: its two ends (the deepest is the first, an end).
        let kept = reduce_to_patches(points.clone());
        assert_eq!(kept, [points[0], points[4], points[5], points[9]]);
    }

    #[test]
    fn repeated_points_count_once() {
        let points = vec![
            at(0.0, 0.0, 0.0),
            at(0.0, 0.0, 0.0),
            at(1.0, 0.0, 0.0),
            at(1.0, 0.0, 0.0),
        ];
        assert_eq!(reduce_to_patches(points.clone()), [points[0], points[3]]);
    }
}
