//! Convex polyhedra, the shape of every body part: winged-edge topology plus
//! the Voronoi-region planes that V-Clip (`crate::collision::vclip`) walks.
//! A leaf below `body` and `collision`: it imports nothing of the crate.
//!
//! Conventions, relied on by `vclip` and `manifold`:
//! - Face loops run counter-clockwise seen from outside; `Face::normal` is the
//!   unit outward normal and `normal · x = offset` on the face plane.
//! - Edge `e` runs `tail → head` with unit direction `u`. Its `left` face
//!   traverses it tail → head, its `right` face head → tail. Seen from
//!   outside, the interior of a CCW face lies to the left of its edges, so the
//!   left face's interior is on the side `n_L × u` of the edge and the right
//!   face's interior on the side `u × n_R`.
//! - Voronoi planes are stored as `n · x − offset = d`, with `d ≥ 0` on the
//!   side of the feature that owns them; `neighbor` is the feature on the
//!   other side:
//!   - vertex `v`, one plane per incident edge with direction `w` leaving `v`:
//!     `d = −w · (x − v)`, neighbour the edge;
//!   - edge `e`, four planes `[tail, head, left, right]`:
//!     `u · (x − t)`, `−u · (x − h)`, `(u × n_L) · (x − t)`, `(n_R × u) · (x − t)`,
//!     neighbours the tail vertex, head vertex, left face, right face;
//!   - face `f`, one side plane per boundary edge, the edge plane above with
//!     its sign flipped, neighbour the edge.
//!
//!   The face's own plane is not among them: a face's region is the half
//!   prism above it, and V-Clip tests the face plane separately.

use std::collections::HashMap;

use nalgebra::{Isometry3, Vector3};
use thiserror::Error;

mod hull;
mod mesh;

use hull::quickhull;

/// Two faces are merged, and a vertex may lie outside a face plane without
/// the mesh being called non-convex, within this fraction of the bounding-box
/// diagonal. 1e-6 absorbs the rounding of meshes stored in single precision
/// (≈ 6e-8 of a coordinate, which may be several body sizes from the origin)
/// while staying far below any real feature of a modelled part.
pub const PLANARITY_REL_TOL: f64 = 1e-6;

/// A mesh whose enclosed volume is below this fraction of the cube of its
/// bounding-box diagonal is flat. Rounding of a truly flat mesh gives about
/// 1e-16; the thinnest real plate (1 mm on a 1 m part) gives about 1e-4.
pub const VOLUME_REL_TOL: f64 = 1e-9;

/// `hull` treats a point within this fraction of the bounding-box diagonal
/// of a face plane as lying on it: far above f64 rounding (1e-16) so that
/// visibility decisions are stable, far below `PLANARITY_REL_TOL`. (Every
/// relative tolerance here is floored at 64 ulps of the largest coordinate.)
pub const HULL_REL_EPS: f64 = 1e-9;

/// `hull` merges its triangles, and checks them for convexity, within this
/// fraction of the diagonal rather than `PLANARITY_REL_TOL`: its output is
/// convex to `HULL_REL_EPS` by construction, and a looser merge would refit
/// face planes past input points (which stay inside to within this).
pub const HULL_MERGE_REL_TOL: f64 = 10.0 * HULL_REL_EPS;

/// Why a mesh or a point set is not a usable convex polyhedron. The messages
/// are phrased to follow a prefix such as "part 'leg': ". Indices are those
/// of the caller's input.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum PolyhedronError {
    #[error("has a non-finite coordinate at vertex {vertex}")]
    NonFinite { vertex: usize },
    #[error("has face {face} with {count} vertices; a face needs at least 3")]
    TooFewFaceVertices { face: usize, count: usize },
    #[error(
        "has face {face} referring to vertex {index}, but there are only {vertex_count} vertices"
    )]
    IndexOutOfRange {
        face: usize,
        index: usize,
        vertex_count: usize,
    },
    #[error("has face {face} listing vertex {vertex} twice")]
    RepeatedVertex { face: usize, vertex: usize },
    #[error(
        "is not closed: edge {tail}-{head} of face {face} has no face on its other side \
         (if this is a triangle soup, weld duplicate vertices first)"
    )]
    OpenEdge {
        tail: usize,
        head: usize,
        face: usize,
    },
    #[error("is not 2-manifold: edge {a}-{b} is shared by more than two faces")]
    NonManifoldEdge { a: usize, b: usize },
    #[error("is not 2-manifold at vertex {vertex}: its faces do not form a single fan")]
    NonManifoldVertex { vertex: usize },
    #[error(
        "has inconsistent winding: faces {face_a} and {face_b} both run edge {tail}->{head} \
         in the same direction"
    )]
    InconsistentWinding {
        face_a: usize,
        face_b: usize,
        tail: usize,
        head: usize,
    },
    #[error(
        "is wound inward (signed volume {volume:.3e} m³): faces must be counter-clockwise \
         seen from outside; reverse the vertex order of every face"
    )]
    InwardWinding { volume: f64 },
    #[error("has zero volume ({volume:.3e} m³): its vertices are (nearly) coplanar")]
    ZeroVolume { volume: f64 },
    #[error("is not convex: vertex {vertex} lies {} m outside face {face}", fmt_len(*.distance))]
    NotConvex {
        vertex: usize,
        face: usize,
        distance: f64,
    },
    #[error(
        "is not convex: the coplanar faces merged around face {face} do not form a simple polygon"
    )]
    NonSimpleFace { face: usize },
    #[error("has a degenerate face {face} (no area, and not coplanar with a neighbour)")]
    DegenerateFace { face: usize },
    #[error("is not a closed genus-0 surface (V - E + F = {euler}, expected 2)")]
    NotSphereLike { euler: i64 },
    #[error("needs at least 4 points for a hull, got {count}")]
    TooFewPoints { count: usize },
    #[error("has all its points (nearly) {shape}: a hull needs volume")]
    DegenerateHull { shape: &'static str },
    #[error(
        "has points too close to degenerate for a robust hull \
         (weld near-duplicate points first)"
    )]
    HullNumerics,
}

fn fmt_len(d: f64) -> String {
    if d >= 1e-3 {
        format!("{d:.4}")
    } else {
        format!("{d:.3e}")
    }
}

/// A merged planar face.
#[derive(Clone, Debug, PartialEq)]
pub struct Face {
    /// Vertex loop, counter-clockwise seen from outside.
    pub vertices: Vec<usize>,
    /// `edges[i]` joins `vertices[i]` and `vertices[i + 1]` (cyclically).
    pub edges: Vec<u32>,
    /// Unit outward normal.
    pub normal: Vector3<f64>,
    /// `normal · x = offset` on the face plane.
    pub offset: f64,
}

/// A winged edge; see the module doc for the orientation convention.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Edge {
    pub tail: u32,
    pub head: u32,
    /// The face that runs this edge tail → head.
    pub left: u32,
    /// The face that runs this edge head → tail.
    pub right: u32,
}

/// One bounding plane of a feature's Voronoi region (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoronoiPlane {
    pub normal: Vector3<f64>,
    pub offset: f64,
    /// Index of the neighbouring feature across the plane; its kind follows
    /// from which region the plane bounds.
    pub neighbor: u32,
}

impl VoronoiPlane {
    /// Positive inside the owning feature's region.
    #[inline]
    pub fn signed_distance(&self, x: &Vector3<f64>) -> f64 {
        self.normal.dot(x) - self.offset
    }
}

/// A closed convex polyhedron with merged coplanar faces.
#[derive(Clone, Debug)]
pub struct ConvexPolyhedron {
    vertices: Vec<Vector3<f64>>,
    edges: Vec<Edge>,
    faces: Vec<Face>,
    edge_dirs: Vec<Vector3<f64>>,
    edge_lengths: Vec<f64>,
    // Incident edges of vertex v: vertex_edges[vertex_start[v]..vertex_start[v + 1]];
    // vertex_planes is indexed the same way.
    vertex_start: Vec<u32>,
    vertex_edges: Vec<u32>,
    vertex_planes: Vec<VoronoiPlane>,
    edge_planes: Vec<[VoronoiPlane; 4]>,
    // Side planes of face f: face_planes[face_start[f]..face_start[f + 1]], in loop order.
    face_start: Vec<u32>,
    face_planes: Vec<VoronoiPlane>,
    centroid: Vector3<f64>,
    scale: f64,
    extent: f64,
}

impl ConvexPolyhedron {
    /// Builds a polyhedron from a closed, consistently wound (CCW seen from
    /// outside) polygon mesh, checking it thoroughly. Adjacent faces that are
    /// coplanar within `PLANARITY_REL_TOL` × bounding-box diagonal are merged,
    /// vertices left in the middle of a merged face or of a merged edge are
    /// dropped, and unused vertices are removed (vertex indices are therefore
    /// renumbered). A triangle soup from OBJ/STL works once duplicate
    /// positions have been welded (see [`weld`]).
    pub fn from_faces(
        vertices: Vec<Vector3<f64>>,
        faces: Vec<Vec<usize>>,
    ) -> Result<Self, PolyhedronError> {
        Self::from_faces_within(vertices, faces, PLANARITY_REL_TOL)
    }

    /// `from_faces` with its merge and convexity tolerance, `rel_tol` ×
    /// bounding-box diagonal, as a parameter.
    fn from_faces_within(
        vertices: Vec<Vector3<f64>>,
        faces: Vec<Vec<usize>>,
        rel_tol: f64,
    ) -> Result<Self, PolyhedronError> {
        mesh::check_indices(&vertices, &faces)?;
        let (directed, successor) = mesh::directed_edges(&faces)?;
        mesh::check_vertex_fans(&vertices, &faces, &successor)?;

        let used: Vec<bool> = {
            let mut u = vec![false; vertices.len()];
            faces.iter().flatten().for_each(|&i| u[i] = true);
            u
        };
        let used_points = || {
            vertices
                .iter()
                .zip(&used)
                .filter(|(_, u)| **u)
                .map(|(v, _)| v)
        };
        let scale = bbox_diagonal(used_points());
        let centre = used_points().sum::<Vector3<f64>>() / used_points().count() as f64;
        let tol = (rel_tol * scale).max(coordinate_rounding(used_points()));

        // Newell's normal: robust for non-planar or nearly degenerate polygons,
        // its length is twice the polygon area.
        let newell: Vec<Vector3<f64>> = faces
            .iter()
            .map(|face| newell_normal(face.iter().map(|&i| vertices[i] - centre)))
            .collect();
        mesh::check_volume(&vertices, &faces, centre, scale)?;
        let (group, seeds) = mesh::merge_coplanar(&vertices, &faces, &newell, &directed, tol)?;
        let mut loops = mesh::boundary_loops(&faces, &directed, &group, &seeds)?;
        mesh::drop_vertices_inside_faces(&vertices, &mut loops, &seeds)?;
        let planes = mesh::loop_planes(&vertices, &loops, centre);
        mesh::check_convex(&vertices, &used, &planes, &seeds, tol)?;
        let (kept, loops) = mesh::renumber(&vertices, &loops);
        mesh::check_sphere_like(kept.len(), &loops)?;
        Ok(Self::assemble(kept, loops, planes))
    }

    /// Convex hull of a point set (quickhull), with coplanar faces merged.
    /// Points within `HULL_REL_EPS` × bounding-box diagonal outside a face are
    /// treated as on it; every point ends up inside the hull or within
    /// `HULL_MERGE_REL_TOL` × diagonal of it. Fails on fewer than 4 points or when the points are
    /// (nearly) coincident, collinear or coplanar.
    pub fn hull(points: &[Vector3<f64>]) -> Result<Self, PolyhedronError> {
        let (vertices, faces) = quickhull(points)?;
        Self::from_faces_within(vertices, faces, HULL_MERGE_REL_TOL)
    }

    /// The same shape moved rigidly by `iso` (placing a compound part, or
    /// re-centring a body at its centre of mass).
    pub fn transformed(&self, iso: &Isometry3<f64>) -> Self {
        let vertices: Vec<Vector3<f64>> = self
            .vertices
            .iter()
            .map(|v| iso.transform_point(&(*v).into()).coords)
            .collect();
        let loops: Vec<Vec<usize>> = self.faces.iter().map(|f| f.vertices.clone()).collect();
        let planes = self
            .faces
            .iter()
            .map(|f| {
                let n = iso.rotation * f.normal;
                (n, f.offset + n.dot(&iso.translation.vector))
            })
            .collect();
        Self::assemble(vertices, loops, planes)
    }

    /// Builds the winged-edge tables and Voronoi planes from validated loops.
    fn assemble(
        vertices: Vec<Vector3<f64>>,
        loops: Vec<Vec<usize>>,
        planes: Vec<(Vector3<f64>, f64)>,
    ) -> Self {
        let mut edges: Vec<Edge> = Vec::new();
        let mut edge_of: HashMap<(usize, usize), u32> = HashMap::new();
        let mut faces: Vec<Face> = Vec::with_capacity(loops.len());
        for (f, (lp, (normal, offset))) in loops.into_iter().zip(planes).enumerate() {
            let n = lp.len();
            let mut face_edges = Vec::with_capacity(n);
            for k in 0..n {
                let (i, j) = (lp[k], lp[(k + 1) % n]);
                let id = *edge_of.entry((i.min(j), i.max(j))).or_insert_with(|| {
                    edges.push(Edge {
                        tail: i as u32,
                        head: j as u32,
                        left: f as u32,
                        right: u32::MAX,
                    });
                    edges.len() as u32 - 1
                });
                if edges[id as usize].left != f as u32 {
                    edges[id as usize].right = f as u32;
                }
                face_edges.push(id);
            }
            faces.push(Face {
                vertices: lp,
                edges: face_edges,
                normal,
                offset,
            });
        }

        let mut edge_dirs = Vec::with_capacity(edges.len());
        let mut edge_lengths = Vec::with_capacity(edges.len());
        let mut edge_planes = Vec::with_capacity(edges.len());
        for e in &edges {
            let t = vertices[e.tail as usize];
            let h = vertices[e.head as usize];
            let len = (h - t).norm();
            let u = (h - t) / len;
            let nl = faces[e.left as usize].normal;
            let nr = faces[e.right as usize].normal;
            // u ⟂ n_L and u ⟂ n_R up to planarity rounding; renormalise anyway.
            let towards_left = u.cross(&nl).normalize();
            let towards_right = nr.cross(&u).normalize();
            let plane = |normal: Vector3<f64>, at: Vector3<f64>, neighbor: u32| VoronoiPlane {
                normal,
                offset: normal.dot(&at),
                neighbor,
            };
            edge_planes.push([
                plane(u, t, e.tail),
                plane(-u, h, e.head),
                plane(towards_left, t, e.left),
                plane(towards_right, t, e.right),
            ]);
            edge_dirs.push(u);
            edge_lengths.push(len);
        }

        let mut vertex_start = vec![0u32; vertices.len() + 1];
        for e in &edges {
            vertex_start[e.tail as usize + 1] += 1;
            vertex_start[e.head as usize + 1] += 1;
        }
        for v in 0..vertices.len() {
            vertex_start[v + 1] += vertex_start[v];
        }
        let mut fill = vertex_start.clone();
        let mut vertex_edges = vec![0u32; 2 * edges.len()];
        let dummy = VoronoiPlane {
            normal: Vector3::zeros(),
            offset: 0.0,
            neighbor: 0,
        };
        let mut vertex_planes = vec![dummy; 2 * edges.len()];
        for (id, e) in edges.iter().enumerate() {
            for (v, w) in [(e.tail, edge_dirs[id]), (e.head, -edge_dirs[id])] {
                let slot = fill[v as usize] as usize;
                fill[v as usize] += 1;
                vertex_edges[slot] = id as u32;
                let p = vertices[v as usize];
                vertex_planes[slot] = VoronoiPlane {
                    normal: -w,
                    offset: -w.dot(&p),
                    neighbor: id as u32,
                };
            }
        }

        let mut face_start = Vec::with_capacity(faces.len() + 1);
        let mut face_planes = Vec::with_capacity(2 * edges.len());
        face_start.push(0u32);
        for (f, face) in faces.iter().enumerate() {
            for &id in &face.edges {
                let [_, _, left, right] = edge_planes[id as usize];
                let side = if edges[id as usize].left == f as u32 {
                    left
                } else {
                    right
                };
                face_planes.push(VoronoiPlane {
                    normal: -side.normal,
                    offset: -side.offset,
                    neighbor: id,
                });
            }
            face_start.push(face_planes.len() as u32);
        }

        let centroid = vertices.iter().sum::<Vector3<f64>>() / vertices.len() as f64;
        let scale = bbox_diagonal(vertices.iter());
        let extent = vertices.iter().map(|v| v.norm()).fold(0.0, f64::max);
        Self {
            vertices,
            edges,
            faces,
            edge_dirs,
            edge_lengths,
            vertex_start,
            vertex_edges,
            vertex_planes,
            edge_planes,
            face_start,
            face_planes,
            centroid,
            scale,
            extent,
        }
    }

    pub fn vertices(&self) -> &[Vector3<f64>] {
        &self.vertices
    }

    pub fn faces(&self) -> &[Face] {
        &self.faces
    }

    pub fn edges(&self) -> &[Edge] {
        &self.edges
    }

    pub fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    pub fn edge_count(&self) -> usize {
        self.edges.len()
    }

    pub fn face_count(&self) -> usize {
        self.faces.len()
    }

    /// Vertices + edges + faces; sizes V-Clip's iteration bound.
    pub fn feature_count(&self) -> usize {
        self.vertices.len() + self.edges.len() + self.faces.len()
    }

    /// Edges incident to vertex `v`.
    pub fn vertex_edges(&self, v: usize) -> &[u32] {
        &self.vertex_edges[self.vertex_start[v] as usize..self.vertex_start[v + 1] as usize]
    }

    /// Unit direction tail → head of edge `e`.
    pub fn edge_direction(&self, e: usize) -> Vector3<f64> {
        self.edge_dirs[e]
    }

    pub fn edge_length(&self, e: usize) -> f64 {
        self.edge_lengths[e]
    }

    /// The vertex mean: a point strictly inside.
    pub fn centroid(&self) -> Vector3<f64> {
        self.centroid
    }

    /// Bounding-box diagonal; the length scale of relative tolerances.
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Largest distance of a vertex from the local origin: the magnitude of
    /// local coordinates, which sets their rounding level.
    pub fn local_extent(&self) -> f64 {
        self.extent
    }

    /// Voronoi planes of vertex `v`, aligned with `vertex_edges(v)`.
    pub fn vertex_voronoi_planes(&self, v: usize) -> &[VoronoiPlane] {
        &self.vertex_planes[self.vertex_start[v] as usize..self.vertex_start[v + 1] as usize]
    }

    /// Voronoi planes of edge `e`: towards tail, head, left face, right face.
    pub fn edge_voronoi_planes(&self, e: usize) -> &[VoronoiPlane; 4] {
        &self.edge_planes[e]
    }

    /// Side planes of face `f`'s Voronoi prism, aligned with `faces()[f].edges`.
    pub fn face_voronoi_planes(&self, f: usize) -> &[VoronoiPlane] {
        &self.face_planes[self.face_start[f] as usize..self.face_start[f + 1] as usize]
    }

    /// Fan triangulation of every face, counter-clockwise seen from outside.
    pub fn triangles(&self) -> Vec<[usize; 3]> {
        self.faces
            .iter()
            .flat_map(|f| {
                (1..f.vertices.len() - 1).map(|k| [f.vertices[0], f.vertices[k], f.vertices[k + 1]])
            })
            .collect()
    }

    /// An enclosing sphere (centre, radius): the smaller of Ritter's sphere
    /// and the sphere about the vertex mean.
    pub fn bounding_sphere(&self) -> (Vector3<f64>, f64) {
        let about = |c: Vector3<f64>| {
            let r = self
                .vertices
                .iter()
                .map(|v| (v - c).norm())
                .fold(0.0, f64::max);
            (c, r)
        };
        let mean = about(self.centroid);
        // Ritter: start from a far pair, then grow to swallow stragglers.
        let far_from = |p: Vector3<f64>| {
            *self
                .vertices
                .iter()
                .max_by(|a, b| (*a - p).norm_squared().total_cmp(&(*b - p).norm_squared()))
                .unwrap()
        };
        let x = far_from(self.vertices[0]);
        let y = far_from(x);
        let mut c = (x + y) / 2.0;
        let mut r = (y - x).norm() / 2.0;
        for v in &self.vertices {
            let d = (v - c).norm();
            if d > r {
                let grow = (d - r) / 2.0;
                r += grow;
                c += (v - c) * (grow / d);
            }
        }
        // Ritter's radius can miss the last vertex by an ulp: re-measure it.
        let ritter = about(c);
        if ritter.1 < mean.1 { ritter } else { mean }
    }

    /// The vertex farthest along `dir`.
    pub fn support(&self, dir: &Vector3<f64>) -> Vector3<f64> {
        self.vertices[self.support_index(dir)]
    }

    /// Index of the vertex farthest along `dir`.
    pub fn support_index(&self, dir: &Vector3<f64>) -> usize {
        let mut best = 0;
        let mut best_d = f64::NEG_INFINITY;
        for (i, v) in self.vertices.iter().enumerate() {
            let d = v.dot(dir);
            if d > best_d {
                best_d = d;
                best = i;
            }
        }
        best
    }
}

/// Merges vertices closer than `tol` (each to the first one met) and
/// re-indexes the faces, dropping repeated consecutive indices and faces left
/// with fewer than 3 vertices. Unused vertices are dropped too. With
/// `tol <= 0` only exactly equal positions merge. Out-of-range face indices
/// become `usize::MAX`, which `from_faces` then reports.
pub fn weld(
    vertices: &[Vector3<f64>],
    faces: &[Vec<usize>],
    tol: f64,
) -> (Vec<Vector3<f64>>, Vec<Vec<usize>>) {
    // Grid of cell size `tol`: a partner within `tol` lies in one of the 27
    // surrounding cells.
    let cell = |p: &Vector3<f64>| -> [i64; 3] {
        if tol > 0.0 {
            [0, 1, 2].map(|k| (p[k] / tol).floor() as i64)
        } else {
            [0, 1, 2].map(|k| p[k].to_bits() as i64)
        }
    };
    let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    let mut rep = vec![0usize; vertices.len()];
    let mut reps: Vec<usize> = Vec::new();
    for (i, p) in vertices.iter().enumerate() {
        let c = cell(p);
        let mut found = None;
        if tol > 0.0 {
            'search: for dx in -1..=1 {
                for dy in -1..=1 {
                    for dz in -1..=1 {
                        if let Some(list) = grid.get(&[c[0] + dx, c[1] + dy, c[2] + dz])
                            && let Some(&r) = list
                                .iter()
                                .find(|&&r| (vertices[reps[r]] - p).norm() <= tol)
                        {
                            found = Some(r);
                            break 'search;
                        }
                    }
                }
            }
        } else if let Some(list) = grid.get(&c) {
            found = list.first().copied();
        }
        rep[i] = found.unwrap_or_else(|| {
            reps.push(i);
            grid.entry(c).or_default().push(reps.len() - 1);
            reps.len() - 1
        });
    }
    let mut new_faces = Vec::with_capacity(faces.len());
    let mut used = vec![false; reps.len()];
    for face in faces {
        let mut out: Vec<usize> = Vec::with_capacity(face.len());
        for &i in face {
            let r = if i < vertices.len() {
                rep[i]
            } else {
                usize::MAX
            };
            if out.last() != Some(&r) {
                out.push(r);
            }
        }
        while out.len() > 1 && out.first() == out.last() {
            out.pop();
        }
        if out.len() >= 3 {
            out.iter()
                .filter(|&&r| r != usize::MAX)
                .for_each(|&r| used[r] = true);
            new_faces.push(out);
        }
    }
    let mut compact = vec![usize::MAX; reps.len()];
    let mut out_vertices = Vec::new();
    for (r, &u) in used.iter().enumerate() {
        if u {
            compact[r] = out_vertices.len();
            out_vertices.push(vertices[reps[r]]);
        }
    }
    for face in &mut new_faces {
        for i in face.iter_mut() {
            if *i != usize::MAX {
                *i = compact[*i];
            }
        }
    }
    (out_vertices, new_faces)
}

/// A length below which differences of these coordinates are rounding: 64
/// ulps of the largest coordinate. Relative tolerances never go below it, or
/// a small part placed far from its origin would be judged by noise.
fn coordinate_rounding<'a>(points: impl Iterator<Item = &'a Vector3<f64>>) -> f64 {
    64.0 * f64::EPSILON * points.map(|p| p.amax()).fold(0.0, f64::max)
}

fn bbox_diagonal<'a>(points: impl Iterator<Item = &'a Vector3<f64>>) -> f64 {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for p in points {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    if lo.x > hi.x { 0.0 } else { (hi - lo).norm() }
}

fn newell_normal(points: impl Iterator<Item = Vector3<f64>> + Clone) -> Vector3<f64> {
    let mut n = Vector3::zeros();
    let first = points.clone().next();
    let mut it = points.peekable();
    while let Some(p) = it.next() {
        let q = it.peek().copied().or(first).unwrap();
        n += p.cross(&q);
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cube_triangles(h: f64) -> (Vec<Vector3<f64>>, Vec<Vec<usize>>) {
        let v = (0..8)
            .map(|i| {
                Vector3::new(
                    if i & 1 == 0 { -h } else { h },
                    if i & 2 == 0 { -h } else { h },
                    if i & 4 == 0 { -h } else { h },
                )
            })
            .collect();
        // Quads CCW from outside, each split into two triangles.
        let quads = [
            [0, 2, 3, 1], // z = -h
            [4, 5, 7, 6], // z = +h
            [0, 1, 5, 4], // y = -h
            [2, 6, 7, 3], // y = +h
            [0, 4, 6, 2], // x = -h
            [1, 3, 7, 5], // x = +h
        ];
        let f = quads
            .iter()
            .flat_map(|q| [vec![q[0], q[1], q[2]], vec![q[0], q[2], q[3]]])
            .collect();
        (v, f)
    }

    #[test]
    fn voronoi_planes_agree_across_shared_boundaries() {
        let (v, f) = cube_triangles(0.5);
        let p = ConvexPolyhedron::from_faces(v, f).unwrap();
        for (e, edge) in p.edges().iter().enumerate() {
            let planes = p.edge_voronoi_planes(e);
            // Edge's tail plane is the negated tail vertex's plane for this edge.
            let t = edge.tail as usize;
            let k = p
                .vertex_edges(t)
                .iter()
                .position(|&x| x as usize == e)
                .unwrap();
            let vp = p.vertex_voronoi_planes(t)[k];
            assert!((vp.normal + planes[0].normal).norm() < 1e-15);
            assert!((vp.offset + planes[0].offset).abs() < 1e-15);
            // Left-face plane points away from the left face's interior.
            let lf = &p.faces()[edge.left as usize];
            let inside_left = lf
                .vertices
                .iter()
                .map(|&i| p.vertices()[i])
                .sum::<Vector3<f64>>()
                / lf.vertices.len() as f64;
            assert!(planes[2].signed_distance(&inside_left) < 0.0);
            assert!(planes[2].normal.dot(&lf.normal).abs() < 1e-15);
        }
        for (fi, face) in p.faces().iter().enumerate() {
            let c = face
                .vertices
                .iter()
                .map(|&i| p.vertices()[i])
                .sum::<Vector3<f64>>()
                / face.vertices.len() as f64;
            for plane in p.face_voronoi_planes(fi) {
                assert!(plane.signed_distance(&c) > 0.0);
            }
        }
    }

    #[test]
    fn bounding_sphere_contains_every_vertex() {
        let pts: Vec<Vector3<f64>> = (0..50)
            .map(|i| {
                let t = i as f64;
                Vector3::new(
                    (t * 1.3).sin(),
                    (t * 2.1).cos() * 0.5,
                    (t * 0.7).sin() * 2.0,
                )
            })
            .collect();
        let p = ConvexPolyhedron::hull(&pts).unwrap();
        let (c, r) = p.bounding_sphere();
        for v in p.vertices() {
            assert!((v - c).norm() <= r * (1.0 + 1e-12));
        }
    }

    #[test]
    fn weld_joins_a_triangle_soup() {
        let (v, f) = cube_triangles(1.0);
        let mut soup_v = Vec::new();
        let mut soup_f = Vec::new();
        for tri in &f {
            let base = soup_v.len();
            for &i in tri {
                soup_v.push(v[i] + Vector3::new(1e-9, 0.0, 0.0) * (base as f64 % 3.0));
            }
            soup_f.push(vec![base, base + 1, base + 2]);
        }
        let (wv, wf) = weld(&soup_v, &soup_f, 1e-7);
        assert_eq!(wv.len(), 8);
        let p = ConvexPolyhedron::from_faces(wv, wf).unwrap();
        assert_eq!(p.face_count(), 6);
    }

    #[test]
    fn transformed_moves_planes_with_vertices() {
        let (v, f) = cube_triangles(0.5);
        let p = ConvexPolyhedron::from_faces(v, f).unwrap();
        let iso = Isometry3::new(Vector3::new(1.0, -2.0, 3.0), Vector3::new(0.3, -0.2, 0.9));
        let q = p.transformed(&iso);
        for face in q.faces() {
            for &i in &face.vertices {
                assert!((face.normal.dot(&q.vertices()[i]) - face.offset).abs() < 1e-12);
            }
        }
    }
}
