//! Integration of one body's state (x, q, v, L) over a step with constant
//! force and torque (SPEC 2.5).
//!
//! Translation is exact for constant force: x(h) = x + v h + ½ a h², so free
//! flight follows the parabola to rounding.
//!
//! Rotation uses a kick–drift–kick splitting: half the torque impulse, then the
//! torque-free ("drift") flow of the rigid body with constant world angular
//! momentum L, then the other half. The free flow itself is split by energy:
//! H = Π₁²/2I₁ + Π₂²/2I₂ + Π₃²/2I₃ (Π = body angular momentum in principal
//! axes). Each piece is solved exactly: a rotation about principal axis i by
//! θ = t Πᵢ/Iᵢ (Dullweber, Leimkuhler & McLachlan 1997). Every sub-flow is a
//! rotation, so |L| and the quaternion norm are kept to rounding; the symmetric
//! (Strang) composition is second order and Yoshida's triple-jump composition
//! of it is **fourth order**, so the energy error is O((h ω)⁴) and does not
//! drift (the scheme is symplectic). No explicit gyroscopic term adds energy.

use crate::body::{BodyKind, BodyState, ObjectDef};
use crate::math;
use nalgebra::{UnitQuaternion, Vector3};

/// Yoshida's fourth-order triple-jump weights: w₁ = 1/(2 − 2^⅓), w₀ = 1 − 2w₁.
const YOSHIDA_W1: f64 = 1.351_207_191_959_657_8;
const YOSHIDA_W0: f64 = -1.702_414_383_919_315_3;

/// Advances a state by `h` under constant world force `force` (gravity
/// included) and torque `torque`.
pub fn integrate(
    state: &BodyState,
    object: &ObjectDef,
    kind: BodyKind,
    force: &Vector3<f64>,
    torque: &Vector3<f64>,
    h: f64,
) -> BodyState {
    match kind {
        BodyKind::Fixed => *state,
        BodyKind::Driven {
            velocity,
            angular_velocity,
        } => BodyState {
            position: state.position + velocity * h,
            orientation: math::rotation_from_scaled_axis(angular_velocity * h) * state.orientation,
            velocity,
            angular_momentum: Vector3::zeros(),
        },
        BodyKind::Dynamic => {
            let a = force / object.mass;
            let position = state.position + state.velocity * h + 0.5 * a * (h * h);
            let velocity = state.velocity + a * h;
            let l_mid = state.angular_momentum + torque * (0.5 * h);
            let orientation = free_rotation(state.orientation, &l_mid, object, h);
            BodyState {
                position,
                orientation,
                velocity,
                angular_momentum: l_mid + torque * (0.5 * h),
            }
        }
    }
}

/// Torque-free rotation over `h` with constant world angular momentum `l`.
pub fn free_rotation(
    q: UnitQuaternion<f64>,
    l: &Vector3<f64>,
    object: &ObjectDef,
    h: f64,
) -> UnitQuaternion<f64> {
    if l.norm_squared() == 0.0 || h == 0.0 {
        return q;
    }
    // Principal frame to world.
    let mut rp = q * object.principal_rotation;
    let mut pi = rp.inverse() * l;
    let moments = object.principal_moments;
    for w in [YOSHIDA_W1, YOSHIDA_W0, YOSHIDA_W1] {
        strang(&mut rp, &mut pi, &moments, w * h);
    }
    let out = rp * object.principal_rotation.inverse();
    // Renormalise against rounding only (each sub-flow is an exact rotation).
    UnitQuaternion::new_normalize(out.into_inner())
}

/// Symmetric composition φ₁(h/2) φ₂(h/2) φ₃(h) φ₂(h/2) φ₁(h/2).
fn strang(rp: &mut UnitQuaternion<f64>, pi: &mut Vector3<f64>, moments: &Vector3<f64>, h: f64) {
    axis_flow(rp, pi, moments, 0, 0.5 * h);
    axis_flow(rp, pi, moments, 1, 0.5 * h);
    axis_flow(rp, pi, moments, 2, h);
    axis_flow(rp, pi, moments, 1, 0.5 * h);
    axis_flow(rp, pi, moments, 0, 0.5 * h);
}

/// Exact flow of Hᵢ = Πᵢ²/2Iᵢ for time t: the body spins about principal axis
/// i at rate Πᵢ/Iᵢ, so R ← R·Rot(eᵢ, θ) and Π ← Rot(eᵢ, −θ)·Π; L = RΠ is unchanged.
fn axis_flow(
    rp: &mut UnitQuaternion<f64>,
    pi: &mut Vector3<f64>,
    moments: &Vector3<f64>,
    i: usize,
    t: f64,
) {
    let theta = t * pi[i] / moments[i];
    let mut axis = Vector3::zeros();
    axis[i] = theta;
    let rot = math::rotation_from_scaled_axis(axis);
    *rp *= rot;
    *pi = rot.inverse() * *pi;
}
