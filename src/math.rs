//! Transcendental functions that give the same bits on every host.
//!
//! `f64::sin` and its kin call the C library, and glibc picks its code path
//! for them when the program starts, by the CPU's features: on this lab's
//! machines with FMA it runs `__sin_fma`, without it another routine, and
//! the two can differ in the last bit. A group step or a scene's shapes
//! computed on two kinds of PC would then end a run on two state hashes
//! (`crowd200.toml` for 2 s did, with glibc told to skip its FMA and AVX2
//! paths: `GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA`). The `libm` crate
//! (a port of musl's, plain Rust, compiled once into the binary) gives every
//! rank the same answer whatever it runs on. Square roots need nothing of
//! this: IEEE 754 rounds them exactly.

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

pub fn sin(x: f64) -> f64 {
    libm::sin(x)
}

pub fn cos(x: f64) -> f64 {
    libm::cos(x)
}

pub fn atan2(y: f64, x: f64) -> f64 {
    libm::atan2(y, x)
}

pub fn hypot(x: f64, y: f64) -> f64 {
    libm::hypot(x, y)
}

/// The rotation by |axis_angle| radians about its direction:
/// `UnitQuaternion::from_scaled_axis` (the quaternion exponential of half
/// the vector, the identity below `f64::EPSILON`), with these sines.
pub fn rotation_from_scaled_axis(axis_angle: Vector3<f64>) -> UnitQuaternion<f64> {
    let v = axis_angle / 2.0;
    let nn = v.norm_squared();
    if nn <= f64::EPSILON * f64::EPSILON {
        return UnitQuaternion::identity();
    }
    let n = nn.sqrt();
    UnitQuaternion::new_unchecked(Quaternion::from_parts(cos(n), v * (sin(n) / n)))
}

/// The angle (radians, 0 to π) of the rotation that takes `from` to `to`:
/// `UnitQuaternion::angle_to`, with this arc tangent.
pub fn angle_between(from: &UnitQuaternion<f64>, to: &UnitQuaternion<f64>) -> f64 {
    let delta = to * from.inverse();
    let q = delta.quaternion();
    atan2(q.imag().norm(), q.scalar().abs()) * 2.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rotations_agree_with_nalgebra_to_rounding() {
        for k in 0..200 {
            let t = k as f64 * 0.37;
            let axis = Vector3::new(sin(t * 1.3), cos(t * 2.1) * 0.5, sin(t * 0.7) * 2.0)
                * (1e-9 + t * 0.05);
            let ours = rotation_from_scaled_axis(axis);
            let theirs = UnitQuaternion::from_scaled_axis(axis);
            assert!(
                (ours.coords - theirs.coords).norm() <= 4.0 * f64::EPSILON,
                "{axis:?}"
            );
            let other = rotation_from_scaled_axis(axis.yzx() * 0.3) * ours;
            let d = angle_between(&ours, &other) - ours.angle_to(&other);
            assert!(d.abs() <= 1e-14, "{d:e}");
        }
        assert_eq!(
            rotation_from_scaled_axis(Vector3::zeros()),
            UnitQuaternion::identity()
        );
    }
}
