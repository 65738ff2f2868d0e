use std::collections::HashMap;

use bytemuck::{Pod, Zeroable};
use nalgebra::Vector3;

use super::RenderError;

/// One object definition's triangle mesh, in its body frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    /// Three indices per triangle. Winding need not be outward: a closed
    /// mesh is re-wound part by part, an open one is drawn two-sided.
    pub indices: Vec<u32>,
}

impl Mesh {
    /// An axis-aligned box centred on the body origin, outward
    /// counter-clockwise winding.
    pub fn cuboid(half_extents: [f32; 3]) -> Mesh {
        let [hx, hy, hz] = half_extents;
        let positions = (0..8)
            .map(|i| {
                [
                    if i & 1 == 0 { -hx } else { hx },
                    if i & 2 == 0 { -hy } else { hy },
                    if i & 4 == 0 { -hz } else { hz },
                ]
            })
            .collect();
        #[rustfmt::skip]
        let indices = vec![
            0, 2, 3, 0, 3, 1, // -z
            4, 5, 7, 4, 7, 6, // +z
            0, 1, 5, 0, 5, 4, // -y
            2, 6, 7, 2, 7, 3, // +y
            0, 4, 6, 0, 6, 2, // -x
            1, 3, 7, 1, 7, 5, // +x
        ];
        Mesh { positions, indices }
    }
}

/// Vertex as the GPU sees it: every triangle has its own three vertices so
/// each carries its face normal (flat shading without derivatives, which
/// GL via llvmpipe and lavapipe both handle, at 3 vertices a triangle).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct Vertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
}

pub(crate) struct FlatMesh {
    pub vertices: Vec<Vertex>,
    /// Closed and now wound outward (counter-clockwise seen from outside):
    /// back faces can be culled, which halves lavapipe's frame time.
    /// Otherwise the mesh is drawn two-sided.
    pub closed: bool,
    /// Largest distance of a vertex from the body origin: the bounding
    /// sphere around the body's translation, used for near/far planes.
    pub radius: f32,
    /// Body-frame axis-aligned box, for framing a scene.
    pub bounds: [[f32; 3]; 2],
    /// Checker cell size for fixed bodies: 1/8 of the mesh's largest
    /// extent, so a floor shows a readable 8-ish cells across whatever its
    /// units.
    pub checker_cell: f32,
}

pub(crate) fn flatten(index: usize, mesh: &Mesh) -> Result<FlatMesh, RenderError> {
    let bad = |reason: String| RenderError::BadMesh {
        mesh: index,
        reason,
    };
    if mesh.indices.len() % 3 != 0 {
        return Err(bad(format!(
            "{} indices is not a whole number of triangles",
            mesh.indices.len()
        )));
    }
    if let Some(p) = mesh
        .positions
        .iter()
        .find(|p| !p.iter().all(|v| v.is_finite()))
    {
        return Err(bad(format!("non-finite vertex {p:?}")));
    }
    if let Some(&i) = mesh
        .indices
        .iter()
        .find(|&&i| i as usize >= mesh.positions.len())
    {
        return Err(bad(format!(
            "index {i} but only {} positions",
            mesh.positions.len()
        )));
    }

    let (ids, welded) = weld(&mesh.positions);
    // Zero-area triangles have no normal and cover no pixel.
    let mut triangles: Vec<[u32; 3]> = mesh
        .indices
        .chunks_exact(3)
        .map(|t| [ids[t[0] as usize], ids[t[1] as usize], ids[t[2] as usize]])
        .filter(|&[a, b, c]| {
            let [a, b, c] = [a, b, c].map(|i| Vector3::from(welded[i as usize]));
            (b - a).cross(&(c - a)).norm_squared() > 0.0
        })
        .collect();
    let closed = orient_outward(&mut triangles, &welded);

    let mut vertices = Vec::with_capacity(triangles.len() * 3);
    for tri in &triangles {
        let [a, b, c] = tri.map(|i| Vector3::from(welded[i as usize]));
        let normal = (b - a).cross(&(c - a)).normalize();
        for p in [a, b, c] {
            vertices.push(Vertex {
                position: p.into(),
                normal: normal.into(),
            });
        }
    }

    let radius = mesh
        .positions
        .iter()
        .map(|p| Vector3::from(*p).norm())
        .fold(0.0f32, f32::max);
    let first = mesh.positions.first().copied().unwrap_or_default();
    let (lo, hi) = mesh.positions.iter().fold((first, first), |(lo, hi), p| {
        (
            std::array::from_fn(|k| lo[k].min(p[k])),
            std::array::from_fn(|k| hi[k].max(p[k])),
        )
    });
    let extent = (0..3).map(|k| hi[k] - lo[k]).fold(0.0f32, f32::max);
    let checker_cell = if extent > 0.0 { extent / 8.0 } else { 1.0 };
    Ok(FlatMesh {
        vertices,
        closed,
        radius,
        bounds: [lo, hi],
        checker_cell,
    })
}

/// Gives vertices with bit-identical coordinates one id, so meshes stored
/// with a vertex per face corner (STL) still share their edges. Returns the
/// id of every input vertex and the position of every id.
fn weld(positions: &[[f32; 3]]) -> (Vec<u32>, Vec<[f32; 3]>) {
    let mut seen: HashMap<[u32; 3], u32> = HashMap::with_capacity(positions.len());
    let mut welded = Vec::new();
    let ids = positions
        .iter()
        .map(|p| {
            // +0.0 folds -0.0 into 0.0, which compare equal but differ in bits.
            let key = p.map(|v| (v + 0.0).to_bits());
            *seen.entry(key).or_insert_with(|| {
                welded.push(*p);
                welded.len() as u32 - 1
            })
        })
        .collect();
    (ids, welded)
}

/// If every edge is used exactly once in each direction, the mesh is a set
/// of closed, consistently wound surfaces (one per connected part: a desk
/// made of a top and legs has five). Each part whose signed volume
/// V = Σ a·(b×c)/6 is negative is wound inward and gets flipped. Returns
/// whether the mesh was closed; an open or inconsistent mesh is left as is.
fn orient_outward(triangles: &mut [[u32; 3]], positions: &[[f32; 3]]) -> bool {
    let mut edge_owner: HashMap<(u32, u32), usize> = HashMap::with_capacity(triangles.len() * 3);
    for (t, &[a, b, c]) in triangles.iter().enumerate() {
        for edge in [(a, b), (b, c), (c, a)] {
            if edge_owner.insert(edge, t).is_some() {
                return false;
            }
        }
    }
    let mut parent: Vec<usize> = (0..triangles.len()).collect();
    fn root(parent: &mut [usize], mut t: usize) -> usize {
        while parent[t] != t {
            parent[t] = parent[parent[t]];
            t = parent[t];
        }
        t
    }
    for (&(a, b), &t) in &edge_owner {
        let Some(&twin) = edge_owner.get(&(b, a)) else {
            return false;
        };
        let (r, s) = (root(&mut parent, t), root(&mut parent, twin));
        parent[r] = s;
    }

    let mut volume: HashMap<usize, f64> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        let [a, b, c] = tri.map(|i| Vector3::from(positions[i as usize]).cast::<f64>());
        *volume.entry(root(&mut parent, t)).or_default() += a.dot(&b.cross(&c));
    }
    for (t, tri) in triangles.iter_mut().enumerate() {
        if volume[&root(&mut parent, t)] < 0.0 {
            tri.swap(1, 2);
        }
    }
    true
}
