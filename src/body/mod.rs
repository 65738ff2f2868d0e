//! Bodies: the static object definitions every rank loads, and the changing
//! state (x, q, v, L) that is all that ever travels between ranks.

pub mod mass;

use crate::polyhedron::ConvexPolyhedron;
use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// Index of a body in scene order (`[[bodies]]` in file order, then scattered bodies).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct BodyId(pub u32);

impl BodyId {
    pub fn index(self) -> usize {
        self.0 as usize
    }
}

/// Index of an object definition in `World::objects`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct ObjectId(pub u32);

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BoundingSphere {
    /// Centre in the body frame (relative to the centre of mass).
    pub center: Vector3<f64>,
    pub radius: f64,
}

/// One convex piece of a body, in the body frame (origin at the centre of mass).
#[derive(Clone, Debug)]
pub struct Part {
    pub hull: ConvexPolyhedron,
    /// Encloses the whole part; used to pick the part pairs worth a V-Clip query.
    pub sphere: BoundingSphere,
}

/// Everything about an object that never changes: loaded by every rank.
#[derive(Clone, Debug)]
pub struct ObjectDef {
    pub name: String,
    pub parts: Vec<Part>,
    pub mass: f64,
    /// Body-frame inertia about the centre of mass.
    pub inertia: Matrix3<f64>,
    pub inv_inertia: Matrix3<f64>,
    /// Rotation from the principal frame to the body frame, and the principal
    /// moments: the free-rotation integrator works in the principal frame.
    pub principal_rotation: UnitQuaternion<f64>,
    pub principal_moments: Vector3<f64>,
    pub restitution: f64,
    pub friction: f64,
    /// Broadphase spheres (body frame): one or several per part.
    pub spheres: Vec<BoundingSphere>,
    /// Offset of the shape's own origin from the centre of mass, body frame:
    /// the scene places the shape origin, the simulation tracks the centre of mass.
    pub shape_origin: Vector3<f64>,
    pub color: [f32; 3],
    pub polygon_count: usize,
    pub volume: f64,
    /// Its thinnest wall: per part, twice the smallest distance from the
    /// part's centroid to a face of the body's surface (a face glued to
    /// another part's is inside the body; `scene::min_thickness`). A body
    /// moving less than half of this per sample cannot pass through
    /// another unseen.
    pub min_thickness: f64,
}

impl ObjectDef {
    /// Radius of a sphere about the centre of mass enclosing every broadphase sphere.
    pub fn outer_radius(&self) -> f64 {
        self.spheres
            .iter()
            .map(|s| s.center.norm() + s.radius)
            .fold(0.0, f64::max)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum BodyKind {
    Dynamic,
    /// Never moves; infinite mass.
    Fixed,
    /// Moves along a prescribed velocity; infinite mass (pushes, is not pushed).
    Driven {
        velocity: Vector3<f64>,
        angular_velocity: Vector3<f64>,
    },
}

/// Activity of a body: what the step spends on it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Activity {
    Awake,
    /// Part of a resting system: not integrated, tested or solved until woken.
    Sleeping,
    /// Fell below `fall_z`: no longer simulated.
    Fallen,
}

/// The changing state of a body, world frame: centre of mass position,
/// orientation (body to world), linear velocity, angular momentum.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct BodyState {
    pub position: Vector3<f64>,
    pub orientation: UnitQuaternion<f64>,
    pub velocity: Vector3<f64>,
    pub angular_momentum: Vector3<f64>,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Body {
    pub object: ObjectId,
    pub kind: BodyKind,
    pub state: BodyState,
    pub activity: Activity,
}

impl Body {
    pub fn is_dynamic(&self) -> bool {
        matches!(self.kind, BodyKind::Dynamic)
    }

    pub fn inv_mass(&self, object: &ObjectDef) -> f64 {
        if self.is_dynamic() {
            1.0 / object.mass
        } else {
            0.0
        }
    }

    /// World inverse inertia R I⁻¹ Rᵀ (zero for fixed and driven bodies).
    pub fn inv_inertia_world(&self, object: &ObjectDef) -> Matrix3<f64> {
        if self.is_dynamic() {
            let r = self.state.orientation.to_rotation_matrix();
            r.matrix() * object.inv_inertia * r.matrix().transpose()
        } else {
            Matrix3::zeros()
        }
    }

    /// World angular velocity: ω = R I⁻¹ Rᵀ L for dynamic bodies.
    pub fn angular_velocity(&self, object: &ObjectDef) -> Vector3<f64> {
        match self.kind {
            BodyKind::Dynamic => self.inv_inertia_world(object) * self.state.angular_momentum,
            BodyKind::Fixed => Vector3::zeros(),
            BodyKind::Driven {
                angular_velocity, ..
            } => angular_velocity,
        }
    }

    /// Velocity of the material point at world position `p`.
    pub fn point_velocity(&self, object: &ObjectDef, p: &Vector3<f64>) -> Vector3<f64> {
        self.state.velocity
            + self
                .angular_velocity(object)
                .cross(&(p - self.state.position))
    }

    pub fn kinetic_energy(&self, object: &ObjectDef) -> f64 {
        if !self.is_dynamic() {
            return 0.0;
        }
        let w = self.angular_velocity(object);
        0.5 * object.mass * self.state.velocity.norm_squared()
            + 0.5 * w.dot(&self.state.angular_momentum)
    }

    pub fn pose(&self) -> nalgebra::Isometry3<f64> {
        nalgebra::Isometry3::from_parts(self.state.position.into(), self.state.orientation)
    }
}
