//! The polyhedra rigidsim simulates, as triangles for the page: every convex
//! part of an object, in its body frame (origin at the centre of mass), one
//! triangle list per object so that all its bodies share one instanced mesh.

use rigidsim::body::ObjectDef;

/// One object's triangles: `positions` holds x, y, z per vertex (body frame),
/// `indices` three vertex numbers per triangle, counter-clockwise seen from
/// outside, so three.js's front faces are the outside.
pub struct TriangleMesh {
    pub positions: Vec<f32>,
    pub indices: Vec<u32>,
}

/// The parts of `object`, triangulated. A face of a convex polyhedron is a
/// convex polygon, so a fan from its first vertex covers it exactly and keeps
/// its winding; the parts' vertices are numbered one after another.
pub fn triangulate(object: &ObjectDef) -> TriangleMesh {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for part in &object.parts {
        let first = (positions.len() / 3) as u32;
        for v in part.hull.vertices() {
            positions.extend([v.x as f32, v.y as f32, v.z as f32]);
        }
        for face in part.hull.faces() {
            let loop_ = &face.vertices;
            for k in 1..loop_.len().saturating_sub(1) {
                indices.extend([loop_[0], loop_[k], loop_[k + 1]].map(|i| first + i as u32));
            }
        }
    }
    TriangleMesh { positions, indices }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A box's six quadrilateral faces become twelve triangles over its eight
    /// corners, each wound so that its normal points away from the centre.
    #[test]
    fn a_box_becomes_twelve_outward_triangles() {
        let scene = rigidsim::scene::load(std::path::Path::new("scenes/render_check.toml"))
            .expect("bundled scene loads");
        let cube = scene.objects.iter().find(|o| o.name == "cube").unwrap();
        let mesh = triangulate(cube);
        assert_eq!(mesh.positions.len(), 8 * 3);
        assert_eq!(mesh.indices.len(), 12 * 3);
        let p = |i: u32| {
            let i = i as usize * 3;
            nalgebra::Vector3::new(
                mesh.positions[i],
                mesh.positions[i + 1],
                mesh.positions[i + 2],
            )
        };
        for t in mesh.indices.chunks(3) {
            let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
            let normal = (b - a).cross(&(c - a));
            let centroid = (a + b + c) / 3.0;
            assert!(normal.dot(&centroid) > 0.0, "triangle {t:?} faces inwards");
        }
    }
}
