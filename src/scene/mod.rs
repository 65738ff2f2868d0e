//! Scene loading: TOML file → validated `Scene` (object definitions with exact
//! mass properties, bodies in scene order, forces, settings).
//!
//! Every rank calls `load` itself: static shapes and masses never travel.
//! Every problem becomes one `SceneError` naming the file and the field.

pub mod bounds;
pub mod mesh_files;
mod overlap;
pub mod schema;
pub mod shapes;

use crate::body::mass::{MomentSum, check_inertia, principal_axes};
use crate::body::{
    Activity, Body, BodyId, BodyKind, BodyState, BoundingSphere, ObjectDef, ObjectId, Part,
};
use crate::collision::narrowphase::{CONTACT_TOLERANCE, NEAR_FROM};
use crate::math;
use crate::polyhedron::{ConvexPolyhedron, Face};
use nalgebra::{Isometry3, Matrix3, Translation3, UnitQuaternion, Vector3};
use rand::{RngExt, SeedableRng};
use schema::{CombineRule, ObjectSection, SceneFile};
use std::path::{Path, PathBuf};

/// A scene asking for more bodies than this is refused, not attempted.
pub const MAX_BODIES: u64 = 200_000;
/// A scene file larger than this is refused before parsing.
pub const MAX_SCENE_BYTES: u64 = 16 * 1024 * 1024;

/// One line: `file: field: message`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{}: {}{}", file.display(), if field.is_empty() { String::new() } else { format!("{field}: ") }, message)]
pub struct SceneError {
    pub file: PathBuf,
    pub field: String,
    pub message: String,
}

#[derive(Clone, Debug)]
pub struct RenderSettings {
    pub size: [u32; 2],
    pub eye: Option<Vector3<f64>>,
    pub target: Option<Vector3<f64>>,
    pub every: f64,
    pub fov_y_deg: f64,
    pub video_fps: f64,
}

/// `world.speculative_speed` where a scene does not give it (m/s): 0, the
/// exact model. The speculative contacts add more rows to a pile's
/// islands than the events they remove save (`docs/benchmarks.md`, *The
/// contact model's dial*), so they are asked for, not assumed.
pub const DEFAULT_SPECULATIVE_SPEED: f64 = 0.0;

/// `world.pile_bodies` where a scene does not give it: an approach whose two
/// bodies' contact islands hold this many moving bodies together is inside a
/// pile; fewer (a cube on the floor, the cradle, two cubes) stay exact events.
pub const DEFAULT_PILE_BODIES: u32 = 8;

/// Blocks an island may be cut into at most (`Settings::island_blocks`):
/// more than a lab has ranks, and blocks of a few bodies each in the
/// largest piles.
pub const MAX_ISLAND_BLOCKS: u32 = 256;

/// Whether `n` may be `Settings::island_blocks`; the message if not.
pub fn check_island_blocks(n: u32) -> Result<(), String> {
    if (1..=MAX_ISLAND_BLOCKS).contains(&n) {
        Ok(())
    } else {
        Err(format!("must be from 1 to {MAX_ISLAND_BLOCKS} (got {n})"))
    }
}

#[derive(Clone, Debug)]
pub struct Settings {
    pub gravity: Vector3<f64>,
    pub dt: f64,
    pub duration: Option<f64>,
    pub until_rest: bool,
    pub max_duration: f64,
    /// Dynamic bodies whose centre of mass goes below this stop being
    /// simulated; `f64::NEG_INFINITY` when none ever does (a scene without
    /// `fall_z` and without fixed bodies, `default_fall_z`).
    pub fall_z: f64,
    pub frame_interval: f64,
    pub restitution_rule: CombineRule,
    pub friction_rule: CombineRule,
    /// `world.speculative_speed` as given (or `--speculative-speed`);
    /// `None`: the default, `speculative_speed()`.
    pub speculative_speed_given: Option<f64>,
    /// `world.pile_bodies` (`DEFAULT_PILE_BODIES` where absent).
    pub pile_bodies: u32,
    /// `world.island_blocks` (or `--island-blocks`; 1 where absent): the
    /// blocks the large-island method cuts an island into, so that ranks
    /// share its sweeps with the same bits on any rank count; 1 sweeps it
    /// whole.
    pub island_blocks: u32,
    /// Trajectory sampling interval; `None` samples every step.
    pub sample_every: Option<f64>,
    pub render: Option<RenderSettings>,
}

impl Settings {
    /// Simulated time at which the run stops at the latest.
    pub fn end_time(&self) -> f64 {
        self.duration.unwrap_or(self.max_duration)
    }

    /// The dial from exact to fast: approaches up to this speed (m/s)
    /// inside a pile (`pile_bodies`) are solved at the step by speculative
    /// contacts, their bounce carried to the step where the bodies meet; 0:
    /// every impact is an exact event (the exact model).
    pub fn speculative_speed(&self) -> f64 {
        self.speculative_speed_given
            .unwrap_or(DEFAULT_SPECULATIVE_SPEED)
    }

    /// Approaches up to this speed are solved at the step wherever they
    /// are: below the restitution threshold an impact does not bounce, so
    /// nothing of it is lost (none in the exact model).
    pub fn slow_speed(&self) -> f64 {
        self.speculative_speed().min(self.restitution_threshold())
    }

    /// Impacts slower than this converge to contact (ε = 0): g·dt/2, the
    /// thesis's threshold (SPEC 2.6).
    pub fn restitution_threshold(&self) -> f64 {
        0.5 * self.gravity.norm() * self.dt
    }

    /// How far apart contact points are kept as speculative contacts: what
    /// an approach at the faster of the two speeds, under twice gravity's
    /// acceleration, closes in a step, past `NEAR_FROM`. 0 (none) in the
    /// exact model.
    pub fn near_distance(&self) -> f64 {
        let v = self.speculative_speed().max(self.slow_speed());
        if v > 0.0 {
            v * self.dt + self.gravity.norm() * self.dt * self.dt + NEAR_FROM
        } else {
            0.0
        }
    }

    /// Steps to the end time (saturating at `u64::MAX`); a run takes them
    /// all unless it comes to rest first.
    pub fn total_steps(&self) -> u64 {
        (self.end_time() / self.dt - 1e-9).ceil().max(0.0) as u64
    }
}

/// How far below the lowest point of the fixed bodies `fall_z` lies when the
/// scene does not set it, metres.
pub const FALL_BELOW_FIXED: f64 = 1.0;

/// `world.fall_z` when the scene does not set it: `FALL_BELOW_FIXED` below
/// the lowest vertex of any fixed body, in world coordinates (a body that
/// left the floor over its edge falls past its underside, not its centre),
/// or no cut-off when no fixed body suggests a floor.
pub fn default_fall_z(bodies: &[Body], objects: &[ObjectDef]) -> f64 {
    let lowest = bodies
        .iter()
        .filter(|b| matches!(b.kind, BodyKind::Fixed))
        .flat_map(|b| {
            let pose = b.pose();
            objects[b.object.0 as usize]
                .parts
                .iter()
                .flat_map(move |p| {
                    p.hull
                        .vertices()
                        .iter()
                        .map(move |v| (pose * nalgebra::Point3::from(*v)).z)
                })
        })
        .fold(f64::INFINITY, f64::min);
    if lowest.is_finite() {
        lowest - FALL_BELOW_FIXED
    } else {
        f64::NEG_INFINITY
    }
}

/// An external force on one body over [start, end).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ForceWindow {
    pub body: BodyId,
    pub force: Vector3<f64>,
    pub torque: Vector3<f64>,
    pub start: f64,
    pub end: f64,
}

/// A loaded, validated scene: static data plus the initial state of every body.
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub path: PathBuf,
    pub settings: Settings,
    pub objects: Vec<ObjectDef>,
    pub bodies: Vec<Body>,
    pub forces: Vec<ForceWindow>,
}

impl Scene {
    pub fn object_of(&self, body: BodyId) -> &ObjectDef {
        &self.objects[self.bodies[body.index()].object.0 as usize]
    }
}

/// Reads, parses and validates a scene file.
pub fn load(path: &Path) -> Result<Scene, SceneError> {
    let fail = |field: &str, message: String| SceneError {
        file: path.to_path_buf(),
        field: field.to_string(),
        message,
    };
    let meta = std::fs::metadata(path).map_err(|e| fail("", format!("cannot read scene: {e}")))?;
    if meta.len() > MAX_SCENE_BYTES {
        return Err(fail(
            "",
            format!("scene file is larger than {MAX_SCENE_BYTES} bytes"),
        ));
    }
    let text =
        std::fs::read_to_string(path).map_err(|e| fail("", format!("cannot read scene: {e}")))?;
    let file = parse(&text).map_err(|(field, message)| fail(&field, message))?;
    let base_dir = path.parent().unwrap_or(Path::new("."));
    let name = path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("scene")
        .to_string();
    build(file, base_dir, name, path).map_err(|(field, message)| fail(&field, message))
}

/// Loads a scene from TOML text (tests, tools): `file` names it in errors and
/// `base_dir` resolves mesh paths.
pub fn from_str(text: &str, file: &Path, base_dir: &Path) -> Result<Scene, SceneError> {
    let fail = |(field, message): (String, String)| SceneError {
        file: file.to_path_buf(),
        field,
        message,
    };
    let parsed = parse(text).map_err(fail)?;
    let name = file
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("scene")
        .to_string();
    build(parsed, base_dir, name, file).map_err(fail)
}

/// Parses TOML text into the schema; errors are (field path, message).
pub fn parse(text: &str) -> Result<SceneFile, (String, String)> {
    let line_of = |span: Option<std::ops::Range<usize>>| {
        span.map(|s| {
            format!(
                "line {}: ",
                text[..s.start.min(text.len())].matches('\n').count() + 1
            )
        })
        .unwrap_or_default()
    };
    let de = toml::Deserializer::parse(text).map_err(|e| {
        (
            String::new(),
            format!("{}{}", line_of(e.span()), one_line(e.message())),
        )
    })?;
    serde_path_to_error::deserialize(de).map_err(|e| {
        let path = e.path().to_string();
        let inner = e.into_inner();
        let field = if path == "." { String::new() } else { path };
        (
            field,
            format!("{}{}", line_of(inner.span()), one_line(inner.message())),
        )
    })
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

type FieldResult<T> = Result<T, (String, String)>;

fn build(file: SceneFile, base_dir: &Path, name: String, path: &Path) -> FieldResult<Scene> {
    let mut settings = build_settings(&file)?;
    let mut objects = Vec::new();
    let mut object_ids = std::collections::BTreeMap::new();
    for (index, (obj_name, section)) in file.objects.iter().enumerate() {
        let def = build_object(obj_name, section, index, base_dir)?;
        object_ids.insert(obj_name.clone(), ObjectId(objects.len() as u32));
        objects.push(def);
    }
    let lookup = |name: &str, field: String| -> FieldResult<ObjectId> {
        object_ids.get(name).copied().ok_or_else(|| {
            let known: Vec<&str> = object_ids.keys().map(String::as_str).collect();
            (
                field,
                format!("unknown object '{name}' (defined: {})", known.join(", ")),
            )
        })
    };

    // Saturating: counts near u64::MAX must not wrap past the limit.
    let mut total = file.bodies.len() as u64;
    for (i, s) in file.scatter.iter().enumerate() {
        total = total.saturating_add(s.count);
        if total > MAX_BODIES {
            return Err((
                format!("scatter[{i}].count"),
                format!(
                    "the scene asks for {total} or more bodies, more than the limit of {MAX_BODIES}"
                ),
            ));
        }
    }

    let mut bodies = Vec::new();
    for (i, b) in file.bodies.iter().enumerate() {
        let f = format!("bodies[{i}]");
        let object = lookup(&b.object, format!("{f}.object"))?;
        shapes::finite_all(&b.position, &format!("{f}.position"))?;
        shapes::finite_all(&b.velocity, &format!("{f}.velocity"))?;
        shapes::finite_all(&b.angular_velocity, &format!("{f}.angular_velocity"))?;
        let reach = bounds::reach(&objects[object.0 as usize]);
        bounds::check_position(&b.position, &format!("{f}.position"))?;
        bounds::check_speed(&b.velocity, &format!("{f}.velocity"))?;
        bounds::check_spin(&b.angular_velocity, reach, &format!("{f}.angular_velocity"))?;
        let orientation = shapes::unit_quaternion(&b.orientation, &format!("{f}.orientation"))?;
        let kind = match (&b.driven, b.fixed) {
            (Some(_), true) => {
                return Err((
                    format!("{f}.driven"),
                    "a body cannot be both fixed and driven".into(),
                ));
            }
            (Some(d), false) => {
                shapes::finite_all(&d.velocity, &format!("{f}.driven.velocity"))?;
                shapes::finite_all(&d.angular_velocity, &format!("{f}.driven.angular_velocity"))?;
                bounds::check_speed(&d.velocity, &format!("{f}.driven.velocity"))?;
                bounds::check_spin(
                    &d.angular_velocity,
                    reach,
                    &format!("{f}.driven.angular_velocity"),
                )?;
                BodyKind::Driven {
                    velocity: d.velocity.into(),
                    angular_velocity: d.angular_velocity.into(),
                }
            }
            (None, true) => BodyKind::Fixed,
            (None, false) => BodyKind::Dynamic,
        };
        bodies.push(make_body(
            &objects[object.0 as usize],
            object,
            kind,
            Vector3::from(b.position),
            orientation,
            Vector3::from(b.velocity),
            Vector3::from(b.angular_velocity),
        ));
    }

    for (si, s) in file.scatter.iter().enumerate() {
        scatter(&mut bodies, &objects, s, si, &lookup)?;
    }

    let mut forces = Vec::new();
    for (i, f) in file.forces.iter().enumerate() {
        let field = format!("forces[{i}]");
        if f.body >= bodies.len() as u64 {
            return Err((
                format!("{field}.body"),
                format!(
                    "no body {} (the scene has {} bodies, numbered from 0)",
                    f.body,
                    bodies.len()
                ),
            ));
        }
        shapes::finite_all(&f.force, &format!("{field}.force"))?;
        shapes::finite_all(&f.torque, &format!("{field}.torque"))?;
        shapes::finite_all(&[f.start], &format!("{field}.start"))?;
        // What the force does to the body it pushes: its centre's
        // acceleration, and its surface's from the torque (about the axis
        // it turns most easily about: the smallest principal moment).
        let o = &objects[bodies[f.body as usize].object.0 as usize];
        bounds::check_acceleration(
            bounds::magnitude(&f.force) / o.mass,
            &format!("{field}.force"),
            &format!("accelerates body {} ({} kg) at", f.body, o.mass),
        )?;
        let turn = bounds::magnitude(&f.torque) / o.principal_moments.min() * bounds::reach(o);
        bounds::check_acceleration(
            turn,
            &format!("{field}.torque"),
            &format!("accelerates body {}'s surface at", f.body),
        )?;
        let end = f.end.unwrap_or(f64::INFINITY);
        if end.is_nan() || end <= f.start {
            return Err((format!("{field}.end"), "must be later than start".into()));
        }
        forces.push(ForceWindow {
            body: BodyId(f.body as u32),
            force: f.force.into(),
            torque: f.torque.into(),
            start: f.start,
            end,
        });
    }

    if let Some(o) = overlap::first_overlap(&bodies, &objects) {
        return Err(overlap_error(&o, &file, &bodies, &objects));
    }
    if file.world.fall_z.is_none() {
        settings.fall_z = default_fall_z(&bodies, &objects);
    }

    Ok(Scene {
        name,
        path: path.to_path_buf(),
        settings,
        objects,
        bodies,
        forces,
    })
}

fn build_settings(file: &SceneFile) -> FieldResult<Settings> {
    let w = &file.world;
    shapes::finite_all(&w.gravity, "world.gravity")?;
    bounds::check_acceleration(
        bounds::magnitude(&w.gravity),
        "world.gravity",
        "accelerates bodies at",
    )?;
    shapes::positive(w.dt, "world.dt")?;
    if w.dt > 1.0 {
        return Err((
            "world.dt".into(),
            format!("must be at most 1 s (got {})", w.dt),
        ));
    }
    shapes::positive(w.frame_interval, "world.frame_interval")?;
    shapes::positive(w.max_duration, "world.max_duration")?;
    if let Some(v) = w.speculative_speed
        && (!v.is_finite() || v < 0.0)
    {
        return Err((
            "world.speculative_speed".into(),
            format!("must be a finite number ≥ 0 m/s (got {v})"),
        ));
    }
    if let Some(n) = w.island_blocks {
        check_island_blocks(n).map_err(|m| ("world.island_blocks".to_string(), m))?;
    }
    if let Some(z) = w.fall_z {
        shapes::finite_all(&[z], "world.fall_z")?;
    }
    if let Some(d) = w.duration {
        if !d.is_finite() || d < 0.0 {
            return Err((
                "world.duration".into(),
                format!("must be a finite number ≥ 0 (got {d})"),
            ));
        }
    } else if !w.until_rest {
        return Err((
            "world.duration".into(),
            "is required unless until_rest = true".into(),
        ));
    }
    let steps_field = if w.duration.is_some() {
        "world.duration"
    } else {
        "world.max_duration"
    };
    if let Some(s) = file.output.sample_every {
        shapes::positive(s, "output.sample_every")?;
    }
    let render = match &file.render {
        None => None,
        Some(r) => {
            if r.size[0] < 16 || r.size[1] < 16 || r.size[0] > 8192 || r.size[1] > 8192 {
                return Err((
                    "render.size".into(),
                    "each side must be between 16 and 8192 pixels".into(),
                ));
            }
            if let Some(e) = &r.eye {
                shapes::finite_all(e, "render.eye")?;
            }
            if let Some(t) = &r.target {
                shapes::finite_all(t, "render.target")?;
            }
            if !(r.fov_y_deg > 1.0 && r.fov_y_deg < 179.0) {
                return Err((
                    "render.fov_y_deg".into(),
                    "must be between 1 and 179 degrees".into(),
                ));
            }
            let every = r.every.unwrap_or(w.frame_interval);
            shapes::positive(every, "render.every")?;
            let video_fps = r.video_fps.unwrap_or(1.0 / every);
            shapes::positive(video_fps, "render.video_fps")?;
            Some(RenderSettings {
                size: r.size,
                eye: r.eye.map(Vector3::from),
                target: r.target.map(Vector3::from),
                every,
                fov_y_deg: r.fov_y_deg,
                video_fps,
            })
        }
    };
    let settings = Settings {
        gravity: w.gravity.into(),
        dt: w.dt,
        duration: w.duration,
        until_rest: w.until_rest,
        max_duration: w.max_duration,
        // The default depends on the fixed bodies: `build` sets it.
        fall_z: w.fall_z.unwrap_or(f64::NEG_INFINITY),
        frame_interval: w.frame_interval,
        restitution_rule: w.restitution_rule,
        friction_rule: w.friction_rule,
        speculative_speed_given: w.speculative_speed,
        pile_bodies: w.pile_bodies.unwrap_or(DEFAULT_PILE_BODIES),
        island_blocks: w.island_blocks.unwrap_or(1),
        sample_every: file.output.sample_every,
        render,
    };
    bounds::check_step_count(&settings).map_err(|m| (steps_field.to_string(), m))?;
    Ok(settings)
}

/// One line for bodies placed inside each other: the later body's field,
/// both bodies with their objects, and the depth.
fn overlap_error(
    o: &overlap::StartOverlap,
    file: &SceneFile,
    bodies: &[Body],
    objects: &[ObjectDef],
) -> (String, String) {
    let object = |i: usize| &objects[bodies[i].object.0 as usize].name;
    let (field_b, who_b) = match origin(o.b, file) {
        Origin::Listed(i) => (format!("bodies[{i}]"), format!("object '{}'", object(o.b))),
        Origin::Scattered(k) => (
            format!("scatter[{k}]"),
            format!("body {} (object '{}')", o.b, object(o.b)),
        ),
    };
    let who_a = match origin(o.a, file) {
        Origin::Listed(i) => format!("bodies[{i}] (object '{}')", object(o.a)),
        Origin::Scattered(k) => format!("body {} of scatter[{k}] (object '{}')", o.a, object(o.a)),
    };
    (
        field_b,
        format!(
            "{who_b} overlaps {who_a} by {} m at the start, more than the contact tolerance \
             ({CONTACT_TOLERANCE:e} m); move them apart (bodies may touch)",
            four_digits(o.depth)
        ),
    )
}

/// Where a body of the scene comes from.
enum Origin {
    /// `[[bodies]]` entry i.
    Listed(usize),
    /// Placed by `[[scatter]]` entry k.
    Scattered(usize),
}

/// Body `i` in scene order: the `[[bodies]]` in file order, then each
/// scatter's bodies in turn.
fn origin(i: usize, file: &SceneFile) -> Origin {
    if i < file.bodies.len() {
        return Origin::Listed(i);
    }
    let mut end = file.bodies.len() as u64;
    for (k, s) in file.scatter.iter().enumerate() {
        end += s.count;
        if (i as u64) < end {
            return Origin::Scattered(k);
        }
    }
    Origin::Scattered(file.scatter.len().saturating_sub(1))
}

/// `x` with four significant digits, in plain decimals (0.1500, 0.00002000).
fn four_digits(x: f64) -> String {
    if !(x.is_finite() && x > 0.0) {
        return format!("{x}");
    }
    let decimals = (3.0 - x.log10().floor()).clamp(0.0, 20.0) as usize;
    format!("{x:.decimals$}")
}

/// Distinct, readable colours for object definitions without `color`.
const PALETTE: [[f32; 3]; 8] = [
    [0.86, 0.30, 0.24],
    [0.25, 0.55, 0.85],
    [0.95, 0.70, 0.20],
    [0.35, 0.70, 0.40],
    [0.60, 0.40, 0.75],
    [0.90, 0.50, 0.70],
    [0.30, 0.75, 0.75],
    [0.75, 0.60, 0.45],
];

fn build_object(
    name: &str,
    s: &ObjectSection,
    index: usize,
    base_dir: &Path,
) -> FieldResult<ObjectDef> {
    let f = format!("objects.{name}");
    let named = shapes::build_parts(&s.shape, &format!("{f}.shape"), base_dir)?;
    let mut moments = MomentSum::new();
    for p in &named {
        moments.add_mesh(p.hull.vertices(), &p.hull.triangles());
    }
    bounds::check_size(
        bounds::extent(named.iter().map(|p| &p.hull)),
        &format!("{f}.shape"),
    )?;
    let props = moments.finish();
    let scale = named
        .iter()
        .flat_map(|p| p.hull.vertices().iter())
        .map(|v| v.norm())
        .fold(0.0, f64::max);
    // NaN fails too.
    if props.volume.is_nan() || props.volume <= 1e-12 * scale.powi(3) {
        return Err((
            format!("{f}.shape"),
            format!("has zero volume ({:e} m³)", props.volume),
        ));
    }
    let mass = match (s.mass, s.density) {
        (Some(_), Some(_)) => {
            return Err((format!("{f}.mass"), "give mass or density, not both".into()));
        }
        (None, None) => return Err((format!("{f}.mass"), "is required (or give density)".into())),
        (Some(m), None) => {
            shapes::positive(m, &format!("{f}.mass"))?;
            bounds::check_mass(m, &format!("{f}.mass"), "is")?;
            m
        }
        (None, Some(d)) => {
            shapes::positive(d, &format!("{f}.density"))?;
            let m = d * props.volume;
            bounds::check_mass(m, &format!("{f}.density"), "gives a mass of")?;
            m
        }
    };
    let inertia = match &s.inertia {
        Some(rows) => {
            let m = Matrix3::from_row_slice(&rows.concat());
            check_inertia(&m).map_err(|e| (format!("{f}.inertia"), e))?;
            // Every point of the body lies within `reach` of the centre of
            // mass (the farthest hull vertex), so I_xx + I_yy + I_zz =
            // 2 ∫ r² dm ≤ 2 m reach² (a thin spherical shell reaches it):
            // a larger inertia belongs to no body of this mass and shape,
            // and one of 1e200 kg·m² would leave the contact solve's
            // products at 1e-200.
            let reach = bounds::reach_from(named.iter().map(|p| &p.hull), &props.centroid);
            let most = 2.0 * mass * reach * reach;
            if m.trace() > most * (1.0 + 1e-9) {
                return Err((
                    format!("{f}.inertia"),
                    format!(
                        "is larger than any body of mass {mass} kg within this shape can have: \
                         its diagonal sums to {:.6e} kg·m², at most 2·mass·r² = {most:.6e} \
                         (r = {reach:.6e} m, the shape's farthest point from its centre)",
                        m.trace()
                    ),
                ));
            }
            m
        }
        None => {
            let m = props.unit_inertia * (mass / props.volume);
            check_inertia(&m)
                .map_err(|e| (format!("{f}.shape"), format!("computed inertia {e}")))?;
            m
        }
    };
    let inv_inertia = inertia
        .try_inverse()
        .ok_or_else(|| (format!("{f}.inertia"), "is singular".to_string()))?;
    let (principal_rotation, principal_moments) = principal_axes(&inertia);
    if !(0.0..=1.0).contains(&s.restitution) {
        return Err((
            format!("{f}.restitution"),
            format!("must be between 0 and 1 (got {})", s.restitution),
        ));
    }
    if !s.friction.is_finite() || s.friction < 0.0 {
        return Err((
            format!("{f}.friction"),
            format!("must be a finite number ≥ 0 (got {})", s.friction),
        ));
    }
    if let Some(c) = s.color {
        if c.iter().any(|x| !(0.0..=1.0).contains(x)) {
            return Err((
                format!("{f}.color"),
                "components must be between 0 and 1".into(),
            ));
        }
    }

    // Re-centre the body frame at the centre of mass.
    let recentre = Isometry3::from_parts(
        Translation3::from(-props.centroid),
        UnitQuaternion::identity(),
    );
    let parts: Vec<Part> = named
        .iter()
        .map(|p| {
            let hull = p.hull.transformed(&recentre);
            let (center, radius) = hull.bounding_sphere();
            Part {
                hull,
                sphere: BoundingSphere { center, radius },
            }
        })
        .collect();
    // Triangles, as the thesis counts polygons (a cube has 12).
    let polygon_count = parts.iter().map(|p| p.hull.triangles().len()).sum();
    let thickness = min_thickness(&parts);

    let spheres = match &s.spheres {
        Some(list) => {
            if list.is_empty() {
                return Err((
                    format!("{f}.spheres"),
                    "must list at least one sphere".into(),
                ));
            }
            let mut out = Vec::new();
            for (i, sp) in list.iter().enumerate() {
                shapes::finite_all(&sp.center, &format!("{f}.spheres[{i}].center"))?;
                shapes::positive(sp.radius, &format!("{f}.spheres[{i}].radius"))?;
                out.push(BoundingSphere {
                    center: sp.center.into(),
                    radius: sp.radius,
                });
            }
            // Spheres that miss part of the shape would hide collisions.
            for (pi, p) in parts.iter().enumerate() {
                for (vi, v) in p.hull.vertices().iter().enumerate() {
                    let inside = out
                        .iter()
                        .any(|sp| (v - sp.center).norm() <= sp.radius * (1.0 + 1e-9));
                    if !inside {
                        return Err((
                            format!("{f}.spheres"),
                            format!(
                                "do not enclose vertex {vi} of part '{}' at {:?} (centre-of-mass frame)",
                                named[pi].name,
                                [v.x, v.y, v.z]
                            ),
                        ));
                    }
                }
            }
            out
        }
        None => parts.iter().flat_map(|p| part_spheres(&p.hull)).collect(),
    };

    Ok(ObjectDef {
        name: name.to_string(),
        parts,
        mass,
        inertia,
        inv_inertia,
        principal_rotation,
        principal_moments,
        restitution: s.restitution,
        friction: s.friction,
        spheres,
        shape_origin: -props.centroid,
        color: s.color.unwrap_or(PALETTE[index % PALETTE.len()]),
        polygon_count,
        volume: props.volume,
        min_thickness: thickness,
    })
}

/// Broadphase spheres of one convex part: one sphere, or several along the
/// longest axis when the part is long and thin (SPEC 2.3, fig. 3.5), where a
/// single sphere would be mostly empty space and report false pairs.
///
/// The part is cut into k slabs along its longest axis; each slab's sphere is
/// centred on the slab's middle and reaches the farthest point of the part
/// inside the slab. Those points are vertices of (part ∩ slab): the part's own
/// vertices in the slab and the crossings of its edges with the slab planes.
pub fn part_spheres(hull: &crate::polyhedron::ConvexPolyhedron) -> Vec<BoundingSphere> {
    let verts = hull.vertices();
    let (center, radius) = hull.bounding_sphere();
    let mut lo = verts[0];
    let mut hi = verts[0];
    for v in verts {
        lo = lo.inf(v);
        hi = hi.sup(v);
    }
    let ext = hi - lo;
    let axis = ext.imax();
    let long = ext[axis];
    let short = ext
        .iter()
        .enumerate()
        .filter(|(i, _)| *i != axis)
        .map(|(_, x)| *x)
        .fold(0.0, f64::max);
    let k = if short > 0.0 {
        (long / short).floor().clamp(1.0, 8.0) as usize
    } else {
        1
    };
    if k < 3 {
        return vec![BoundingSphere { center, radius }];
    }
    let width = long / k as f64;
    let mid = 0.5 * (lo + hi);
    let mut edges = Vec::new();
    for face in hull.faces() {
        let n = face.vertices.len();
        for i in 0..n {
            edges.push((face.vertices[i], face.vertices[(i + 1) % n]));
        }
    }
    (0..k)
        .map(|s| {
            let a = lo[axis] + width * s as f64;
            let b = a + width;
            let mut c = mid;
            c[axis] = 0.5 * (a + b);
            let mut r: f64 = 0.0;
            for v in verts {
                if v[axis] >= a - 1e-12 && v[axis] <= b + 1e-12 {
                    r = r.max((v - c).norm());
                }
            }
            for &(i, j) in &edges {
                let (p, q) = (verts[i], verts[j]);
                for plane in [a, b] {
                    let (dp, dq) = (p[axis] - plane, q[axis] - plane);
                    if dp * dq < 0.0 {
                        let x = p + (q - p) * (dp / (dp - dq));
                        r = r.max((x - c).norm());
                    }
                }
            }
            BoundingSphere {
                center: c,
                radius: r * (1.0 + 1e-9) + 1e-12,
            }
        })
        .collect()
}

/// The thinnest wall of a body, for the time-of-impact sampling
/// (`ObjectDef::min_thickness`): per convex part, twice the least distance
/// from its vertex centroid to a face of the body's surface. A face glued
/// to another part's face (`glued`) is no surface: the body's material goes
/// on through it, so a point crossing the part through it is still inside
/// the body. A nut's 32 wedges are 3 mm wide between their glued sides, and
/// its wall 9 mm thick between the faces of its flats and its hole: taking
/// the wedges' width sampled the nut's pairs every 1.5 mm of travel.
/// Only parts whose bounding spheres touch can share a face, so a mesh of
/// many parts tests each face against its neighbours' only.
fn min_thickness(parts: &[Part]) -> f64 {
    let touching = |p: &Part, q: &Part| {
        (p.sphere.center - q.sphere.center).norm()
            <= (p.sphere.radius + q.sphere.radius) * (1.0 + 1e-9)
    };
    parts
        .iter()
        .enumerate()
        .map(|(k, part)| {
            let hull = &part.hull;
            let verts = hull.vertices();
            let c = verts.iter().sum::<Vector3<f64>>() / verts.len() as f64;
            let distance = |f: &Face| f.normal.dot(&(verts[f.vertices[0]] - c));
            let surface = hull
                .faces()
                .iter()
                .filter(|f| {
                    !parts.iter().enumerate().any(|(j, other)| {
                        j != k && touching(part, other) && glued(hull, f, &other.hull)
                    })
                })
                .map(distance)
                .fold(f64::INFINITY, f64::min);
            // A part glued on every side is no body's whole wall: its own
            // width then, as for a part alone.
            if surface.is_finite() {
                surface
            } else {
                hull.faces()
                    .iter()
                    .map(distance)
                    .fold(f64::INFINITY, f64::min)
            }
        })
        .fold(f64::INFINITY, f64::min)
        * 2.0
}

/// Whether face `f` of `hull` lies wholly on a face of `other` that faces
/// it: the same plane with opposite normals, every corner of `f` inside
/// that face (to 1e-9 of the parts' size).
fn glued(hull: &ConvexPolyhedron, f: &Face, other: &ConvexPolyhedron) -> bool {
    let tol = 1e-9 * hull.scale().max(other.scale());
    let corners = || f.vertices.iter().map(|&v| hull.vertices()[v]);
    other.faces().iter().any(|g| {
        g.normal.dot(&f.normal) <= -(1.0 - 1e-9)
            && (g.offset + f.offset).abs() <= tol
            && corners().all(|x| {
                let ring = &g.vertices;
                (0..ring.len()).all(|i| {
                    let u0 = other.vertices()[ring[i]];
                    let u1 = other.vertices()[ring[(i + 1) % ring.len()]];
                    (u1 - u0).cross(&(x - u0)).dot(&g.normal) >= -tol * (u1 - u0).norm()
                })
            })
    })
}

/// Builds a body from a placement of the shape's origin.
fn make_body(
    object: &ObjectDef,
    id: ObjectId,
    kind: BodyKind,
    origin: Vector3<f64>,
    orientation: UnitQuaternion<f64>,
    velocity: Vector3<f64>,
    angular_velocity: Vector3<f64>,
) -> Body {
    // The scene places the shape's origin; the centre of mass sits at −shape_origin from it.
    let position = origin - orientation * object.shape_origin;
    let r = orientation.to_rotation_matrix();
    let inertia_world = r.matrix() * object.inertia * r.matrix().transpose();
    let (velocity, angular_momentum) = match kind {
        BodyKind::Dynamic => (velocity, inertia_world * angular_velocity),
        BodyKind::Fixed => (Vector3::zeros(), Vector3::zeros()),
        BodyKind::Driven { velocity, .. } => (velocity, Vector3::zeros()),
    };
    Body {
        object: id,
        kind,
        state: BodyState {
            position,
            orientation,
            velocity,
            angular_momentum,
        },
        activity: Activity::Awake,
    }
}

/// World-frame axis-aligned boxes of a body's parts (for placement checks).
fn part_boxes(object: &ObjectDef, body: &Body) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let pose = body.pose();
    object
        .parts
        .iter()
        .map(|p| {
            let mut lo = Vector3::repeat(f64::INFINITY);
            let mut hi = Vector3::repeat(f64::NEG_INFINITY);
            for v in p.hull.vertices() {
                let w = pose * nalgebra::Point3::from(*v);
                lo = lo.inf(&w.coords);
                hi = hi.sup(&w.coords);
            }
            (lo, hi)
        })
        .collect()
}

fn boxes_overlap(a: &[(Vector3<f64>, Vector3<f64>)], b: &[(Vector3<f64>, Vector3<f64>)]) -> bool {
    a.iter().any(|(alo, ahi)| {
        b.iter()
            .any(|(blo, bhi)| (0..3).all(|k| alo[k] <= bhi[k] && blo[k] <= ahi[k]))
    })
}

/// Random, non-overlapping placement reproducible from the seed. Overlap is
/// judged on the parts' world boxes: conservative (never accepts an overlap).
fn scatter(
    bodies: &mut Vec<Body>,
    objects: &[ObjectDef],
    s: &schema::ScatterSection,
    index: usize,
    lookup: &dyn Fn(&str, String) -> FieldResult<ObjectId>,
) -> FieldResult<()> {
    let f = format!("scatter[{index}]");
    if s.objects.is_empty() {
        return Err((
            format!("{f}.objects"),
            "must list at least one object".into(),
        ));
    }
    let ids = s
        .objects
        .iter()
        .enumerate()
        .map(|(i, n)| lookup(n, format!("{f}.objects[{i}]")))
        .collect::<FieldResult<Vec<_>>>()?;
    shapes::finite_all(&s.min, &format!("{f}.min"))?;
    shapes::finite_all(&s.max, &format!("{f}.max"))?;
    shapes::finite_all(&s.velocity, &format!("{f}.velocity"))?;
    bounds::check_position(&s.min, &format!("{f}.min"))?;
    bounds::check_position(&s.max, &format!("{f}.max"))?;
    bounds::check_speed(&s.velocity, &format!("{f}.velocity"))?;
    if (0..3).any(|k| s.min[k] > s.max[k]) {
        return Err((format!("{f}.max"), "must be ≥ min on every axis".into()));
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(s.seed);
    // Placed bodies in a uniform grid (cells of twice the largest scattered
    // body), so each attempt tests only its neighbours: placing n bodies costs
    // O(n), not O(n²). Bodies much larger than a cell (floors, walls) are
    // kept in a short list tested every time.
    let cell = ids
        .iter()
        .map(|id| 2.0 * objects[id.0 as usize].outer_radius())
        .fold(f64::MIN_POSITIVE, f64::max);
    let mut grid = PlacementGrid::new(cell);
    for b in bodies.iter() {
        grid.insert(part_boxes(&objects[b.object.0 as usize], b));
    }
    const ATTEMPTS_PER_BODY: usize = 2000;
    for n in 0..s.count as usize {
        let id = ids[n % ids.len()];
        let object = &objects[id.0 as usize];
        let mut done = false;
        for _ in 0..ATTEMPTS_PER_BODY {
            let p = Vector3::from_fn(|k, _| s.min[k] + (s.max[k] - s.min[k]) * rng.random::<f64>());
            let q = if s.random_orientation {
                random_rotation(&mut rng)
            } else {
                UnitQuaternion::identity()
            };
            let body = make_body(
                object,
                id,
                BodyKind::Dynamic,
                p,
                q,
                s.velocity.into(),
                Vector3::zeros(),
            );
            let boxes = part_boxes(object, &body);
            if grid.overlaps(&boxes) {
                continue;
            }
            grid.insert(boxes);
            bodies.push(body);
            done = true;
            break;
        }
        if !done {
            return Err((
                format!("{f}.count"),
                format!(
                    "could place only {n} of {} bodies without overlap; enlarge min/max or lower count",
                    s.count
                ),
            ));
        }
    }
    Ok(())
}

type Aabb = (Vector3<f64>, Vector3<f64>);

/// Uniform grid of placed bodies' part boxes (scatter only).
struct PlacementGrid {
    cell: f64,
    bodies: Vec<Vec<Aabb>>,
    cells: std::collections::HashMap<[i64; 3], Vec<usize>>,
    large: Vec<usize>,
}

impl PlacementGrid {
    fn new(cell: f64) -> Self {
        PlacementGrid {
            cell,
            bodies: Vec::new(),
            cells: Default::default(),
            large: Vec::new(),
        }
    }

    fn span(&self, boxes: &[Aabb]) -> ([i64; 3], [i64; 3]) {
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for (l, h) in boxes {
            lo = lo.inf(l);
            hi = hi.sup(h);
        }
        let c = |x: f64| (x / self.cell).floor().clamp(-1e15, 1e15) as i64;
        ([c(lo.x), c(lo.y), c(lo.z)], [c(hi.x), c(hi.y), c(hi.z)])
    }

    fn insert(&mut self, boxes: Vec<Aabb>) {
        let (lo, hi) = self.span(&boxes);
        let index = self.bodies.len();
        self.bodies.push(boxes);
        if (0..3).any(|k| hi[k] - lo[k] > 4) {
            self.large.push(index);
            return;
        }
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    self.cells.entry([x, y, z]).or_default().push(index);
                }
            }
        }
    }

    fn overlaps(&self, boxes: &[Aabb]) -> bool {
        let hit = |i: usize| boxes_overlap(boxes, &self.bodies[i]);
        if self.large.iter().any(|&i| hit(i)) {
            return true;
        }
        let (lo, hi) = self.span(boxes);
        for x in lo[0]..=hi[0] {
            for y in lo[1]..=hi[1] {
                for z in lo[2]..=hi[2] {
                    if let Some(list) = self.cells.get(&[x, y, z]) {
                        if list.iter().any(|&i| hit(i)) {
                            return true;
                        }
                    }
                }
            }
        }
        false
    }
}

/// Uniformly distributed rotation (Shoemake's method).
fn random_rotation(rng: &mut impl rand::Rng) -> UnitQuaternion<f64> {
    let (u1, u2, u3): (f64, f64, f64) = (rng.random(), rng.random(), rng.random());
    let tau = std::f64::consts::TAU;
    let q = nalgebra::Quaternion::new(
        (1.0 - u1).sqrt() * math::sin(tau * u2),
        (1.0 - u1).sqrt() * math::cos(tau * u2),
        u1.sqrt() * math::sin(tau * u3),
        u1.sqrt() * math::cos(tau * u3),
    );
    UnitQuaternion::from_quaternion(q)
}
