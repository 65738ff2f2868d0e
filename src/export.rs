//! `rigidsim export`: a loaded scene written out exactly as the simulator
//! holds it, so that another engine can be given the very same bodies.
//!
//! Nothing is recomputed here: every number is read from the `Scene` that
//! `scene::load` returns (scatter expanded, shapes re-centred at the centre
//! of mass, `fall_z` defaulted), the one `run` simulates. Pure data, no MPI.
//!
//! Frames: a body's parts are stored in its body frame (origin at the centre
//! of mass, axes those of the scene's shape), and its state is the pose of
//! that frame, so a vertex `v` of a part is at `x + R(q) v` in the world: the
//! narrowphase's `pose * vertex`. The layout is documented in README.md
//! ("rigidsim export").

use crate::body::{Body, BodyKind, ObjectDef};
use crate::scene::Scene;
use crate::scene::schema::CombineRule;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::Serialize;

/// Version of the layout below; raised whenever a field changes meaning or goes.
pub const FORMAT: u32 = 1;

/// The whole file.
#[derive(Serialize)]
pub struct SceneExport<'a> {
    pub format: u32,
    pub scene: &'a str,
    pub world: WorldExport,
    /// Shared geometry, referenced by `BodyExport::object`; numbered as the
    /// loader numbers them (the scene's `[objects]` sorted by name).
    pub objects: Vec<ObjectExport<'a>>,
    /// In rigidsim's body order, the `body` column of `trajectory.csv`.
    pub bodies: Vec<BodyExport<'a>>,
}

#[derive(Serialize)]
pub struct WorldExport {
    pub gravity: [f64; 3],
    pub dt: f64,
    /// `None` (null) when the run ends at rest or at `max_duration`.
    pub duration: Option<f64>,
    pub until_rest: bool,
    pub max_duration: f64,
    /// `None` (null): no cut-off (`Settings::fall_z` is −∞, which JSON cannot hold).
    pub fall_z: Option<f64>,
    /// How a contact's coefficient comes from the two bodies' own:
    /// `CombineRule::combine(a, b)`, i.e. min | max | mean | product.
    pub restitution_rule: CombineRule,
    pub friction_rule: CombineRule,
}

#[derive(Serialize)]
pub struct ObjectExport<'a> {
    pub index: usize,
    pub name: &'a str,
    /// Where the scene's shape origin lies in the body frame (`ObjectDef::shape_origin`).
    pub shape_origin: [f64; 3],
    pub parts: Vec<PartExport>,
}

/// One convex part, body frame.
#[derive(Serialize)]
pub struct PartExport {
    pub vertices: Vec<[f64; 3]>,
    /// Indices into `vertices`, each loop counter-clockwise seen from outside
    /// (outward normal by the right-hand rule); planar faces are merged, so
    /// a loop may have more than three vertices.
    pub faces: Vec<Vec<usize>>,
}

#[derive(Serialize)]
pub struct BodyExport<'a> {
    pub index: usize,
    pub object: usize,
    pub object_name: &'a str,
    /// dynamic | fixed | driven.
    pub kind: &'static str,
    /// The prescribed motion of a driven body; null otherwise.
    pub driven: Option<DrivenExport>,
    pub mass: f64,
    /// Body frame, about the centre of mass, rows.
    pub inertia: [[f64; 3]; 3],
    /// Ascending.
    pub principal_moments: [f64; 3],
    /// Rotation from the principal frame to the body frame, [w, x, y, z]:
    /// inertia = R diag(principal_moments) Rᵀ.
    pub principal_rotation: [f64; 4],
    pub restitution: f64,
    pub friction: f64,
    pub initial: StateExport,
}

#[derive(Serialize)]
pub struct DrivenExport {
    pub velocity: [f64; 3],
    pub angular_velocity: [f64; 3],
}

/// World frame, centre of mass.
#[derive(Serialize)]
pub struct StateExport {
    pub position: [f64; 3],
    /// Body to world, [w, x, y, z].
    pub orientation: [f64; 4],
    pub velocity: [f64; 3],
    /// As `trajectory.csv` reports it: ω = R I⁻¹ Rᵀ L for dynamic bodies.
    pub angular_velocity: [f64; 3],
    /// L, the quantity the integrator carries (zero for fixed and driven bodies).
    pub angular_momentum: [f64; 3],
}

fn vec3(v: &Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

fn quat(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

fn rows(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    [0, 1, 2].map(|r| [m[(r, 0)], m[(r, 1)], m[(r, 2)]])
}

/// The export of a loaded scene.
pub fn export(scene: &Scene) -> SceneExport<'_> {
    let s = &scene.settings;
    SceneExport {
        format: FORMAT,
        scene: &scene.name,
        world: WorldExport {
            gravity: vec3(&s.gravity),
            dt: s.dt,
            duration: s.duration,
            until_rest: s.until_rest,
            max_duration: s.max_duration,
            fall_z: s.fall_z.is_finite().then_some(s.fall_z),
            restitution_rule: s.restitution_rule,
            friction_rule: s.friction_rule,
        },
        objects: scene
            .objects
            .iter()
            .enumerate()
            .map(|(index, o)| object(index, o))
            .collect(),
        bodies: scene
            .bodies
            .iter()
            .enumerate()
            .map(|(index, b)| body(index, b, &scene.objects))
            .collect(),
    }
}

fn object(index: usize, o: &ObjectDef) -> ObjectExport<'_> {
    ObjectExport {
        index,
        name: &o.name,
        shape_origin: vec3(&o.shape_origin),
        parts: o
            .parts
            .iter()
            .map(|p| PartExport {
                vertices: p.hull.vertices().iter().map(vec3).collect(),
                faces: p.hull.faces().iter().map(|f| f.vertices.clone()).collect(),
            })
            .collect(),
    }
}

fn body<'a>(index: usize, b: &Body, objects: &'a [ObjectDef]) -> BodyExport<'a> {
    let o = &objects[b.object.0 as usize];
    let (kind, driven) = match b.kind {
        BodyKind::Dynamic => ("dynamic", None),
        BodyKind::Fixed => ("fixed", None),
        BodyKind::Driven {
            velocity,
            angular_velocity,
        } => (
            "driven",
            Some(DrivenExport {
                velocity: vec3(&velocity),
                angular_velocity: vec3(&angular_velocity),
            }),
        ),
    };
    BodyExport {
        index,
        object: b.object.0 as usize,
        object_name: &o.name,
        kind,
        driven,
        mass: o.mass,
        inertia: rows(&o.inertia),
        principal_moments: vec3(&o.principal_moments),
        principal_rotation: quat(&o.principal_rotation),
        restitution: o.restitution,
        friction: o.friction,
        initial: StateExport {
            position: vec3(&b.state.position),
            orientation: quat(&b.state.orientation),
            velocity: vec3(&b.state.velocity),
            angular_velocity: vec3(&b.angular_velocity(o)),
            angular_momentum: vec3(&b.state.angular_momentum),
        },
    }
}

/// Writes the export of `scene` to `path` as compact JSON (numbers round-trip
/// exactly), creating missing parent folders.
pub fn write(scene: &Scene, path: &std::path::Path) -> std::io::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)?;
    }
    let mut w = std::io::BufWriter::new(std::fs::File::create(path)?);
    serde_json::to_writer(&mut w, &export(scene))?;
    std::io::Write::write_all(&mut w, b"\n")?;
    std::io::Write::flush(&mut w)
}
