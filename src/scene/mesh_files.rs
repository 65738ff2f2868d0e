//! Mesh files as convex parts: OBJ (one part per object/group), STL and DXF
//! (3DFACE entities, the thesis's shape format; one part per file).
//!
//! Files are triangle or polygon soups: duplicate positions are welded, then
//! `ConvexPolyhedron::from_faces` checks the part is closed, consistently
//! wound and convex, and merges coplanar triangles into faces. With
//! `hull = true` the convex hull of all vertices is taken instead.

use crate::polyhedron::{self, ConvexPolyhedron};
use nalgebra::Vector3;
use std::path::Path;

/// A mesh file larger than this is refused before it is read.
pub const MAX_MESH_BYTES: u64 = 256 * 1024 * 1024;
/// Welding tolerance relative to the mesh's bounding-box diagonal.
const WELD_RELATIVE: f64 = 1e-9;

/// A convex part with the name used in error messages ("shape.compound[1].box").
pub struct NamedPart {
    pub name: String,
    pub hull: ConvexPolyhedron,
}

type RawPart = (String, Vec<Vector3<f64>>, Vec<Vec<usize>>);

/// Loads a mesh file's parts. Errors are (part name or "", message).
pub fn load_parts(path: &Path, hull: bool) -> Result<Vec<NamedPart>, (String, String)> {
    let meta = std::fs::metadata(path)
        .map_err(|e| (String::new(), format!("cannot read mesh file: {e}")))?;
    if meta.len() > MAX_MESH_BYTES {
        return Err((
            String::new(),
            format!(
                "mesh file is {} bytes, more than the limit of {MAX_MESH_BYTES}",
                meta.len()
            ),
        ));
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    let raw: Vec<RawPart> = match ext.as_str() {
        "obj" => read_obj(path)?,
        "stl" => read_stl(path)?,
        "dxf" => read_dxf(path)?,
        _ => {
            return Err((
                String::new(),
                format!("unknown mesh format '.{ext}' (expected .obj, .stl or .dxf)"),
            ));
        }
    };
    if raw.is_empty() || raw.iter().all(|(_, v, _)| v.is_empty()) {
        return Err((String::new(), "mesh file has no geometry".into()));
    }
    if hull {
        let points: Vec<Vector3<f64>> =
            raw.iter().flat_map(|(_, v, _)| v.iter().copied()).collect();
        let hull =
            ConvexPolyhedron::hull(&points).map_err(|e| ("hull".to_string(), e.to_string()))?;
        return Ok(vec![NamedPart {
            name: "hull".into(),
            hull,
        }]);
    }
    raw.into_iter()
        .map(|(name, vertices, faces)| {
            if let Some(x) = vertices
                .iter()
                .flat_map(|v| v.iter())
                .find(|x| !x.is_finite())
            {
                return Err((name, format!("has a non-finite coordinate ({x})")));
            }
            let tol = WELD_RELATIVE * diagonal(&vertices).max(f64::MIN_POSITIVE);
            let (vertices, faces) = polyhedron::weld(&vertices, &faces, tol);
            ConvexPolyhedron::from_faces(vertices, faces)
                .map(|hull| NamedPart {
                    name: name.clone(),
                    hull,
                })
                .map_err(|e| (name, e.to_string()))
        })
        .collect()
}

fn diagonal(v: &[Vector3<f64>]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    let mut lo = v[0];
    let mut hi = v[0];
    for p in v {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    (hi - lo).norm()
}

fn read_obj(path: &Path) -> Result<Vec<RawPart>, (String, String)> {
    let opts = tobj::LoadOptions {
        single_index: false,
        triangulate: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _) = tobj::load_obj(path, &opts)
        .map_err(|e| (String::new(), format!("cannot parse OBJ: {e}")))?;
    Ok(models
        .into_iter()
        .enumerate()
        .map(|(i, m)| {
            let name = if m.name.is_empty() {
                format!("#{i}")
            } else {
                m.name.clone()
            };
            let mesh = m.mesh;
            let vertices: Vec<Vector3<f64>> = mesh
                .positions
                .chunks_exact(3)
                .map(|p| Vector3::new(p[0], p[1], p[2]))
                .collect();
            let mut faces = Vec::new();
            if mesh.face_arities.is_empty() {
                faces.extend(
                    mesh.indices
                        .chunks_exact(3)
                        .map(|t| t.iter().map(|&i| i as usize).collect()),
                );
            } else {
                let mut at = 0usize;
                for &n in &mesh.face_arities {
                    let n = n as usize;
                    faces.push(
                        mesh.indices[at..at + n]
                            .iter()
                            .map(|&i| i as usize)
                            .collect(),
                    );
                    at += n;
                }
            }
            (name, vertices, faces)
        })
        .collect())
}

fn read_stl(path: &Path) -> Result<Vec<RawPart>, (String, String)> {
    let mut file =
        std::fs::File::open(path).map_err(|e| (String::new(), format!("cannot open: {e}")))?;
    let mesh = stl_io::read_stl(&mut file)
        .map_err(|e| (String::new(), format!("cannot parse STL: {e}")))?;
    let vertices = mesh
        .vertices
        .iter()
        .map(|v| Vector3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    let faces = mesh.faces.iter().map(|f| f.vertices.to_vec()).collect();
    Ok(vec![("stl".into(), vertices, faces)])
}

/// Reads the 3DFACE entities of an ASCII DXF file: group codes 10/20/30 …
/// 13/23/33 are the four corners (the fourth equals the third for triangles).
fn read_dxf(path: &Path) -> Result<Vec<RawPart>, (String, String)> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| (String::new(), format!("cannot read DXF: {e}")))?;
    let mut lines: Vec<&str> = text.lines().map(str::trim).collect();
    // Stop at the end-of-file marker; ignore blank lines after it or at the end.
    if let Some(end) = lines
        .chunks_exact(2)
        .position(|c| c[0] == "0" && c[1] == "EOF")
    {
        lines.truncate(2 * end + 2);
    }
    while lines.last() == Some(&"") {
        lines.pop();
    }
    if lines.len() % 2 != 0 {
        return Err((
            String::new(),
            "DXF has an odd number of lines (group code without value)".into(),
        ));
    }
    let mut vertices = Vec::new();
    let mut faces = Vec::new();
    let mut corners: Option<[[f64; 3]; 4]> = None;
    let mut flush = |corners: &mut Option<[[f64; 3]; 4]>, vertices: &mut Vec<Vector3<f64>>| {
        if let Some(c) = corners.take() {
            let base = vertices.len();
            let mut face = vec![];
            for (k, p) in c.iter().enumerate() {
                if k == 3 && p == &c[2] {
                    break;
                }
                vertices.push(Vector3::from(*p));
                face.push(base + face.len());
            }
            faces.push(face);
        }
    };
    for (pair, chunk) in lines.chunks_exact(2).enumerate() {
        let code: i32 = chunk[0].parse().map_err(|_| {
            (
                String::new(),
                format!("DXF line {}: bad group code '{}'", 2 * pair + 1, chunk[0]),
            )
        })?;
        let value = chunk[1];
        if code == 0 {
            flush(&mut corners, &mut vertices);
            if value == "3DFACE" {
                corners = Some([[0.0; 3]; 4]);
            }
            continue;
        }
        if let Some(c) = corners.as_mut() {
            if (10..=33).contains(&code) && code % 10 <= 3 {
                let axis = (code / 10 - 1) as usize;
                let corner = (code % 10) as usize;
                c[corner][axis] = value.parse().map_err(|_| {
                    (
                        String::new(),
                        format!("DXF line {}: bad coordinate '{value}'", 2 * pair + 2),
                    )
                })?;
            }
        }
    }
    flush(&mut corners, &mut vertices);
    if faces.is_empty() {
        return Err((String::new(), "DXF file has no 3DFACE entities".into()));
    }
    Ok(vec![("dxf".into(), vertices, faces)])
}
