//! The hand: a spring-damper between the point where a person holds a body
//! and the point under their cursor.
//!
//! For a grab point p (fixed to the body) moving at v_p = v + ω × (p − c),
//! and the hand's target x, the force on the body at p is
//!
//! ```text
//! F = m (ω_h² (x − p) − 2 ω_h v_p),   |F| ≤ m · HAND_MAX_ACCELERATION
//! τ = (p − c) × F
//! ```
//!
//! with m the body's mass: a point mass m on this spring is critically
//! damped (ζ = 1) at natural frequency ω_h, so a 30 g nut and a 10 kg block
//! follow a hand alike. The force is constant over each step (an external
//! force of the step, like a scene's `[[forces]]`), which an explicit
//! spring carries stably only while ω_h·dt stays small: ω_h is
//! `HAND_FREQUENCY`, lowered to `HAND_STEP_LIMIT / dt` on coarse steps.
//! Gravity still acts, so a body held still hangs g / ω_h² below the hand
//! (2.5 cm at 20 rad/s).

use nalgebra::{UnitQuaternion, Vector3};

/// The hand's natural frequency, rad/s (about 3 Hz): a body reaches a
/// moved target in about 1 / ω_h = 0.05 s, quick as a hand, slow enough for
/// the step to carry.
pub const HAND_FREQUENCY: f64 = 20.0;

/// The largest ω_h·dt the hand uses: an explicit spring-damper applied once a
/// step stays well damped up to about 0.5.
pub const HAND_STEP_LIMIT: f64 = 0.5;

/// The hand's force is capped at this acceleration of the body it holds,
/// m/s² (5 g): enough to lift anything against gravity, not enough to fling
/// it through the world when the cursor jumps across the screen.
pub const HAND_MAX_ACCELERATION: f64 = 50.0;

/// ω_h for a step of `dt` seconds.
pub fn frequency(dt: f64) -> f64 {
    HAND_FREQUENCY.min(HAND_STEP_LIMIT / dt)
}

/// What the hand needs of the body it holds, now.
pub struct Held {
    pub mass: f64,
    pub centre: Vector3<f64>,
    pub orientation: UnitQuaternion<f64>,
    pub velocity: Vector3<f64>,
    pub angular_velocity: Vector3<f64>,
}

/// The force and torque (about the centre of mass) on a body held at
/// `local` (body frame, from the centre of mass) by a hand at `target`.
pub fn spring_force(
    held: &Held,
    local: &Vector3<f64>,
    target: &Vector3<f64>,
    dt: f64,
) -> (Vector3<f64>, Vector3<f64>) {
    let w = frequency(dt);
    let arm = held.orientation * local;
    let p = held.centre + arm;
    let v_p = held.velocity + held.angular_velocity.cross(&arm);
    let mut f = held.mass * (w * w * (target - p) - 2.0 * w * v_p);
    let cap = held.mass * HAND_MAX_ACCELERATION;
    if f.norm() > cap {
        f *= cap / f.norm();
    }
    (f, arm.cross(&f))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point mass on the hand, stepped as the simulator steps it (the
    /// force constant over a step), settles on the target without
    /// overshooting by more than a hair, at any mass.
    #[test]
    fn a_held_point_mass_settles_critically_damped() {
        for mass in [0.03, 10.0] {
            let dt = 0.001;
            let mut x = Vector3::zeros();
            let mut v = Vector3::zeros();
            let target = Vector3::new(0.0, 0.0, 0.5);
            let mut highest: f64 = 0.0;
            for _ in 0..2000 {
                let held = Held {
                    mass,
                    centre: x,
                    orientation: UnitQuaternion::identity(),
                    velocity: v,
                    angular_velocity: Vector3::zeros(),
                };
                let (f, tau) = spring_force(&held, &Vector3::zeros(), &target, dt);
                assert_eq!(tau, Vector3::zeros());
                v += f / mass * dt;
                x += v * dt;
                highest = highest.max(x.z);
            }
            assert!((x.z - 0.5).abs() < 1e-6, "mass {mass}: ends at {}", x.z);
            assert!(highest < 0.5 + 1e-3, "mass {mass}: overshoots to {highest}");
        }
    }

    #[test]
    fn the_force_is_capped_and_the_frequency_fits_the_step() {
        let held = Held {
            mass: 2.0,
            centre: Vector3::zeros(),
            orientation: UnitQuaternion::identity(),
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
        };
        let (f, _) = spring_force(
            &held,
            &Vector3::zeros(),
            &Vector3::new(100.0, 0.0, 0.0),
            0.01,
        );
        assert!((f.norm() - 2.0 * HAND_MAX_ACCELERATION).abs() < 1e-9);
        assert_eq!(frequency(0.001), HAND_FREQUENCY);
        assert_eq!(frequency(0.1), 5.0);
    }
}
