//! The scene file as written: TOML, SI units, z up, quaternions `[w, x, y, z]`.
//!
//! These structs mirror the file one to one (serde does the parsing); the
//! meaning checks (positive masses, finite numbers, convex parts) happen in
//! `scene::load`, which turns a `SceneFile` into a `World`. Field names here are
//! a contract with the tools that read and write scenes: keep them.

use serde::Deserialize;
use std::collections::BTreeMap;

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default)]
    pub world: WorldSection,
    #[serde(default)]
    pub output: OutputSection,
    pub render: Option<RenderSection>,
    #[serde(default)]
    pub objects: BTreeMap<String, ObjectSection>,
    #[serde(default)]
    pub bodies: Vec<BodySection>,
    #[serde(default)]
    pub scatter: Vec<ScatterSection>,
    #[serde(default)]
    pub forces: Vec<ForceSection>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSection {
    #[serde(default = "default_gravity")]
    pub gravity: [f64; 3],
    #[serde(default = "default_dt")]
    pub dt: f64,
    pub duration: Option<f64>,
    #[serde(default)]
    pub until_rest: bool,
    /// Safety cap for `until_rest` scenes that never settle (simulated s).
    #[serde(default = "default_max_duration")]
    pub max_duration: f64,
    /// Height below which a dynamic body stops being simulated. When absent,
    /// 1 m below the lowest point of the fixed bodies, or no cut-off in a
    /// scene without fixed bodies (`scene::default_fall_z`).
    #[serde(default)]
    pub fall_z: Option<f64>,
    #[serde(default = "default_frame_interval")]
    pub frame_interval: f64,
    #[serde(default)]
    pub restitution_rule: CombineRule,
    #[serde(default)]
    pub friction_rule: CombineRule,
    /// Approaches inside a pile up to this speed (m/s) are solved at the
    /// step by speculative contacts; 0 makes every impact an exact event
    /// (`Settings::speculative_speed`).
    #[serde(default)]
    pub speculative_speed: Option<f64>,
    /// Moving bodies in the two contact islands of an approach from which
    /// it is inside a pile (`Settings::pile_bodies`).
    #[serde(default)]
    pub pile_bodies: Option<u32>,
    /// Blocks a large island is cut into so that ranks can share its
    /// sweeps (`Settings::island_blocks`); 1: swept whole.
    #[serde(default)]
    pub island_blocks: Option<u32>,
}

impl Default for WorldSection {
    fn default() -> Self {
        WorldSection {
            gravity: default_gravity(),
            dt: default_dt(),
            duration: None,
            until_rest: false,
            max_duration: default_max_duration(),
            fall_z: None,
            frame_interval: default_frame_interval(),
            restitution_rule: CombineRule::Min,
            friction_rule: CombineRule::Min,
            speculative_speed: None,
            pile_bodies: None,
            island_blocks: None,
        }
    }
}

fn default_gravity() -> [f64; 3] {
    [0.0, 0.0, -9.81]
}
fn default_dt() -> f64 {
    0.01
}
fn default_max_duration() -> f64 {
    600.0
}
fn default_frame_interval() -> f64 {
    1.0 / 60.0
}

/// How the restitution (or friction) of two objects combine at a contact.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CombineRule {
    #[default]
    Min,
    Max,
    Mean,
    Product,
}

impl CombineRule {
    pub fn combine(self, a: f64, b: f64) -> f64 {
        match self {
            CombineRule::Min => a.min(b),
            CombineRule::Max => a.max(b),
            CombineRule::Mean => 0.5 * (a + b),
            CombineRule::Product => a * b,
        }
    }
}

#[derive(Debug, Clone, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OutputSection {
    /// Trajectory sampling interval in simulated seconds; every step when absent.
    pub sample_every: Option<f64>,
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSection {
    #[serde(default = "default_render_size")]
    pub size: [u32; 2],
    pub eye: Option<[f64; 3]>,
    pub target: Option<[f64; 3]>,
    /// Simulated seconds between rendered frames; the frame interval when absent.
    pub every: Option<f64>,
    #[serde(default = "default_fov")]
    pub fov_y_deg: f64,
    /// Frames per second of `video.mp4`; real time (1 / every) when absent.
    pub video_fps: Option<f64>,
}

fn default_render_size() -> [u32; 2] {
    [640, 360]
}
fn default_fov() -> f64 {
    45.0
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObjectSection {
    pub shape: ShapeSpec,
    pub mass: Option<f64>,
    pub density: Option<f64>,
    #[serde(default = "default_restitution")]
    pub restitution: f64,
    #[serde(default = "default_friction")]
    pub friction: f64,
    /// Body-frame inertia about the centre of mass, kg·m².
    pub inertia: Option<[[f64; 3]; 3]>,
    /// Bounding spheres, centres given relative to the centre of mass.
    pub spheres: Option<Vec<SphereSpec>>,
    pub color: Option<[f32; 3]>,
}

fn default_restitution() -> f64 {
    0.5
}
fn default_friction() -> f64 {
    0.5
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SphereSpec {
    pub center: [f64; 3],
    pub radius: f64,
}

/// Every shape is a union of convex polyhedra.
#[derive(Debug, Clone, Deserialize)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum ShapeSpec {
    Box {
        half_extents: [f64; 3],
    },
    Sphere {
        radius: f64,
        #[serde(default = "default_subdivisions")]
        subdivisions: u32,
    },
    Cylinder {
        radius: f64,
        half_height: f64,
        #[serde(default = "default_sides")]
        sides: u32,
    },
    Nut {
        #[serde(default = "default_nut_across_flats")]
        across_flats: f64,
        #[serde(default = "default_nut_thickness")]
        thickness: f64,
        #[serde(default = "default_nut_hole_radius")]
        hole_radius: f64,
        #[serde(default = "default_nut_sides")]
        sides: u32,
    },
    Bolt {
        #[serde(default = "default_bolt_head_across_flats")]
        head_across_flats: f64,
        #[serde(default = "default_bolt_head_height")]
        head_height: f64,
        #[serde(default = "default_bolt_shaft_radius")]
        shaft_radius: f64,
        #[serde(default = "default_bolt_shaft_length")]
        shaft_length: f64,
        #[serde(default = "default_sides")]
        sides: u32,
    },
    Mesh {
        path: String,
        #[serde(default)]
        hull: bool,
    },
    Compound(Vec<CompoundPart>),
}

fn default_subdivisions() -> u32 {
    2
}
fn default_sides() -> u32 {
    40
}
fn default_nut_across_flats() -> f64 {
    0.04
}
fn default_nut_thickness() -> f64 {
    0.016
}
fn default_nut_hole_radius() -> f64 {
    0.011
}
fn default_nut_sides() -> u32 {
    32
}
fn default_bolt_head_across_flats() -> f64 {
    0.03
}
fn default_bolt_head_height() -> f64 {
    0.012
}
fn default_bolt_shaft_radius() -> f64 {
    0.009
}
fn default_bolt_shaft_length() -> f64 {
    0.04
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CompoundPart {
    pub shape: ShapeSpec,
    #[serde(default)]
    pub position: [f64; 3],
    #[serde(default = "identity_quaternion")]
    pub orientation: [f64; 4],
}

pub fn identity_quaternion() -> [f64; 4] {
    [1.0, 0.0, 0.0, 0.0]
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BodySection {
    pub object: String,
    #[serde(default)]
    pub position: [f64; 3],
    #[serde(default = "identity_quaternion")]
    pub orientation: [f64; 4],
    #[serde(default)]
    pub velocity: [f64; 3],
    #[serde(default)]
    pub angular_velocity: [f64; 3],
    #[serde(default)]
    pub fixed: bool,
    pub driven: Option<DrivenSpec>,
}

/// A prescribed motion (a trainee's tool): pushes others, is never pushed back.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DrivenSpec {
    #[serde(default)]
    pub velocity: [f64; 3],
    #[serde(default)]
    pub angular_velocity: [f64; 3],
}

#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ScatterSection {
    pub objects: Vec<String>,
    pub count: u64,
    pub min: [f64; 3],
    pub max: [f64; 3],
    #[serde(default = "default_seed")]
    pub seed: u64,
    #[serde(default = "default_true")]
    pub random_orientation: bool,
    #[serde(default)]
    pub velocity: [f64; 3],
}

fn default_seed() -> u64 {
    1
}
fn default_true() -> bool {
    true
}

/// An external force on one body over a window of simulated time.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceSection {
    pub body: u64,
    pub force: [f64; 3],
    #[serde(default)]
    pub torque: [f64; 3],
    #[serde(default)]
    pub start: f64,
    pub end: Option<f64>,
}
