//! Procedural shapes, each a list of convex polyhedra in the shape's own frame
//! (the thesis's "ptree": a concave object is a union of convex parts).

use super::mesh_files;
pub use super::mesh_files::NamedPart;
use super::schema::ShapeSpec;
use crate::math;
use crate::polyhedron::ConvexPolyhedron;
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use std::f64::consts::PI;
use std::path::Path;

/// Upper bounds that keep a hostile scene from asking for absurd work.
pub const MAX_SIDES: u32 = 512;
pub const MAX_SUBDIVISIONS: u32 = 5;

/// Builds the convex parts of a shape. `field` names the shape in errors;
/// `base_dir` resolves mesh paths (the scene file's folder).
pub fn build_parts(
    spec: &ShapeSpec,
    field: &str,
    base_dir: &Path,
) -> Result<Vec<NamedPart>, (String, String)> {
    let err = |f: String, m: String| Err((f, m));
    match spec {
        ShapeSpec::Box { half_extents } => {
            let f = format!("{field}.box.half_extents");
            positive_all(half_extents, &f)?;
            let hull = box_hull(Vector3::from(*half_extents)).map_err(|e| (f.clone(), e))?;
            Ok(vec![NamedPart {
                name: format!("{field}.box"),
                hull,
            }])
        }
        ShapeSpec::Sphere {
            radius,
            subdivisions,
        } => {
            let f = format!("{field}.sphere");
            positive(*radius, &format!("{f}.radius"))?;
            if *subdivisions > MAX_SUBDIVISIONS {
                return err(
                    format!("{f}.subdivisions"),
                    format!("must be at most {MAX_SUBDIVISIONS}"),
                );
            }
            let hull = geodesic_sphere(*radius, *subdivisions).map_err(|e| (f.clone(), e))?;
            Ok(vec![NamedPart { name: f, hull }])
        }
        ShapeSpec::Cylinder {
            radius,
            half_height,
            sides,
        } => {
            let f = format!("{field}.cylinder");
            positive(*radius, &format!("{f}.radius"))?;
            positive(*half_height, &format!("{f}.half_height"))?;
            check_sides(*sides, 3, &format!("{f}.sides"))?;
            let hull = prism(
                &regular_polygon(*radius, *sides as usize, 0.0),
                -half_height,
                *half_height,
            )
            .map_err(|e| (f.clone(), e))?;
            Ok(vec![NamedPart { name: f, hull }])
        }
        ShapeSpec::Nut {
            across_flats,
            thickness,
            hole_radius,
            sides,
        } => {
            let f = format!("{field}.nut");
            positive(*across_flats, &format!("{f}.across_flats"))?;
            positive(*thickness, &format!("{f}.thickness"))?;
            positive(*hole_radius, &format!("{f}.hole_radius"))?;
            check_sides(*sides, 3, &format!("{f}.sides"))?;
            if *hole_radius >= 0.5 * across_flats * 0.95 {
                return err(
                    format!("{f}.hole_radius"),
                    format!(
                        "must be smaller than half of across_flats ({})",
                        0.5 * across_flats
                    ),
                );
            }
            nut_parts(*across_flats, *thickness, *hole_radius, *sides as usize)
                .map_err(|e| (f.clone(), e))
                .map(|parts| {
                    parts
                        .into_iter()
                        .enumerate()
                        .map(|(i, hull)| NamedPart {
                            name: format!("{f}.piece[{i}]"),
                            hull,
                        })
                        .collect()
                })
        }
        ShapeSpec::Bolt {
            head_across_flats,
            head_height,
            shaft_radius,
            shaft_length,
            sides,
        } => {
            let f = format!("{field}.bolt");
            positive(*head_across_flats, &format!("{f}.head_across_flats"))?;
            positive(*head_height, &format!("{f}.head_height"))?;
            positive(*shaft_radius, &format!("{f}.shaft_radius"))?;
            positive(*shaft_length, &format!("{f}.shaft_length"))?;
            check_sides(*sides, 3, &format!("{f}.sides"))?;
            // Head from z = 0 to head_height, shaft hanging below it.
            let head = prism(&hexagon(*head_across_flats), 0.0, *head_height)
                .map_err(|e| (f.clone(), e))?;
            let shaft = prism(
                &regular_polygon(*shaft_radius, *sides as usize, 0.0),
                -shaft_length,
                0.0,
            )
            .map_err(|e| (f.clone(), e))?;
            Ok(vec![
                NamedPart {
                    name: format!("{f}.head"),
                    hull: head,
                },
                NamedPart {
                    name: format!("{f}.shaft"),
                    hull: shaft,
                },
            ])
        }
        ShapeSpec::Mesh { path, hull } => {
            let f = format!("{field}.mesh.path");
            let full = base_dir.join(path);
            mesh_files::load_parts(&full, *hull).map_err(|(part, msg)| {
                let where_ = if part.is_empty() {
                    f.clone()
                } else {
                    format!("{f} part '{part}'")
                };
                (where_, format!("{}: {msg}", full.display()))
            })
        }
        ShapeSpec::Compound(items) => {
            if items.is_empty() {
                return err(
                    format!("{field}.compound"),
                    "must list at least one part".into(),
                );
            }
            let mut parts = Vec::new();
            for (i, item) in items.iter().enumerate() {
                let f = format!("{field}.compound[{i}]");
                finite_all(&item.position, &format!("{f}.position"))?;
                let rotation = unit_quaternion(&item.orientation, &format!("{f}.orientation"))?;
                let iso = Isometry3::from_parts(
                    Translation3::from(Vector3::from(item.position)),
                    rotation,
                );
                for p in build_parts(&item.shape, &format!("{f}.shape"), base_dir)? {
                    parts.push(NamedPart {
                        name: p.name,
                        hull: p.hull.transformed(&iso),
                    });
                }
            }
            Ok(parts)
        }
    }
}

pub fn unit_quaternion(q: &[f64; 4], field: &str) -> Result<UnitQuaternion<f64>, (String, String)> {
    finite_all(q, field)?;
    let quat = Quaternion::new(q[0], q[1], q[2], q[3]);
    if quat.norm() < 1e-9 {
        return Err((
            field.into(),
            "quaternion [w, x, y, z] must not be zero".into(),
        ));
    }
    Ok(UnitQuaternion::from_quaternion(quat))
}

pub fn finite_all(v: &[f64], field: &str) -> Result<(), (String, String)> {
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return Err((field.into(), format!("must be finite (got {x})")));
    }
    Ok(())
}

pub fn positive(x: f64, field: &str) -> Result<(), (String, String)> {
    if !x.is_finite() || x <= 0.0 {
        return Err((
            field.into(),
            format!("must be a positive finite number (got {x})"),
        ));
    }
    Ok(())
}

fn positive_all(v: &[f64], field: &str) -> Result<(), (String, String)> {
    for x in v {
        positive(*x, field)?;
    }
    Ok(())
}

fn check_sides(sides: u32, min: u32, field: &str) -> Result<(), (String, String)> {
    if sides < min || sides > MAX_SIDES {
        return Err((
            field.into(),
            format!("must be between {min} and {MAX_SIDES} (got {sides})"),
        ));
    }
    Ok(())
}

pub fn box_hull(h: Vector3<f64>) -> Result<ConvexPolyhedron, String> {
    let v = |x: f64, y: f64, z: f64| Vector3::new(x * h.x, y * h.y, z * h.z);
    let vertices = vec![
        v(-1.0, -1.0, -1.0),
        v(1.0, -1.0, -1.0),
        v(1.0, 1.0, -1.0),
        v(-1.0, 1.0, -1.0),
        v(-1.0, -1.0, 1.0),
        v(1.0, -1.0, 1.0),
        v(1.0, 1.0, 1.0),
        v(-1.0, 1.0, 1.0),
    ];
    // Counter-clockwise seen from outside.
    let faces = vec![
        vec![0, 3, 2, 1],
        vec![4, 5, 6, 7],
        vec![0, 1, 5, 4],
        vec![1, 2, 6, 5],
        vec![2, 3, 7, 6],
        vec![3, 0, 4, 7],
    ];
    ConvexPolyhedron::from_faces(vertices, faces).map_err(|e| e.to_string())
}

/// Icosahedron subdivided `subdivisions` times, vertices pushed onto the
/// sphere; the hull keeps it exactly convex whatever rounding does.
pub fn geodesic_sphere(radius: f64, subdivisions: u32) -> Result<ConvexPolyhedron, String> {
    let t = (1.0 + 5f64.sqrt()) / 2.0;
    let mut points: Vec<Vector3<f64>> = [
        [-1.0, t, 0.0],
        [1.0, t, 0.0],
        [-1.0, -t, 0.0],
        [1.0, -t, 0.0],
        [0.0, -1.0, t],
        [0.0, 1.0, t],
        [0.0, -1.0, -t],
        [0.0, 1.0, -t],
        [t, 0.0, -1.0],
        [t, 0.0, 1.0],
        [-t, 0.0, -1.0],
        [-t, 0.0, 1.0],
    ]
    .iter()
    .map(|p| Vector3::from(*p).normalize())
    .collect();
    let mut faces: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut midpoints = std::collections::HashMap::new();
        let mut mid = |a: usize, b: usize, points: &mut Vec<Vector3<f64>>| -> usize {
            *midpoints.entry((a.min(b), a.max(b))).or_insert_with(|| {
                points.push(((points[a] + points[b]) * 0.5).normalize());
                points.len() - 1
            })
        };
        let mut next = Vec::with_capacity(faces.len() * 4);
        for [a, b, c] in faces {
            let ab = mid(a, b, &mut points);
            let bc = mid(b, c, &mut points);
            let ca = mid(c, a, &mut points);
            next.extend_from_slice(&[[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    let scaled: Vec<Vector3<f64>> = points.iter().map(|p| p * radius).collect();
    ConvexPolyhedron::hull(&scaled).map_err(|e| e.to_string())
}

/// Vertices of a regular polygon in the xy plane, counter-clockwise.
pub fn regular_polygon(radius: f64, sides: usize, phase: f64) -> Vec<[f64; 2]> {
    (0..sides)
        .map(|i| {
            let a = phase + 2.0 * PI * i as f64 / sides as f64;
            [radius * math::cos(a), radius * math::sin(a)]
        })
        .collect()
}

/// Regular hexagon with the given distance across flats (flats parallel to x).
pub fn hexagon(across_flats: f64) -> Vec<[f64; 2]> {
    let circumradius = 0.5 * across_flats / math::cos(PI / 6.0);
    regular_polygon(circumradius, 6, 0.0)
}

/// Extrudes a convex counter-clockwise polygon between z0 and z1.
pub fn prism(polygon: &[[f64; 2]], z0: f64, z1: f64) -> Result<ConvexPolyhedron, String> {
    let n = polygon.len();
    let mut vertices = Vec::with_capacity(2 * n);
    for p in polygon {
        vertices.push(Vector3::new(p[0], p[1], z0));
    }
    for p in polygon {
        vertices.push(Vector3::new(p[0], p[1], z1));
    }
    let mut faces = Vec::with_capacity(n + 2);
    faces.push((0..n).rev().collect::<Vec<_>>()); // bottom, seen from below
    faces.push((n..2 * n).collect::<Vec<_>>()); // top
    for i in 0..n {
        let j = (i + 1) % n;
        faces.push(vec![i, j, n + j, n + i]);
    }
    ConvexPolyhedron::from_faces(vertices, faces).map_err(|e| e.to_string())
}

/// A hexagonal nut as a ring of convex wedges around a polygonal hole.
///
/// Wedge i lies between the rays through hole corners i and i+1: its outline
/// is the hole chord, the ray segments out to the hexagon, and the hexagon's
/// boundary between them (with any hexagon corner that falls inside the
/// wedge). Removing the triangle (centre, hole corner i, hole corner i+1) from
/// the convex region "wedge ∩ hexagon" keeps it convex while the wedge angle is
/// below 180°, so every piece is a convex prism.
pub fn nut_parts(
    across_flats: f64,
    thickness: f64,
    hole_radius: f64,
    sides: usize,
) -> Result<Vec<ConvexPolyhedron>, String> {
    let apothem = 0.5 * across_flats;
    let hex = hexagon(across_flats);
    // Distance from the centre to the hexagon boundary along direction angle a.
    let to_boundary = |a: f64| -> f64 {
        let sector = (a / (PI / 3.0)).floor();
        let flat_normal = sector * PI / 3.0 + PI / 6.0;
        apothem / math::cos(a - flat_normal)
    };
    let half = 0.5 * thickness;
    let mut parts = Vec::with_capacity(sides);
    for i in 0..sides {
        let a0 = 2.0 * PI * i as f64 / sides as f64;
        let a1 = 2.0 * PI * (i + 1) as f64 / sides as f64;
        let dir = |a: f64| [math::cos(a), math::sin(a)];
        let mut outline = vec![
            [hole_radius * dir(a0)[0], hole_radius * dir(a0)[1]],
            [to_boundary(a0) * dir(a0)[0], to_boundary(a0) * dir(a0)[1]],
        ];
        for (k, corner) in hex.iter().enumerate() {
            let ca = PI / 3.0 * k as f64;
            let ca = if ca < a0 - 1e-12 { ca + 2.0 * PI } else { ca };
            if ca > a0 + 1e-9 && ca < a1 - 1e-9 {
                outline.push(*corner);
            }
        }
        outline.push([
            to_boundary(a1 - 1e-15) * dir(a1)[0],
            to_boundary(a1 - 1e-15) * dir(a1)[1],
        ]);
        outline.push([hole_radius * dir(a1)[0], hole_radius * dir(a1)[1]]);
        parts.push(prism(&outline, -half, half)?);
    }
    Ok(parts)
}
