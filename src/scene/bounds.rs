//! Bounds on a scene's finite numbers (issue 23). A body thrown at 10³⁰⁸ m/s,
//! a cube a light year wide or a run of 10¹² steps is bad input, refused when
//! the scene is loaded with the file and the field, not a numerical failure
//! at t = 0 or a run that never ends.
//!
//! Each bound lies far beyond the scenes this simulator is for (bodies of
//! centimetres to metres, kilograms to tonnes, metres per second), and close
//! enough that within all of them every quantity the step forms keeps its
//! precision. Momenta stay below 10¹⁸ N·s, kinetic energies below 5·10²³ J,
//! moments of inertia (of order m·size²) between about 10⁻²² and 10²⁴
//! kg·m²: squared, as the contact solve's factorisation squares them, still
//! far from f64's limits (10⁻³⁰⁸ to 10³⁰⁸) and clear of its subnormals,
//! where products silently lose digits.

use super::Settings;
use crate::body::ObjectDef;
use crate::collision::narrowphase::CONTACT_TOLERANCE;
use crate::polyhedron::ConvexPolyhedron;
use nalgebra::Vector3;

/// Largest |coordinate| of a body's placement, or of a scatter box, on each
/// axis, metres. At 10⁶ m a coordinate's rounding (its ulp, 1.2·10⁻¹⁰ m) is
/// a thousandth of the 0.1 µm gap at which the time of impact places bodies
/// (`step::TOI_GAP`); at 10⁹ m it would be that whole gap.
pub const MAX_COORDINATE: f64 = 1e6;

/// Smallest size of an object (the longest side of the box around it),
/// metres: a body smaller than the contact tolerance would count as
/// touching whatever comes within its own size of it.
pub const MIN_SIZE: f64 = CONTACT_TOLERANCE;
/// Largest size of an object, metres: the size of the region bodies may be
/// placed in.
pub const MAX_SIZE: f64 = MAX_COORDINATE;

/// Masses, kg: from a nanogram to a billion tonnes.
pub const MIN_MASS: f64 = 1e-12;
pub const MAX_MASS: f64 = 1e12;

/// Most steps a run may take: its duration (`max_duration` for an
/// `until_rest` scene without one) over `dt`. A lone body's step takes
/// about 10 µs, so 10⁹ steps are hours of wall time even for it, and years
/// for a pile of bodies: a longer run is a typo, not a plan.
pub const MAX_STEPS: u64 = 1_000_000_000;

/// The speed no body may reach, m/s: a step that produces one stops the run
/// (`check_states`), and a scene that starts with one is refused
/// (`scene::load`). The fastest bodies the tests throw move at a thousandth
/// of it (1000 m/s at a 1 cm wall); at 10⁶ m/s a 10 ms step carries a body
/// 10 km.
pub const MAX_SPEED: f64 = 1e6;

/// Largest acceleration gravity or a force may give a body, m/s² (10⁸ g):
/// even at it a body takes a millisecond to reach the speed bound, so no
/// single step can carry it far past that bound.
pub const MAX_ACCELERATION: f64 = 1e9;

type Checked = Result<(), (String, String)>;

/// A linear acceleration (gravity, or a force over the mass it pushes) of
/// at most `MAX_ACCELERATION`; `what` says what gives it.
pub fn check_acceleration(a: f64, field: &str, what: &str) -> Checked {
    if a > MAX_ACCELERATION {
        return Err((
            field.into(),
            format!("{what} {a:.3e} m/s², more than the {MAX_ACCELERATION:e} m/s² bound"),
        ));
    }
    Ok(())
}

/// |v| of a vector given as three numbers (as the scene file has them).
pub fn magnitude(v: &[f64; 3]) -> f64 {
    norm(v)
}

/// Every coordinate within ±`MAX_COORDINATE`.
pub fn check_position(p: &[f64; 3], field: &str) -> Checked {
    match p.iter().find(|x| x.abs() > MAX_COORDINATE) {
        Some(x) => Err((
            field.into(),
            format!(
                "must lie within ±{MAX_COORDINATE:e} m of the origin on each axis (got {x:e} m)"
            ),
        )),
        None => Ok(()),
    }
}

/// A speed of at most `MAX_SPEED`, the bound the step enforces.
pub fn check_speed(v: &[f64; 3], field: &str) -> Checked {
    let speed = norm(v);
    if speed > MAX_SPEED {
        return Err((
            field.into(),
            format!("is {speed:.3e} m/s, faster than the {MAX_SPEED:e} m/s bound"),
        ));
    }
    Ok(())
}

/// An angular velocity at which no point of the body (`reach` from its
/// centre of mass at most) moves faster than `MAX_SPEED` about the centre.
pub fn check_spin(w: &[f64; 3], reach: f64, field: &str) -> Checked {
    let spin = norm(w);
    if spin * reach > MAX_SPEED {
        return Err((
            field.into(),
            format!(
                "is {spin:.3e} rad/s: the body's surface, up to {reach:.3e} m from its centre of \
                 mass, would move at {:.3e} m/s, faster than the {MAX_SPEED:e} m/s bound",
                spin * reach
            ),
        ));
    }
    Ok(())
}

/// An object's size (`extent`) between `MIN_SIZE` and `MAX_SIZE`.
pub fn check_size(size: f64, field: &str) -> Checked {
    if !(MIN_SIZE..=MAX_SIZE).contains(&size) {
        return Err((
            field.into(),
            format!(
                "is {size:.3e} m across; an object's size must be between {MIN_SIZE:e} m \
                 (the contact tolerance) and {MAX_SIZE:e} m"
            ),
        ));
    }
    Ok(())
}

/// A mass between `MIN_MASS` and `MAX_MASS`; `what` says where it came from
/// ("is", "gives a mass of").
pub fn check_mass(mass: f64, field: &str, what: &str) -> Checked {
    if !(MIN_MASS..=MAX_MASS).contains(&mass) {
        return Err((
            field.into(),
            format!("{what} {mass:e} kg; a mass must be between {MIN_MASS:e} and {MAX_MASS:e} kg"),
        ));
    }
    Ok(())
}

/// At most `MAX_STEPS` steps to the end time; the message says how many.
pub fn check_step_count(settings: &Settings) -> Result<(), String> {
    let steps = settings.total_steps();
    if steps > MAX_STEPS {
        return Err(format!(
            "{} s at dt = {} s needs {:.3e} steps, more than the limit of {MAX_STEPS:e}",
            readable(settings.end_time()),
            readable(settings.dt),
            settings.end_time() / settings.dt
        ));
    }
    Ok(())
}

/// The longest side of the axis-aligned box around the parts' vertices.
pub fn extent<'a>(parts: impl Iterator<Item = &'a ConvexPolyhedron>) -> f64 {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for v in parts.flat_map(|p| p.vertices().iter()) {
        lo = lo.inf(v);
        hi = hi.sup(v);
    }
    (hi - lo).max()
}

/// The largest distance of a vertex of `object` from its centre of mass.
pub fn reach(object: &ObjectDef) -> f64 {
    reach_from(object.parts.iter().map(|p| &p.hull), &Vector3::zeros())
}

/// The largest distance of a vertex of `parts` from `centre`.
pub fn reach_from<'a>(
    parts: impl Iterator<Item = &'a ConvexPolyhedron>,
    centre: &Vector3<f64>,
) -> f64 {
    parts
        .flat_map(|p| p.vertices().iter())
        .map(|v| (v - centre).norm())
        .fold(0.0, f64::max)
}

/// `x` as written in a scene: plain decimals for everyday magnitudes,
/// scientific notation for the rest (1e300 is not 301 digits).
pub fn readable(x: f64) -> String {
    if x == 0.0 || (1e-4..1e9).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}

/// |v|, scaled so that 1e308 does not square to infinity.
fn norm(v: &[f64; 3]) -> f64 {
    let scale = v.iter().fold(0.0, |m: f64, x| m.max(x.abs()));
    if scale == 0.0 {
        return 0.0;
    }
    scale * (Vector3::from(*v) / scale).norm()
}
