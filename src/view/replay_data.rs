//! What the page embeds: a small JSON header (names, colours, masses, the
//! camera, the energies) and one binary block (meshes and the sampled
//! trajectory), which the page decodes into typed arrays without copying.
//!
//! Binary layout, little-endian, every array starting at a multiple of 8
//! bytes, each located by the header's `{ offset, count }` (count in
//! elements): `times` f64 per sample; per sample, per body in body order,
//! `positions` f32 ×3 (centre of mass, world), `orientations` i16 ×4
//! (x, y, z, w, times 32767: three.js's order; the page renormalises),
//! `speeds` f32 (|v|); per object `vertices` f32 ×3 (body frame) and
//! `indices` u32 ×3 per triangle. f32 keeps a position to 1e-7 of its size
//! (0.1 µm at 1 m) and a quantised quaternion turns a body by at most about
//! 1e-4 rad: far below a pixel, at half the bytes of f64.

use super::mesh::triangulate;
use super::run_output::{Row, RunOutput};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use rigidsim::body::BodyKind;
use rigidsim::scene::{Scene, Settings};
use serde::Serialize;

/// Version of the layout above and of the header; the page checks it.
pub const FORMAT: u32 = 1;

#[derive(Serialize)]
pub struct Header {
    pub format: u32,
    pub scene: String,
    pub end_reason: String,
    /// `summary.json`'s `sim_time_s`: the time the run reached.
    pub sim_time_s: f64,
    pub bodies: usize,
    pub samples: usize,
    pub gravity: [f64; 3],
    /// `None`: no cut-off (−∞).
    pub fall_z: Option<f64>,
    /// The scene's `[render]` camera, if it has one; the page frames the
    /// bodies itself otherwise.
    pub camera: Option<Camera>,
    /// Where the page draws its floor grid.
    pub floor: Floor,
    pub objects: Vec<ObjectHeader>,
    /// Per body: its object's index, `dynamic` | `fixed` | `driven`, mass [kg].
    pub body_object: Vec<usize>,
    pub body_kind: Vec<&'static str>,
    pub body_mass: Vec<f64>,
    /// `[body, time]` for each body that fell, from `summary.json`.
    pub fallen: Vec<(usize, f64)>,
    /// Per sample [J]: the kinetic and potential energy of the dynamic
    /// bodies that have not fallen, as `summary.json`'s energies count them.
    pub kinetic_j: Vec<f64>,
    pub potential_j: Vec<f64>,
    /// `summary.json`'s energies at the start and the end, which the first
    /// and last sample's kinetic + potential repeat to rounding.
    pub energy_initial_j: f64,
    pub energy_final_j: f64,
    pub times: Slice,
    pub positions: Slice,
    pub orientations: Slice,
    pub speeds: Slice,
}

#[derive(Serialize)]
pub struct Camera {
    pub eye: [f64; 3],
    pub target: [f64; 3],
    pub fov_y_deg: f64,
}

/// A grid in the plane z = `z`, `half_size` each way from `center`.
#[derive(Serialize)]
pub struct Floor {
    pub z: f64,
    pub center: [f64; 2],
    pub half_size: f64,
}

#[derive(Serialize)]
pub struct ObjectHeader {
    pub name: String,
    pub color: [f32; 3],
    pub vertices: Slice,
    pub indices: Slice,
}

/// An array in the binary block: byte offset and element count.
#[derive(Clone, Copy, Serialize)]
pub struct Slice {
    pub offset: usize,
    pub count: usize,
}

pub struct ReplayData {
    pub header: Header,
    pub binary: Vec<u8>,
}

/// Appends arrays at 8-byte boundaries, so that each can be viewed in place
/// as a typed array of its element type.
struct BinaryBlock(Vec<u8>);

impl BinaryBlock {
    fn push<T: Copy, const N: usize>(
        &mut self,
        items: impl Iterator<Item = T>,
        bytes: impl Fn(T) -> [u8; N],
        per_item: usize,
    ) -> Slice {
        while self.0.len() % 8 != 0 {
            self.0.push(0);
        }
        let offset = self.0.len();
        let mut n = 0;
        for item in items {
            self.0.extend_from_slice(&bytes(item));
            n += 1;
        }
        Slice {
            offset,
            count: n * per_item,
        }
    }
}

fn quantise(q: f64) -> [u8; 2] {
    ((q.clamp(-1.0, 1.0) * 32767.0).round() as i16).to_le_bytes()
}

/// Kinetic and potential energy of body state `row` of a body of `mass` and
/// body-frame inertia `inertia`: ½ m v² + ½ ωᵀ (R I Rᵀ) ω and −m g·x, the
/// terms of `World::energy` (which holds L = R I Rᵀ ω rather than ω).
fn energies(
    row: &Row,
    mass: f64,
    inertia: &nalgebra::Matrix3<f64>,
    g: &Vector3<f64>,
) -> (f64, f64) {
    let [w, x, y, z] = row.orientation;
    let r = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)).to_rotation_matrix();
    let v = Vector3::from(row.velocity);
    let omega = Vector3::from(row.angular_velocity);
    let l = r * inertia * r.transpose() * omega;
    let kinetic = 0.5 * mass * v.norm_squared() + 0.5 * omega.dot(&l);
    (kinetic, -mass * g.dot(&Vector3::from(row.position)))
}

impl ReplayData {
    pub fn new(scene: &Scene, run: &RunOutput) -> ReplayData {
        let n = scene.bodies.len();
        let samples = run.times.len();
        let settings = &scene.settings;
        let mut block = BinaryBlock(Vec::new());
        let times = block.push(run.times.iter().copied(), f64::to_le_bytes, 1);
        let positions = block.push(
            run.rows.iter().flat_map(|r| r.position),
            |v| (v as f32).to_le_bytes(),
            1,
        );
        let orientations = block.push(
            run.rows.iter().flat_map(|r| {
                let [w, x, y, z] = r.orientation;
                [x, y, z, w]
            }),
            quantise,
            1,
        );
        let speeds = block.push(
            run.rows.iter().map(|r| Vector3::from(r.velocity).norm()),
            |v| (v as f32).to_le_bytes(),
            1,
        );
        let objects = scene
            .objects
            .iter()
            .map(|o| {
                let mesh = triangulate(o);
                ObjectHeader {
                    name: o.name.clone(),
                    color: o.color,
                    vertices: block.push(mesh.positions.into_iter(), f32::to_le_bytes, 1),
                    indices: block.push(mesh.indices.into_iter(), u32::to_le_bytes, 1),
                }
            })
            .collect();

        // A body counts until the time it fell, as `World::energy` leaves
        // fallen bodies out from the step that found them below `fall_z`.
        let mut fell_at = vec![f64::INFINITY; n];
        for &(body, time) in &run.fallen {
            fell_at[body] = fell_at[body].min(time);
        }
        let mut kinetic_j = Vec::with_capacity(samples);
        let mut potential_j = Vec::with_capacity(samples);
        for (k, &t) in run.times.iter().enumerate() {
            let (mut kinetic, mut potential) = (0.0, 0.0);
            for (i, body) in scene.bodies.iter().enumerate() {
                if !body.is_dynamic() || fell_at[i] <= t {
                    continue;
                }
                let o = &scene.objects[body.object.0 as usize];
                let (ke, pe) =
                    energies(&run.rows[k * n + i], o.mass, &o.inertia, &settings.gravity);
                kinetic += ke;
                potential += pe;
            }
            kinetic_j.push(kinetic);
            potential_j.push(potential);
        }

        let (body_object, body_kind, body_mass) = body_columns(scene);
        let header = Header {
            format: FORMAT,
            scene: scene.name.clone(),
            end_reason: run.end_reason.clone(),
            sim_time_s: run.sim_time_s,
            bodies: n,
            samples,
            gravity: settings.gravity.into(),
            fall_z: fall_z(settings),
            camera: camera(settings),
            floor: floor(scene),
            objects,
            body_object,
            body_kind,
            body_mass,
            fallen: run.fallen.clone(),
            kinetic_j,
            potential_j,
            energy_initial_j: run.energy_initial_j,
            energy_final_j: run.energy_final_j,
            times,
            positions,
            orientations,
            speeds,
        };
        ReplayData {
            header,
            binary: block.0,
        }
    }
}

/// `None`: the scene's `fall_z` is no cut-off (−∞).
pub(crate) fn fall_z(settings: &Settings) -> Option<f64> {
    settings.fall_z.is_finite().then_some(settings.fall_z)
}

/// The scene's `[render]` camera, where it names an eye and a target.
pub(crate) fn camera(settings: &Settings) -> Option<Camera> {
    settings.render.as_ref().and_then(|r| {
        Some(Camera {
            eye: r.eye?.into(),
            target: r.target?.into(),
            fov_y_deg: r.fov_y_deg,
        })
    })
}

/// A body's kind as the pages name it: `dynamic` | `fixed` | `driven`.
pub(crate) fn kind_name(kind: &BodyKind) -> &'static str {
    match kind {
        BodyKind::Dynamic => "dynamic",
        BodyKind::Fixed => "fixed",
        BodyKind::Driven { .. } => "driven",
    }
}

/// Per body: its object's index, its kind (`kind_name`) and its mass [kg].
pub(crate) fn body_columns(scene: &Scene) -> (Vec<usize>, Vec<&'static str>, Vec<f64>) {
    let bodies = &scene.bodies;
    (
        bodies.iter().map(|b| b.object.0 as usize).collect(),
        bodies.iter().map(|b| kind_name(&b.kind)).collect(),
        bodies
            .iter()
            .map(|b| scene.objects[b.object.0 as usize].mass)
            .collect(),
    )
}

/// The floor grid: on the top of the widest fixed body (the floor of the
/// bundled scenes) when there is one, else in the plane z = 0 under the
/// bodies' starting places.
pub(crate) fn floor(scene: &Scene) -> Floor {
    let world_box = |body: &rigidsim::body::Body| {
        let o = &scene.objects[body.object.0 as usize];
        let pose = body.pose();
        let mut lo = Vector3::repeat(f64::INFINITY);
        let mut hi = Vector3::repeat(f64::NEG_INFINITY);
        for part in &o.parts {
            for v in part.hull.vertices() {
                let p = pose * nalgebra::Point3::from(*v);
                lo = lo.inf(&p.coords);
                hi = hi.sup(&p.coords);
            }
        }
        (lo, hi)
    };
    let widest_fixed = scene
        .bodies
        .iter()
        .filter(|b| matches!(b.kind, BodyKind::Fixed))
        .map(world_box)
        .max_by(|a, b| {
            let area = |(lo, hi): &(Vector3<f64>, Vector3<f64>)| (hi.x - lo.x) * (hi.y - lo.y);
            area(a).total_cmp(&area(b))
        });
    let (z, lo, hi) = match widest_fixed {
        Some((lo, hi)) => (hi.z, lo, hi),
        None => {
            let mut lo = Vector3::repeat(f64::INFINITY);
            let mut hi = Vector3::repeat(f64::NEG_INFINITY);
            for b in &scene.bodies {
                let (l, h) = world_box(b);
                lo = lo.inf(&l);
                hi = hi.sup(&h);
            }
            (0.0, lo, hi)
        }
    };
    Floor {
        z,
        center: [(lo.x + hi.x) / 2.0, (lo.y + hi.y) / 2.0],
        half_size: ((hi.x - lo.x).max(hi.y - lo.y) / 2.0).max(0.5),
    }
}
