//! The steps of `ConvexPolyhedron::from_faces`: the checks that a polygon
//! mesh bounds a convex solid (indices, a closed and consistently wound
//! 2-manifold, volume, convexity, Euler characteristic) and the merge of
//! its coplanar faces into the loops and planes that `assemble` takes.

use std::collections::HashMap;

use nalgebra::Vector3;

use super::{PolyhedronError, VOLUME_REL_TOL, newell_normal};
use PolyhedronError as E;

/// A value per directed edge (tail, head).
pub(super) type EdgeMap = HashMap<(usize, usize), usize>;

/// Every coordinate finite; every face of 3 or more distinct vertices,
/// each an index into `vertices`; at least one face.
pub(super) fn check_indices(
    vertices: &[Vector3<f64>],
    faces: &[Vec<usize>],
) -> Result<(), PolyhedronError> {
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
    Ok(())
}

/// Directed edges: a closed, consistently wound 2-manifold runs every
/// edge exactly once in each direction. Returns the face that runs each
/// directed edge, and the vertex after it in that face.
pub(super) fn directed_edges(faces: &[Vec<usize>]) -> Result<(EdgeMap, EdgeMap), PolyhedronError> {
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
    Ok((directed, successor))
}

/// The faces around each vertex must form one fan: walking from an
/// outgoing edge (v→j) across to the face that runs (j→v) and on to its
/// next edge (v→k) must visit every outgoing edge before returning.
pub(super) fn check_vertex_fans(
    vertices: &[Vector3<f64>],
    faces: &[Vec<usize>],
    successor: &EdgeMap,
) -> Result<(), PolyhedronError> {
    let mut out_degree = vec![0usize; vertices.len()];
    let mut first_out = vec![usize::MAX; vertices.len()];
    for face in faces {
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
    Ok(())
}

/// Volume by the divergence theorem over fan triangles, about the centre
/// so that rounding does not grow with the distance from the origin.
/// A flat mesh (below `VOLUME_REL_TOL` of the diagonal cubed) or an
/// inward-wound one is refused.
pub(super) fn check_volume(
    vertices: &[Vector3<f64>],
    faces: &[Vec<usize>],
    centre: Vector3<f64>,
    scale: f64,
) -> Result<(), PolyhedronError> {
    let volume: f64 = faces
        .iter()
        .map(|face| {
            let p0 = vertices[face[0]] - centre;
            (1..face.len() - 1)
                .map(|k| {
                    p0.dot(&(vertices[face[k]] - centre).cross(&(vertices[face[k + 1]] - centre)))
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
    Ok(())
}

/// Merge coplanar neighbours by region growing from the largest faces.
/// Every face of a group must lie within `tol` of the seed's plane (not
/// just of its neighbour's), so gently curved surfaces do not chain.
/// A sliver, whose height (2 area / longest edge) is within `tol`, has
/// no trustworthy normal; it lies along its long edge, which the
/// neighbouring groups' planes hold, so the first group to reach it
/// takes it.
///
/// Returns the group of each face and the seed face of each group.
pub(super) fn merge_coplanar(
    vertices: &[Vector3<f64>],
    faces: &[Vec<usize>],
    newell: &[Vector3<f64>],
    directed: &EdgeMap,
    tol: f64,
) -> Result<(Vec<usize>, Vec<usize>), PolyhedronError> {
    let sliver: Vec<bool> = faces
        .iter()
        .zip(newell)
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
    Ok((group, seeds))
}

/// Boundary loop of each group: its directed edges whose twin belongs to
/// another group, chained head to tail.
pub(super) fn boundary_loops(
    faces: &[Vec<usize>],
    directed: &EdgeMap,
    group: &[usize],
    seeds: &[usize],
) -> Result<Vec<Vec<usize>>, PolyhedronError> {
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
    Ok(loops)
}

/// A vertex on fewer than three merged faces sits in the middle of a
/// merged edge (collinear with its neighbours) or of a merged face: it
/// leaves the loops.
pub(super) fn drop_vertices_inside_faces(
    vertices: &[Vector3<f64>],
    loops: &mut [Vec<usize>],
    seeds: &[usize],
) -> Result<(), PolyhedronError> {
    let mut face_degree = vec![0usize; vertices.len()];
    loops.iter().flatten().for_each(|&i| face_degree[i] += 1);
    for (lp, &seed) in loops.iter_mut().zip(seeds) {
        lp.retain(|&i| face_degree[i] >= 3);
        if lp.len() < 3 {
            return Err(E::NonSimpleFace { face: seed });
        }
    }
    Ok(())
}

/// The plane (unit normal, offset) of each merged face: Newell's normal of
/// its loop, the offset averaged over its vertices.
pub(super) fn loop_planes(
    vertices: &[Vector3<f64>],
    loops: &[Vec<usize>],
    centre: Vector3<f64>,
) -> Vec<(Vector3<f64>, f64)> {
    loops
        .iter()
        .map(|lp| {
            let n = newell_normal(lp.iter().map(|&i| vertices[i] - centre)).normalize();
            let off = lp.iter().map(|&i| n.dot(&vertices[i])).sum::<f64>() / lp.len() as f64;
            (n, off)
        })
        .collect()
}

/// Convexity: no used vertex (dropped ones included) may lie outside any
/// merged face plane by more than `tol`. Report the worst offender.
pub(super) fn check_convex(
    vertices: &[Vector3<f64>],
    used: &[bool],
    planes: &[(Vector3<f64>, f64)],
    seeds: &[usize],
    tol: f64,
) -> Result<(), PolyhedronError> {
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
    Ok(())
}

/// The vertices the loops keep, numbered in the order the loops meet them,
/// and the loops in that numbering.
pub(super) fn renumber(
    vertices: &[Vector3<f64>],
    loops: &[Vec<usize>],
) -> (Vec<Vector3<f64>>, Vec<Vec<usize>>) {
    let mut new_index = vec![u32::MAX; vertices.len()];
    let mut kept = Vec::new();
    for lp in loops {
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
    (kept, loops)
}

/// A closed surface of genus 0 (a sphere's topology): V − E + F = 2.
pub(super) fn check_sphere_like(
    vertex_count: usize,
    loops: &[Vec<usize>],
) -> Result<(), PolyhedronError> {
    let edge_count = loops.iter().map(Vec::len).sum::<usize>() / 2;
    let euler = vertex_count as i64 - edge_count as i64 + loops.len() as i64;
    if euler != 2 {
        return Err(E::NotSphereLike { euler });
    }
    Ok(())
}
