//! Convex polyhedra for the narrowphase: winged-edge topology plus the
//! Voronoi-region planes that V-Clip (`super::vclip`) walks.
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
        use PolyhedronError as E;
        for (i, v) in vertices.iter().enumerate() {
            if !v.iter().all(|c| c.is_finite()) {
                return Err(E::NonFinite { vertex: i });
            }
        }
        for (f, face) in faces.iter().enumerate() {
            if face.len() < 3 {
                return Err(E::TooFewFaceVertices {
                    face: f,
                    count: face.len(),
                });
            }
            for (k, &i) in face.iter().enumerate() {
                if i >= vertices.len() {
                    return Err(E::IndexOutOfRange {
                        face: f,
                        index: i,
                        vertex_count: vertices.len(),
                    });
                }
                if face[..k].contains(&i) {
                    return Err(E::RepeatedVertex { face: f, vertex: i });
                }
            }
        }
        if faces.is_empty() {
            return Err(E::ZeroVolume { volume: 0.0 });
        }

        // Directed edges: a closed, consistently wound 2-manifold runs every
        // edge exactly once in each direction.
        let mut directed: HashMap<(usize, usize), usize> = HashMap::new();
        let mut successor: HashMap<(usize, usize), usize> = HashMap::new();
        for (f, face) in faces.iter().enumerate() {
            let n = face.len();
            for k in 0..n {
                let (i, j) = (face[k], face[(k + 1) % n]);
                if let Some(g) = directed.insert((i, j), f) {
                    return Err(if directed.contains_key(&(j, i)) {
                        E::NonManifoldEdge {
                            a: i.min(j),
                            b: i.max(j),
                        }
                    } else {
                        E::InconsistentWinding {
                            face_a: g,
                            face_b: f,
                            tail: i,
                            head: j,
                        }
                    });
                }
                successor.insert((i, j), face[(k + 2) % n]);
            }
        }
        for (f, face) in faces.iter().enumerate() {
            let n = face.len();
            for k in 0..n {
                let (i, j) = (face[k], face[(k + 1) % n]);
                if !directed.contains_key(&(j, i)) {
                    return Err(E::OpenEdge {
                        tail: i,
                        head: j,
                        face: f,
                    });
                }
            }
        }
        // The faces around each vertex must form one fan: walking from an
        // outgoing edge (v→j) across to the face that runs (j→v) and on to its
        // next edge (v→k) must visit every outgoing edge before returning.
        let mut out_degree = vec![0usize; vertices.len()];
        let mut first_out = vec![usize::MAX; vertices.len()];
        for face in &faces {
            let n = face.len();
            for k in 0..n {
                out_degree[face[k]] += 1;
                first_out[face[k]] = face[(k + 1) % n];
            }
        }
        for v in 0..vertices.len() {
            if out_degree[v] == 0 {
                continue;
            }
            let start = first_out[v];
            let mut j = start;
            let mut count = 0;
            loop {
                j = successor[&(j, v)];
                count += 1;
                if j == start || count > out_degree[v] {
                    break;
                }
            }
            if count != out_degree[v] {
                return Err(E::NonManifoldVertex { vertex: v });
            }
        }

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

        // Volume by the divergence theorem over fan triangles, about the centre
        // so that rounding does not grow with the distance from the origin.
        let volume: f64 = faces
            .iter()
            .map(|face| {
                let p0 = vertices[face[0]] - centre;
                (1..face.len() - 1)
                    .map(|k| {
                        p0.dot(
                            &(vertices[face[k]] - centre).cross(&(vertices[face[k + 1]] - centre)),
                        )
                    })
                    .sum::<f64>()
                    / 6.0
            })
            .sum();
        // Divided stepwise: scale³ overflows for absurd (but finite) sizes.
        // All vertices at one point (scale 0) is flat too.
        if scale == 0.0 || volume.abs() / scale / scale / scale <= VOLUME_REL_TOL {
            return Err(E::ZeroVolume { volume });
        }
        if volume < 0.0 {
            return Err(E::InwardWinding { volume });
        }

        // Merge coplanar neighbours by region growing from the largest faces.
        // Every face of a group must lie within `tol` of the seed's plane (not
        // just of its neighbour's), so gently curved surfaces do not chain.
        // A sliver, whose height (2 area / longest edge) is within `tol`, has
        // no trustworthy normal; it lies along its long edge, which the
        // neighbouring groups' planes hold, so the first group to reach it
        // takes it.
        let sliver: Vec<bool> = faces
            .iter()
            .zip(&newell)
            .map(|(face, twice_area)| {
                let m = face.len();
                let longest = (0..m)
                    .map(|k| (vertices[face[(k + 1) % m]] - vertices[face[k]]).norm())
                    .fold(0.0, f64::max);
                twice_area.norm() <= tol * longest
            })
            .collect();
        let mut order: Vec<usize> = (0..faces.len()).collect();
        order.sort_by(|&x, &y| {
            sliver[x]
                .cmp(&sliver[y])
                .then(newell[y].norm().total_cmp(&newell[x].norm()))
                .then(x.cmp(&y))
        });
        let mut group = vec![usize::MAX; faces.len()];
        let mut seeds: Vec<usize> = Vec::new();
        for &seed in &order {
            if group[seed] != usize::MAX {
                continue;
            }
            if sliver[seed] {
                return Err(E::DegenerateFace { face: seed });
            }
            let g = seeds.len();
            seeds.push(seed);
            group[seed] = g;
            let n = newell[seed].normalize();
            let off = faces[seed]
                .iter()
                .map(|&i| n.dot(&vertices[i]))
                .sum::<f64>()
                / faces[seed].len() as f64;
            let mut stack = vec![seed];
            while let Some(f) = stack.pop() {
                let m = faces[f].len();
                for k in 0..m {
                    let (i, j) = (faces[f][k], faces[f][(k + 1) % m]);
                    let h = directed[&(j, i)];
                    if group[h] != usize::MAX {
                        continue;
                    }
                    let coplanar = newell[h].dot(&n) > 0.0
                        && faces[h]
                            .iter()
                            .all(|&q| (n.dot(&vertices[q]) - off).abs() <= tol);
                    if sliver[h] || coplanar {
                        group[h] = g;
                        stack.push(h);
                    }
                }
            }
        }

        // Boundary loop of each group: its directed edges whose twin belongs to
        // another group, chained head to tail.
        let mut loops: Vec<Vec<usize>> = Vec::with_capacity(seeds.len());
        for (g, &seed) in seeds.iter().enumerate() {
            let mut next: HashMap<usize, usize> = HashMap::new();
            let mut first = None;
            for (f, face) in faces.iter().enumerate() {
                if group[f] != g {
                    continue;
                }
                let m = face.len();
                for k in 0..m {
                    let (i, j) = (face[k], face[(k + 1) % m]);
                    if group[directed[&(j, i)]] != g {
                        if next.insert(i, j).is_some() {
                            return Err(E::NonSimpleFace { face: seed });
                        }
                        first.get_or_insert(i);
                    }
                }
            }
            let Some(start) = first else {
                return Err(E::NonSimpleFace { face: seed });
            };
            let mut lp = vec![start];
            let mut v = next[&start];
            while v != start {
                if lp.len() > next.len() {
                    return Err(E::NonSimpleFace { face: seed });
                }
                lp.push(v);
                v = next[&v];
            }
            if lp.len() != next.len() {
                return Err(E::NonSimpleFace { face: seed });
            }
            loops.push(lp);
        }

        // A vertex on fewer than three merged faces sits in the middle of a
        // merged edge (collinear with its neighbours) or of a merged face.
        let mut face_degree = vec![0usize; vertices.len()];
        loops.iter().flatten().for_each(|&i| face_degree[i] += 1);
        for (lp, &seed) in loops.iter_mut().zip(&seeds) {
            lp.retain(|&i| face_degree[i] >= 3);
            if lp.len() < 3 {
                return Err(E::NonSimpleFace { face: seed });
            }
        }

        let planes: Vec<(Vector3<f64>, f64)> = loops
            .iter()
            .map(|lp| {
                let n = newell_normal(lp.iter().map(|&i| vertices[i] - centre)).normalize();
                let off = lp.iter().map(|&i| n.dot(&vertices[i])).sum::<f64>() / lp.len() as f64;
                (n, off)
            })
            .collect();

        // Convexity: no used vertex (dropped ones included) may lie outside any
        // merged face plane by more than `tol`. Report the worst offender.
        let mut worst: Option<(f64, usize, usize)> = None;
        for (k, (n, off)) in planes.iter().enumerate() {
            for (v, p) in vertices.iter().enumerate() {
                if !used[v] {
                    continue;
                }
                let d = n.dot(p) - off;
                if d > tol && worst.is_none_or(|(w, _, _)| d > w) {
                    worst = Some((d, v, seeds[k]));
                }
            }
        }
        if let Some((distance, vertex, face)) = worst {
            return Err(E::NotConvex {
                vertex,
                face,
                distance,
            });
        }

        let mut new_index = vec![u32::MAX; vertices.len()];
        let mut kept = Vec::new();
        for lp in &loops {
            for &i in lp {
                if new_index[i] == u32::MAX {
                    new_index[i] = kept.len() as u32;
                    kept.push(vertices[i]);
                }
            }
        }
        let loops: Vec<Vec<usize>> = loops
            .iter()
            .map(|lp| lp.iter().map(|&i| new_index[i] as usize).collect())
            .collect();
        let edge_count = loops.iter().map(Vec::len).sum::<usize>() / 2;
        let euler = kept.len() as i64 - edge_count as i64 + loops.len() as i64;
        if euler != 2 {
            return Err(E::NotSphereLike { euler });
        }
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

/// Vertices and CCW face loops.
type Mesh = (Vec<Vector3<f64>>, Vec<Vec<usize>>);

/// Quickhull: returns the input points and CCW triangles of their hull.
fn quickhull(points: &[Vector3<f64>]) -> Result<Mesh, PolyhedronError> {
    use PolyhedronError as E;
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

    // Initial tetrahedron from extreme points.
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

    let lost = E::HullNumerics;
    let mut pending: Vec<usize> = (0..faces.len()).collect();
    let mut visible_mark: Vec<bool> = vec![false; faces.len()];
    while let Some(f) = pending.pop() {
        if !faces[f].alive || faces[f].outside.is_empty() {
            continue;
        }
        let apex = *faces[f]
            .outside
            .iter()
            .max_by(|&&a, &&b| {
                faces[f]
                    .distance(&points[a])
                    .total_cmp(&faces[f].distance(&points[b]))
            })
            .unwrap();
        let p = points[apex];

        // The faces the apex sees, grown from f across shared edges.
        let mut visible = vec![f];
        visible_mark[f] = true;
        let mut k = 0;
        while k < visible.len() {
            let g = visible[k];
            k += 1;
            let v = faces[g].v;
            for e in 0..3 {
                let Some(&h) = edge_face.get(&(v[(e + 1) % 3], v[e])) else {
                    return Err(lost);
                };
                if !visible_mark[h] && faces[h].distance(&p) > eps {
                    visible_mark[h] = true;
                    visible.push(h);
                }
            }
        }
        // The horizon must be one simple loop, or the new cone of faces
        // would not close up: each of its vertices starts exactly one edge.
        let mut horizon = Vec::new();
        for &g in &visible {
            let v = faces[g].v;
            for e in 0..3 {
                let (a, b) = (v[e], v[(e + 1) % 3]);
                let Some(&h) = edge_face.get(&(b, a)) else {
                    return Err(lost);
                };
                if !visible_mark[h] {
                    horizon.push((a, b));
                }
            }
        }
        let mut tails: Vec<usize> = horizon.iter().map(|&(a, _)| a).collect();
        tails.sort_unstable();
        if tails.windows(2).any(|w| w[0] == w[1]) {
            return Err(lost);
        }
        let mut orphans = Vec::new();
        for &g in &visible {
            faces[g].alive = false;
            visible_mark[g] = false;
            let v = faces[g].v;
            for e in 0..3 {
                edge_face.remove(&(v[e], v[(e + 1) % 3]));
            }
            orphans.append(&mut faces[g].outside);
        }
        let first_new = faces.len();
        for (a, b) in horizon {
            let id = faces.len();
            let nf = HullFace::new([a, b, apex], points);
            for k in 0..3 {
                edge_face.insert((nf.v[k], nf.v[(k + 1) % 3]), id);
            }
            faces.push(nf);
            visible_mark.push(false);
        }
        for q in orphans {
            if q == apex {
                continue;
            }
            if let Some(nf) = faces[first_new..]
                .iter_mut()
                .find(|nf| nf.distance(&points[q]) > eps)
            {
                nf.outside.push(q);
            }
        }
        pending.extend(first_new..faces.len());
    }

    let tris = faces
        .iter()
        .filter(|f| f.alive)
        .map(|f| f.v.to_vec())
        .collect();
    Ok((points.to_vec(), tris))
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
