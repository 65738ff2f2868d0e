//! Scene loading (issue 2): mass properties against closed forms, the
//! procedural nut and bolt, mesh files (OBJ, STL, DXF), the one-line error of
//! every bad input, and the bundled scenes.
//!
//! Tolerances: closed forms are met to 1e-12 relative (f64 rounding of sums
//! over at most a few thousand triangles stays near 1e-14); mesh files stored
//! in single precision use coordinates that f32 represents exactly, so they
//! are held to the same bound.

use nalgebra::{Matrix3, UnitQuaternion, Vector3};
use rigidsim::body::ObjectDef;
use rigidsim::scene::{self, Scene, SceneError};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const WORLD: &str = "[world]\nduration = 1.0\n";

// ---------------------------------------------------------------- helpers

/// Writes `text` as `scene.toml` in a fresh temporary folder and loads it.
/// Returns the path the error messages must name.
fn load_text(text: &str) -> (PathBuf, Result<Scene, SceneError>) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.toml");
    std::fs::write(&path, text).unwrap();
    let result = scene::load(&path);
    (path, result)
}

fn load_ok(text: &str) -> Scene {
    load_text(text)
        .1
        .unwrap_or_else(|e| panic!("scene should load, got: {e}\n--- scene ---\n{text}"))
}

/// A scene with one object `thing` (the TOML lines given) and one body of it.
fn one_object(object: &str) -> String {
    format!("{WORLD}\n[objects.thing]\n{object}\n\n[[bodies]]\nobject = \"thing\"\n")
}

fn object<'a>(scene: &'a Scene, name: &str) -> &'a ObjectDef {
    scene
        .objects
        .iter()
        .find(|o| o.name == name)
        .unwrap_or_else(|| panic!("no object '{name}'"))
}

fn thing(text: &str) -> ObjectDef {
    object(&load_ok(&one_object(text)), "thing").clone()
}

/// Absolute path of a fixture in tests/data, for `mesh = { path = ... }`.
fn data(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
        .display()
        .to_string()
}

/// Loads a scene that must be refused; checks that the error is one line
/// that starts with the file and names exactly `field`.
fn expect_error(text: &str, field: &str) -> SceneError {
    let (path, result) = load_text(text);
    let err = match result {
        Ok(_) => panic!("scene should be refused at {field}\n--- scene ---\n{text}"),
        Err(e) => e,
    };
    let line = err.to_string();
    assert!(!line.contains('\n'), "error is not one line: {line:?}");
    assert_eq!(err.file, path, "error names the wrong file: {line}");
    assert!(
        line.starts_with(&format!("{}: ", path.display())),
        "error does not start with the file: {line}"
    );
    assert_eq!(err.field, field, "wrong field in: {line}");
    if !field.is_empty() {
        assert!(
            line.contains(&format!(": {field}: ")),
            "field not shown: {line}"
        );
    }
    err
}

fn assert_mentions(err: &SceneError, words: &[&str]) {
    for w in words {
        assert!(
            err.message.contains(w),
            "message should mention {w:?}: {err}"
        );
    }
}

fn assert_close(actual: f64, expected: f64, rel: f64, what: &str) {
    let err = (actual - expected).abs();
    assert!(
        err <= rel * expected.abs(),
        "{what}: got {actual:e}, expected {expected:e} (relative error {:e}, allowed {rel:e})",
        err / expected.abs()
    );
}

/// Element-wise, relative to the largest element of `expected`.
fn assert_matrix_close(actual: &Matrix3<f64>, expected: &Matrix3<f64>, rel: f64, what: &str) {
    let scale = expected.abs().max();
    let err = (actual - expected).abs().max();
    assert!(
        err <= rel * scale,
        "{what}: got {actual}expected {expected}(largest difference {err:e}, allowed {:e})",
        rel * scale
    );
}

fn assert_vector_close(actual: &Vector3<f64>, expected: &Vector3<f64>, abs: f64, what: &str) {
    let err = (actual - expected).abs().max();
    assert!(
        err <= abs,
        "{what}: got {actual:?}, expected {expected:?} (difference {err:e}, allowed {abs:e})"
    );
}

/// Solid box of half extents h about its centre: I_xx = m (b² + c²) / 3, ...
fn box_inertia(mass: f64, h: [f64; 3]) -> Matrix3<f64> {
    let [a, b, c] = h.map(|x| x * x);
    Matrix3::from_diagonal(&Vector3::new(b + c, a + c, a + b)) * (mass / 3.0)
}

/// Parallel-axis term of a mass m whose centre sits at offset d.
fn parallel_axis(mass: f64, d: Vector3<f64>) -> Matrix3<f64> {
    (Matrix3::identity() * d.norm_squared() - d * d.transpose()) * mass
}

/// Volume of an object's parts computed here, independently of the loader:
/// the signed tetrahedra (0, a, b, c) over every outward triangle.
fn summed_tetrahedra(o: &ObjectDef) -> f64 {
    o.parts
        .iter()
        .map(|p| {
            let v = p.hull.vertices();
            p.hull
                .triangles()
                .iter()
                .map(|t| v[t[0]].dot(&v[t[1]].cross(&v[t[2]])) / 6.0)
                .sum::<f64>()
        })
        .sum()
}

fn triangle_count(o: &ObjectDef) -> usize {
    o.parts.iter().map(|p| p.hull.triangles().len()).sum()
}

/// Extent of an object along each axis of its body frame.
fn extent(o: &ObjectDef) -> Vector3<f64> {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for v in o.parts.iter().flat_map(|p| p.hull.vertices()) {
        lo = lo.inf(v);
        hi = hi.sup(v);
    }
    hi - lo
}

/// Area of the regular n-gon with circumradius r: ½ n r² sin(2π/n).
fn polygon_area(n: u32, r: f64) -> f64 {
    0.5 * n as f64 * r * r * (2.0 * PI / n as f64).sin()
}

/// Area of the regular hexagon with the given distance across flats.
fn hexagon_area(across_flats: f64) -> f64 {
    3f64.sqrt() / 2.0 * across_flats * across_flats
}

fn assert_matches_box(o: &ObjectDef, mass: f64, h: [f64; 3], what: &str) {
    assert_close(
        o.volume,
        8.0 * h[0] * h[1] * h[2],
        1e-12,
        &format!("{what} volume"),
    );
    assert_close(o.mass, mass, 1e-12, &format!("{what} mass"));
    assert_matrix_close(
        &o.inertia,
        &box_inertia(mass, h),
        1e-12,
        &format!("{what} inertia"),
    );
}

// ------------------------------------------------ mass properties, closed forms

#[test]
fn box_mass_properties_match_closed_form() {
    let h = [0.1, 0.2, 0.3];
    let o = thing("shape = { box = { half_extents = [0.1, 0.2, 0.3] } }\nmass = 2.5");
    assert_matches_box(&o, 2.5, h, "box");
    assert_close(o.volume, 0.048, 1e-12, "box volume 8abc");
    assert_vector_close(
        &o.shape_origin,
        &Vector3::zeros(),
        1e-15,
        "box centre of mass",
    );
    assert_eq!(o.parts.len(), 1);
    assert_eq!(merged_faces(&o), 6, "a box has six faces");
    // Principal moments ascend: the longest axis (z) has the smallest moment.
    let expected = Vector3::new(2.5 * 0.05 / 3.0, 2.5 * 0.1 / 3.0, 2.5 * 0.13 / 3.0);
    assert_vector_close(
        &o.principal_moments,
        &expected,
        1e-14,
        "box principal moments",
    );
    assert_matrix_close(
        &(o.inertia * o.inv_inertia),
        &Matrix3::identity(),
        1e-12,
        "inverse inertia",
    );
}

#[test]
fn cylinder_prism_volume_and_inertia_match_regular_polygon_closed_form() {
    // For the regular n-gon of circumradius r, the fan of n triangles
    // (0, p_i, p_i+1) gives ∫ |x|² dA = A r² (2 + cos(2π/n)) / 6, split
    // equally between x and y by symmetry (n ≥ 3). The prism of height 2h adds
    // the slab term h²/3 to the two transverse moments.
    let (r, h, m) = (0.25, 0.4, 3.0);
    for n in [3u32, 4, 5, 7, 16, 64, 512] {
        let o = thing(&format!(
            "shape = {{ cylinder = {{ radius = {r}, half_height = {h}, sides = {n} }} }}\nmass = {m}"
        ));
        let what = format!("cylinder sides = {n}");
        assert_close(
            o.volume,
            polygon_area(n, r) * 2.0 * h,
            1e-12,
            &format!("{what} volume"),
        );
        let polar = r * r * (2.0 + (2.0 * PI / n as f64).cos()) / 6.0;
        let expected = Matrix3::from_diagonal(&Vector3::new(
            m * (polar / 2.0 + h * h / 3.0),
            m * (polar / 2.0 + h * h / 3.0),
            m * polar,
        ));
        assert_matrix_close(&o.inertia, &expected, 1e-12, &format!("{what} inertia"));
        assert_vector_close(&o.shape_origin, &Vector3::zeros(), 1e-15, &what);
        assert_eq!(
            merged_faces(&o) as u32,
            n + 2,
            "{what}: n sides and two caps"
        );
    }
}

#[test]
fn icosahedron_volume_matches_closed_form() {
    // Edge a of the icosahedron inscribed in radius r: r = a sin(2π/5).
    let r: f64 = 0.3;
    let a = r / (2.0 * PI / 5.0).sin();
    let expected = 5.0 / 12.0 * (3.0 + 5f64.sqrt()) * a.powi(3);
    let o = thing(&format!(
        "shape = {{ sphere = {{ radius = {r}, subdivisions = 0 }} }}\nmass = 1.0"
    ));
    assert_close(o.volume, expected, 1e-12, "icosahedron volume");
    assert_eq!(merged_faces(&o), 20);
}

/// Geodesic spheres of radius r for subdivisions 0..=5 (the allowed range).
fn geodesic_spheres(r: f64) -> Vec<ObjectDef> {
    let mut text = WORLD.to_string();
    for s in 0..=5 {
        text += &format!(
            "[objects.s{s}]\nshape = {{ sphere = {{ radius = {r}, subdivisions = {s} }} }}\nmass = 2.0\n"
        );
    }
    let scene = load_ok(&text);
    (0..=5)
        .map(|s| object(&scene, &format!("s{s}")).clone())
        .collect()
}

#[test]
fn geodesic_sphere_volume_is_the_sum_of_its_tetrahedra_and_converges_from_below() {
    let r: f64 = 0.3;
    let ball = 4.0 / 3.0 * PI * r.powi(3);
    let spheres = geodesic_spheres(r);
    let mut last_deficit = f64::INFINITY;
    for (s, o) in spheres.iter().enumerate() {
        assert_close(
            summed_tetrahedra(o),
            o.volume,
            1e-12,
            &format!("s = {s}: tetrahedra"),
        );
        assert_eq!(
            merged_faces(o),
            20 * 4usize.pow(s as u32),
            "s = {s}: face count"
        );
        let deficit = (ball - o.volume) / ball;
        assert!(
            deficit > 0.0,
            "s = {s}: inscribed polyhedron exceeds the ball ({deficit:e})"
        );
        // Halving the edges quarters the deficit (second order): the ratio
        // falls from 0.32 (icosahedron to 80 faces) towards 1/4.
        if s > 0 {
            let ratio = deficit / last_deficit;
            assert!(
                (0.25..0.33).contains(&ratio),
                "s = {s}: deficit {deficit:e} is {ratio} of the previous one"
            );
        }
        last_deficit = deficit;
    }
    assert!(
        last_deficit < 6e-4,
        "s = 5 still misses {last_deficit:e} of the ball"
    );
}

#[test]
fn geodesic_sphere_inertia_is_isotropic_and_near_two_fifths_m_r_squared() {
    // For a body star-shaped about its centre with radial function ρ between
    // the inradius r_in and r, I/m = (2/5) ∫ρ⁵ / ∫ρ³ lies in [(2/5) r_in²,
    // (2/5) r²]; icosahedral symmetry makes the tensor a multiple of 1.
    let (r, m) = (0.3, 2.0);
    let mut last_gap = f64::INFINITY;
    for (s, o) in geodesic_spheres(r).iter().enumerate() {
        let what = format!("s = {s}");
        let moment = o.inertia[(0, 0)];
        let iso = Matrix3::identity() * moment;
        assert_matrix_close(
            &o.inertia,
            &iso,
            1e-12,
            &format!("{what}: isotropic inertia"),
        );
        let hull = &o.parts[0].hull;
        let r_in = hull
            .faces()
            .iter()
            .map(|f| f.offset)
            .fold(f64::INFINITY, f64::min);
        assert!(r_in > 0.0 && r_in < r, "{what}: inradius {r_in}");
        assert!(
            moment > 0.4 * m * r_in * r_in && moment < 0.4 * m * r * r,
            "{what}: I = {moment:e} outside [(2/5) m r_in², (2/5) m r²] = [{:e}, {:e}]",
            0.4 * m * r_in * r_in,
            0.4 * m * r * r
        );
        let gap = 1.0 - moment / (0.4 * m * r * r);
        if s > 0 {
            let ratio = gap / last_gap;
            assert!(
                (0.25..0.33).contains(&ratio),
                "{what}: inertia deficit {gap:e} is {ratio} of the previous one"
            );
        }
        last_gap = gap;
    }
    assert!(
        last_gap < 4e-4,
        "s = 5: inertia still {last_gap:e} below (2/5) m r²"
    );
}

#[test]
fn two_boxes_side_by_side_equal_one_box_twice_as_long() {
    let scene = load_ok(&format!(
        "{WORLD}
[objects.pair]
shape = {{ compound = [
  {{ shape = {{ box = {{ half_extents = [0.2, 0.1, 0.05] }} }}, position = [-0.2, 0.0, 0.0] }},
  {{ shape = {{ box = {{ half_extents = [0.2, 0.1, 0.05] }} }}, position = [0.2, 0.0, 0.0] }},
] }}
mass = 4.0

[objects.long]
shape = {{ box = {{ half_extents = [0.4, 0.1, 0.05] }} }}
mass = 4.0
"
    ));
    let pair = object(&scene, "pair");
    let long = object(&scene, "long");
    assert_eq!(pair.parts.len(), 2);
    assert_close(pair.volume, long.volume, 1e-12, "volume");
    assert_matches_box(pair, 4.0, [0.4, 0.1, 0.05], "two boxes");
    assert_vector_close(
        &pair.shape_origin,
        &Vector3::zeros(),
        1e-15,
        "centre of mass",
    );
}

const OFF_CENTRE: &str = "
[objects.offcentre]
# A 0.2 m cube at the origin and a 0.4 x 0.2 x 0.2 m block touching it at x = 0.1.
shape = { compound = [
  { shape = { box = { half_extents = [0.1, 0.1, 0.1] } } },
  { shape = { box = { half_extents = [0.2, 0.1, 0.1] } }, position = [0.3, 0.0, 0.0] },
] }
density = 1000.0
";

#[test]
fn off_centre_compound_shifts_centre_of_mass_by_parallel_axis_rule() {
    let o = object(&load_ok(&format!("{WORLD}{OFF_CENTRE}")), "offcentre").clone();
    // Masses 8 kg and 16 kg at x = 0 and x = 0.3: centre of mass at x = 0.2.
    let (m1, m2) = (8.0, 16.0);
    let com = Vector3::new(0.2, 0.0, 0.0);
    assert_close(o.mass, m1 + m2, 1e-12, "mass");
    assert_vector_close(
        &o.shape_origin,
        &-com,
        1e-15,
        "shape origin seen from the centre of mass",
    );
    let expected = box_inertia(m1, [0.1, 0.1, 0.1])
        + parallel_axis(m1, Vector3::new(0.0, 0.0, 0.0) - com)
        + box_inertia(m2, [0.2, 0.1, 0.1])
        + parallel_axis(m2, Vector3::new(0.3, 0.0, 0.0) - com);
    assert_matrix_close(
        &o.inertia,
        &expected,
        1e-12,
        "inertia about the centre of mass",
    );
    // The parts are stored in the centre-of-mass frame.
    let mean_x = o.parts[0].hull.vertices().iter().map(|v| v.x).sum::<f64>() / 8.0;
    assert_close(mean_x, -0.2, 1e-12, "first part's centre in the body frame");
}

#[test]
fn body_position_places_shape_origin_and_state_holds_centre_of_mass() {
    let scene = load_ok(&format!(
        "{WORLD}{OFF_CENTRE}
[[bodies]]
object = \"offcentre\"
position = [1.0, 2.0, 3.0]

[[bodies]]
object = \"offcentre\"
position = [5.0, 2.0, 3.0]
# A quarter turn about z: the centre of mass swings from +x to +y of the origin.
orientation = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]
velocity = [0.5, 0.0, 0.0]
angular_velocity = [1.0, -2.0, 3.0]
"
    ));
    let [plain, turned] = [&scene.bodies[0], &scene.bodies[1]];
    assert_vector_close(
        &plain.state.position,
        &Vector3::new(1.2, 2.0, 3.0),
        1e-12,
        "unrotated",
    );
    assert_vector_close(
        &turned.state.position,
        &Vector3::new(5.0, 2.2, 3.0),
        1e-12,
        "rotated",
    );
    let q = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), PI / 2.0);
    assert!(turned.state.orientation.angle_to(&q) < 1e-12);
    let o = scene.object_of(rigidsim::body::BodyId(1));
    assert_vector_close(
        &turned.state.velocity,
        &Vector3::new(0.5, 0.0, 0.0),
        0.0,
        "velocity",
    );
    assert_vector_close(
        &turned.angular_velocity(o),
        &Vector3::new(1.0, -2.0, 3.0),
        1e-12,
        "angular velocity (through L = I ω)",
    );
}

#[test]
fn density_gives_mass_from_volume_and_same_inertia_as_equal_mass() {
    let scene = load_ok(&format!(
        "{WORLD}
[objects.by_density]
shape = {{ box = {{ half_extents = [0.1, 0.2, 0.3] }} }}
density = 500.0

[objects.by_mass]
shape = {{ box = {{ half_extents = [0.1, 0.2, 0.3] }} }}
mass = 24.0
"
    ));
    let d = object(&scene, "by_density");
    let m = object(&scene, "by_mass");
    assert_close(d.mass, 500.0 * 0.048, 1e-12, "mass = density x volume");
    assert_matrix_close(&d.inertia, &m.inertia, 1e-12, "inertia");
}

#[test]
fn given_inertia_replaces_the_computed_one() {
    let o = thing(
        "shape = { box = { half_extents = [0.1, 0.1, 0.1] } }\nmass = 1.0\n\
         inertia = [[0.01, 0.001, 0.0], [0.001, 0.02, 0.0], [0.0, 0.0, 0.025]]",
    );
    let given = Matrix3::new(0.01, 0.001, 0.0, 0.001, 0.02, 0.0, 0.0, 0.0, 0.025);
    assert_eq!(o.inertia, given);
}

#[test]
fn computed_bounding_spheres_enclose_every_point_of_every_part() {
    let scene = load_ok(&format!(
        "{WORLD}{OFF_CENTRE}
[objects.cube]
shape = {{ box = {{ half_extents = [0.1, 0.1, 0.1] }} }}
mass = 1.0

[objects.rod]
shape = {{ box = {{ half_extents = [1.0, 0.05, 0.1] }} }}
mass = 1.0

[objects.tilted_rod]
shape = {{ compound = [
  {{ shape = {{ cylinder = {{ radius = 0.05, half_height = 0.8 }} }},
     orientation = [0.9238795325112867, 0.3826834323650898, 0.0, 0.0], position = [0.0, 0.3, 0.0] }},
] }}
mass = 1.0

[objects.nut]
shape = {{ nut = {{}} }}
mass = 0.02

[objects.bolt]
shape = {{ bolt = {{}} }}
mass = 0.03

[objects.ball]
shape = {{ sphere = {{ radius = 0.2, subdivisions = 3 }} }}
mass = 1.0
"
    ));
    assert_eq!(
        object(&scene, "cube").spheres.len(),
        1,
        "a cube needs one sphere"
    );
    assert!(
        object(&scene, "rod").spheres.len() >= 3,
        "a long rod gets several spheres"
    );
    // Points of each convex part: its vertices and seeded convex combinations of them.
    let mut seed = 1u64;
    let mut uniform = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for o in &scene.objects {
        for (pi, p) in o.parts.iter().enumerate() {
            let v = p.hull.vertices();
            let mut points = v.to_vec();
            for _ in 0..2000 {
                let w: Vec<f64> = v.iter().map(|_| uniform().powi(8)).collect();
                let total: f64 = w.iter().sum();
                points.push(v.iter().zip(&w).map(|(x, wi)| x * (wi / total)).sum());
            }
            for x in &points {
                let inside = o
                    .spheres
                    .iter()
                    .any(|s| (x - s.center).norm() <= s.radius * (1.0 + 1e-9));
                assert!(
                    inside,
                    "{}: point {x:?} of part {pi} is in no sphere",
                    o.name
                );
                let own = (x - p.sphere.center).norm() <= p.sphere.radius * (1.0 + 1e-9);
                assert!(own, "{}: point {x:?} outside its part's sphere", o.name);
            }
        }
    }
}

#[test]
fn given_spheres_that_miss_a_vertex_are_refused() {
    let e = expect_error(
        &one_object(&format!(
            "{CUBE}\nmass = 1.0\nspheres = [{{ center = [0.0, 0.0, 0.0], radius = 0.15 }}]"
        )),
        "objects.thing.spheres",
    );
    assert_mentions(
        &e,
        &["do not enclose vertex", "part 'objects.thing.shape.box'"],
    );
}

// ------------------------------------------------------------- nut and bolt

fn nut_and_bolt() -> (ObjectDef, ObjectDef) {
    let scene = load_ok(&format!(
        "{WORLD}
[objects.nut]
shape = {{ nut = {{}} }}
mass = 0.02

[objects.bolt]
shape = {{ bolt = {{}} }}
mass = 0.03
"
    ));
    (
        object(&scene, "nut").clone(),
        object(&scene, "bolt").clone(),
    )
}

#[test]
fn default_nut_is_a_ring_of_convex_pieces_with_hexagon_minus_hole_volume() {
    let (nut, _) = nut_and_bolt();
    // Defaults: 40 mm across flats, 16 mm thick, a 32-sided hole of radius 11 mm.
    let expected = (hexagon_area(0.04) - polygon_area(32, 0.011)) * 0.016;
    assert_close(nut.volume, expected, 1e-12, "nut volume");
    assert_close(summed_tetrahedra(&nut), expected, 1e-12, "nut tetrahedra");
    assert_eq!(nut.parts.len(), 32, "one convex piece per hole side");
    // Symmetric about its centre, which lies in the hole: inside no piece.
    assert_vector_close(
        &nut.shape_origin,
        &Vector3::zeros(),
        1e-15,
        "nut centre of mass",
    );
    for (i, p) in nut.parts.iter().enumerate() {
        let outside = p.hull.faces().iter().any(|f| f.offset < 0.0);
        assert!(outside, "piece {i} contains the centre of the hole");
    }
}

#[test]
fn nut_volume_is_hexagon_minus_hole_for_any_side_count() {
    // Wedges whose rays hit hexagon corners exactly (6, 12) and ones that
    // cut across flats and hold a corner inside (3, 5, 7, 13, ...).
    for n in [3u32, 4, 5, 6, 7, 8, 12, 13, 32, 100] {
        let o = thing(&format!(
            "shape = {{ nut = {{ across_flats = 0.05, thickness = 0.02, hole_radius = 0.015, sides = {n} }} }}\n\
             mass = 0.02"
        ));
        let expected = (hexagon_area(0.05) - polygon_area(n, 0.015)) * 0.02;
        assert_eq!(o.parts.len() as u32, n, "sides = {n}");
        assert_close(
            o.volume,
            expected,
            1e-12,
            &format!("nut volume, sides = {n}"),
        );
    }
}

#[test]
fn default_bolt_is_hex_head_and_prism_shaft_with_closed_form_volume() {
    let (_, bolt) = nut_and_bolt();
    // Head: hexagon 30 mm across flats, 12 mm high; shaft: 40-gon of radius 9 mm, 40 mm long.
    let head = hexagon_area(0.03) * 0.012;
    let shaft = polygon_area(40, 0.009) * 0.04;
    assert_close(bolt.volume, head + shaft, 1e-12, "bolt volume");
    assert_eq!(bolt.parts.len(), 2);
    // Head from z = 0 up, shaft below: the centre of mass on the axis, between.
    let com_z = (head * 0.006 + shaft * -0.02) / (head + shaft);
    assert_vector_close(
        &bolt.shape_origin,
        &Vector3::new(0.0, 0.0, -com_z),
        1e-15,
        "shape origin from the centre of mass",
    );
}

#[test]
fn nut_and_bolt_are_about_four_centimetres() {
    let (nut, bolt) = nut_and_bolt();
    for (name, o) in [("nut", &nut), ("bolt", &bolt)] {
        let size = extent(o).max();
        assert!((0.03..0.06).contains(&size), "{name} is {size} m across");
    }
    assert_close(extent(&nut).y, 0.04, 1e-12, "nut across flats");
    assert_close(extent(&nut).z, 0.016, 1e-12, "nut thickness");
    assert_close(extent(&bolt).z, 0.052, 1e-12, "bolt length");
}

#[test]

fn nut_and_bolt_have_hundreds_of_triangles_like_the_thesis() {
    let (nut, bolt) = nut_and_bolt();
    for (name, o) in [("nut", &nut), ("bolt", &bolt)] {
        let n = triangle_count(o);
        assert!((100..1000).contains(&n), "{name} has {n} triangles");
    }
}

// ---------------------------------------------------------------- mesh files

fn mesh_thing(file: &str, extra: &str) -> ObjectDef {
    thing(&format!(
        "shape = {{ mesh = {{ path = \"{}\"{extra} }} }}\nmass = 2.0",
        data(file)
    ))
}

#[test]
fn obj_with_two_objects_gives_two_convex_parts_equal_to_one_box() {
    let o = mesh_thing("two_cubes.obj", "");
    assert_eq!(o.parts.len(), 2, "one part per OBJ object");
    assert_matches_box(&o, 2.0, [1.0, 0.5, 0.25], "two OBJ cubes");
    assert_vector_close(&o.shape_origin, &Vector3::zeros(), 1e-15, "centre of mass");
}

#[test]
fn ascii_stl_box_matches_box_mass_properties() {
    let o = mesh_thing("box_ascii.stl", "");
    assert_eq!(o.parts.len(), 1);
    assert_eq!(
        merged_faces(&o),
        6,
        "coplanar triangles merged into six faces"
    );
    assert_matches_box(&o, 2.0, [0.5, 0.25, 0.125], "ASCII STL box");
}

/// Binary STL: 80-byte header, triangle count, then per triangle a normal,
/// three corners (f32, little-endian) and a 2-byte attribute.
fn write_binary_stl(path: &Path, header: &str, h: [f32; 3]) {
    let c = |x: f32, y: f32, z: f32| [x * h[0], y * h[1], z * h[2]];
    let v = [
        c(-1., -1., -1.),
        c(1., -1., -1.),
        c(1., 1., -1.),
        c(-1., 1., -1.),
        c(-1., -1., 1.),
        c(1., -1., 1.),
        c(1., 1., 1.),
        c(-1., 1., 1.),
    ];
    let quads = [
        [0, 3, 2, 1],
        [4, 5, 6, 7],
        [0, 1, 5, 4],
        [1, 2, 6, 5],
        [2, 3, 7, 6],
        [3, 0, 4, 7],
    ];
    let mut bytes = header.as_bytes().to_vec();
    bytes.resize(80, b' ');
    bytes.extend_from_slice(&12u32.to_le_bytes());
    for q in quads {
        for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            bytes.extend_from_slice(&[0u8; 12]);
            for i in t {
                for x in v[i] {
                    bytes.extend_from_slice(&x.to_le_bytes());
                }
            }
            bytes.extend_from_slice(&[0u8; 2]);
        }
    }
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn binary_stl_box_matches_box_mass_properties() {
    // Many exporters start binary headers with "solid", the ASCII keyword.
    for header in ["binary box", "solid box (binary)"] {
        let dir = tempfile::tempdir().unwrap();
        write_binary_stl(&dir.path().join("box.stl"), header, [0.5, 0.25, 0.125]);
        let text = one_object("shape = { mesh = { path = \"box.stl\" } }\nmass = 2.0");
        std::fs::write(dir.path().join("scene.toml"), text).unwrap();
        let scene = scene::load(&dir.path().join("scene.toml")).unwrap_or_else(|e| panic!("{e}"));
        let what = format!("binary STL box, header {header:?}");
        assert_matches_box(object(&scene, "thing"), 2.0, [0.5, 0.25, 0.125], &what);
    }
}

#[test]
fn dxf_3dface_box_matches_box_mass_properties() {
    // DXF coordinates are text read as f64: no single-precision rounding.
    for file in ["box_quads.dxf", "box_triangles.dxf"] {
        let o = mesh_thing(file, "");
        assert_eq!(o.parts.len(), 1, "{file}");
        assert_eq!(merged_faces(&o), 6, "{file}: faces merged");
        assert_matches_box(&o, 2.0, [0.1, 0.2, 0.3], file);
    }
}

#[test]
fn hull_of_a_dented_obj_is_the_cube_around_it() {
    let o = mesh_thing("dented_cube.obj", ", hull = true");
    assert_eq!(o.parts.len(), 1);
    assert_eq!(merged_faces(&o), 6);
    assert_matches_box(&o, 2.0, [0.5, 0.5, 0.5], "hull of the dented cube");
}

#[test]
fn mesh_of_unknown_format_is_refused() {
    let e = expect_error(
        &one_object("shape = { mesh = { path = \"part.ply\" } }\nmass = 1.0"),
        "objects.thing.shape.mesh.path",
    );
    assert_mentions(&e, &["part.ply"]);
}

#[test]

fn dxf_with_a_trailing_blank_line_loads() {
    let dir = tempfile::tempdir().unwrap();
    let dxf = std::fs::read_to_string(data("box_quads.dxf")).unwrap() + "\n";
    std::fs::write(dir.path().join("box.dxf"), dxf).unwrap();
    let text = one_object("shape = { mesh = { path = \"box.dxf\" } }\nmass = 2.0");
    std::fs::write(dir.path().join("scene.toml"), text).unwrap();
    let scene = scene::load(&dir.path().join("scene.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_matches_box(object(&scene, "thing"), 2.0, [0.1, 0.2, 0.3], "DXF box");
}

#[test]

fn obj_vertices_keep_double_precision() {
    let dir = tempfile::tempdir().unwrap();
    let obj = std::fs::read_to_string(data("two_cubes.obj"))
        .unwrap()
        .replace("0.25", "0.1");
    std::fs::write(dir.path().join("cubes.obj"), obj).unwrap();
    let text = one_object("shape = { mesh = { path = \"cubes.obj\" } }\nmass = 2.0");
    std::fs::write(dir.path().join("scene.toml"), text).unwrap();
    let scene = scene::load(&dir.path().join("scene.toml")).unwrap_or_else(|e| panic!("{e}"));
    assert_matches_box(
        object(&scene, "thing"),
        2.0,
        [1.0, 0.5, 0.1],
        "OBJ box, z = ±0.1",
    );
}

// ----------------------------------------------------------------- bad input

#[test]
fn malformed_toml_names_the_line() {
    let e = expect_error("[world]\nduration = 1.0\ndt = 0.01 0.02\n", "");
    assert!(e.message.starts_with("line 3: "), "{e}");
}

#[test]
fn unclosed_table_header_names_the_line() {
    let e = expect_error("[world]\nduration = 1.0\n\n[objects.cube\n", "");
    assert!(e.message.starts_with("line 4: "), "{e}");
}

#[test]
fn misspelt_field_is_named_with_the_fields_expected() {
    let e = expect_error(
        "[world]\nduration = 1.0\ngravty = [0.0, 0.0, -1.0]\n",
        "world.gravty",
    );
    assert_mentions(&e, &["line 3", "unknown field", "gravty", "gravity"]);
}

#[test]
fn unknown_object_in_bodies_lists_the_defined_ones() {
    let e = expect_error(
        &format!(
            "{WORLD}[objects.cube]\nshape = {{ box = {{ half_extents = [0.1, 0.1, 0.1] }} }}\n\
             mass = 1.0\n\n[[bodies]]\nobject = \"cube\"\n\n[[bodies]]\nobject = \"cub\"\n"
        ),
        "bodies[1].object",
    );
    assert_eq!(e.message, "unknown object 'cub' (defined: cube)");
}

#[test]
fn missing_mesh_file_is_named() {
    let e = expect_error(
        &one_object("shape = { mesh = { path = \"no_such_mesh.obj\" } }\nmass = 1.0"),
        "objects.thing.shape.mesh.path",
    );
    assert_mentions(&e, &["no_such_mesh.obj", "cannot read mesh file"]);
}

const CUBE: &str = "shape = { box = { half_extents = [0.1, 0.1, 0.1] } }";

#[test]
fn negative_mass_is_refused() {
    let e = expect_error(
        &one_object(&format!("{CUBE}\nmass = -1.0")),
        "objects.thing.mass",
    );
    assert_eq!(e.message, "must be a positive finite number (got -1)");
}

#[test]
fn zero_mass_is_refused() {
    let e = expect_error(
        &one_object(&format!("{CUBE}\nmass = 0.0")),
        "objects.thing.mass",
    );
    assert_eq!(e.message, "must be a positive finite number (got 0)");
}

#[test]
fn missing_mass_and_density_is_refused() {
    let e = expect_error(&one_object(CUBE), "objects.thing.mass");
    assert_mentions(&e, &["required", "density"]);
}

#[test]
fn mass_and_density_together_are_refused() {
    let e = expect_error(
        &one_object(&format!("{CUBE}\nmass = 1.0\ndensity = 1000.0")),
        "objects.thing.mass",
    );
    assert_eq!(e.message, "give mass or density, not both");
}

#[test]
fn non_finite_density_is_refused() {
    let e = expect_error(
        &one_object(&format!("{CUBE}\ndensity = inf")),
        "objects.thing.density",
    );
    assert_mentions(&e, &["positive finite", "inf"]);
}

#[test]
fn nan_in_a_position_is_refused() {
    let text = one_object(&format!("{CUBE}\nmass = 1.0")) + "position = [nan, 0.0, 1.0]\n";
    let e = expect_error(&text, "bodies[0].position");
    assert_eq!(e.message, "must be finite (got NaN)");
}

#[test]
fn infinite_gravity_is_refused() {
    let e = expect_error(
        "[world]\nduration = 1.0\ngravity = [0.0, 0.0, -inf]\n",
        "world.gravity",
    );
    assert_eq!(e.message, "must be finite (got -inf)");
}

#[test]
fn island_blocks_out_of_range_are_refused() {
    for (given, got) in [("0", "0"), ("1000", "1000")] {
        let e = expect_error(
            &format!("[world]\nduration = 1.0\nisland_blocks = {given}\n"),
            "world.island_blocks",
        );
        assert_eq!(e.message, format!("must be from 1 to 256 (got {got})"));
    }
}

#[test]
fn nan_gravity_is_refused() {
    let e = expect_error(
        "[world]\nduration = 1.0\ngravity = [nan, 0.0, -9.81]\n",
        "world.gravity",
    );
    assert_eq!(e.message, "must be finite (got NaN)");
}

fn mesh_error(file: &str) -> SceneError {
    let part = match file {
        "l_shape.obj" => "ell",
        "dented_cube.obj" => "dented",
        "open_box.obj" => "open",
        "flat.obj" => "sheet",
        _ => unreachable!(),
    };
    let text = one_object(&format!(
        "shape = {{ mesh = {{ path = \"{}\" }} }}\nmass = 1.0",
        data(file)
    ));
    let e = expect_error(
        &text,
        &format!("objects.thing.shape.mesh.path part '{part}'"),
    );
    assert_mentions(&e, &[file]);
    e
}

#[test]
fn non_convex_obj_part_is_named() {
    for file in ["l_shape.obj", "dented_cube.obj"] {
        assert_mentions(&mesh_error(file), &["is not convex"]);
    }
}

#[test]
fn open_mesh_is_refused() {
    assert_mentions(&mesh_error("open_box.obj"), &["is not closed"]);
}

#[test]
fn flat_mesh_has_zero_volume() {
    assert_mentions(&mesh_error("flat.obj"), &["zero volume"]);
}

#[test]
fn zero_half_extent_is_refused() {
    let e = expect_error(
        &one_object("shape = { box = { half_extents = [0.1, 0.0, 0.1] } }\nmass = 1.0"),
        "objects.thing.shape.box.half_extents",
    );
    assert_eq!(e.message, "must be a positive finite number (got 0)");
}

#[test]
fn compound_part_of_zero_radius_is_named() {
    let e = expect_error(
        &one_object(
            "shape = { compound = [\n\
             { shape = { box = { half_extents = [0.1, 0.1, 0.1] } } },\n\
             { shape = { sphere = { radius = 0.0 } }, position = [0.3, 0.0, 0.0] },\n\
             ] }\nmass = 1.0",
        ),
        "objects.thing.shape.compound[1].shape.sphere.radius",
    );
    assert_mentions(&e, &["positive"]);
}

#[test]
fn nut_hole_too_wide_for_its_hexagon_is_refused() {
    let e = expect_error(
        &one_object("shape = { nut = { across_flats = 0.04, hole_radius = 0.021 } }\nmass = 1.0"),
        "objects.thing.shape.nut.hole_radius",
    );
    assert_mentions(&e, &["across_flats"]);
}

#[test]
fn inertia_that_is_not_positive_definite_is_refused() {
    let e = expect_error(
        &one_object(&format!(
            "{CUBE}\nmass = 1.0\ninertia = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, -0.01]]"
        )),
        "objects.thing.inertia",
    );
    assert_mentions(&e, &["is not positive definite"]);
}

#[test]
fn inertia_that_is_not_symmetric_is_refused() {
    let e = expect_error(
        &one_object(&format!(
            "{CUBE}\nmass = 1.0\ninertia = [[0.01, 0.005, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.01]]"
        )),
        "objects.thing.inertia",
    );
    assert_eq!(e.message, "is not symmetric");
}

#[test]
fn inertia_that_breaks_the_triangle_inequality_is_refused() {
    let e = expect_error(
        &one_object(&format!(
            "{CUBE}\nmass = 1.0\ninertia = [[0.01, 0.0, 0.0], [0.0, 0.01, 0.0], [0.0, 0.0, 0.05]]"
        )),
        "objects.thing.inertia",
    );
    assert_mentions(&e, &["not physically possible"]);
}

#[test]
fn restitution_above_one_is_refused() {
    let e = expect_error(
        &one_object(&format!("{CUBE}\nmass = 1.0\nrestitution = 1.5")),
        "objects.thing.restitution",
    );
    assert_eq!(e.message, "must be between 0 and 1 (got 1.5)");
}

#[test]
fn negative_friction_is_refused() {
    let e = expect_error(
        &one_object(&format!("{CUBE}\nmass = 1.0\nfriction = -0.1")),
        "objects.thing.friction",
    );
    assert_eq!(e.message, "must be a finite number ≥ 0 (got -0.1)");
}

#[test]
fn duration_is_required_without_until_rest() {
    let e = expect_error("[world]\ndt = 0.01\n", "world.duration");
    assert_eq!(e.message, "is required unless until_rest = true");
    load_ok("[world]\nuntil_rest = true\n");
}

const SCATTER_CUBES: &str = "[objects.cube]
shape = { box = { half_extents = [0.1, 0.1, 0.1] } }
mass = 1.0
";

#[test]
fn scatter_of_a_billion_bodies_is_refused_quickly() {
    let started = Instant::now();
    let e = expect_error(
        &format!(
            "{WORLD}{SCATTER_CUBES}\n[[scatter]]\nobjects = [\"cube\"]\ncount = 1000000000\n\
             min = [-1.0, -1.0, 0.0]\nmax = [1.0, 1.0, 1.0]\n"
        ),
        "scatter[0].count",
    );
    assert!(
        started.elapsed() < Duration::from_secs(2),
        "took {:?}",
        started.elapsed()
    );
    assert_mentions(&e, &["1000000000", &scene::MAX_BODIES.to_string()]);
}

#[test]

fn scatter_counts_that_overflow_are_refused_by_the_body_limit() {
    // 2 x (2^63 - 1) + 10 wraps to 8 in u64.
    let e = expect_error(
        &format!(
            "{WORLD}{SCATTER_CUBES}
[[scatter]]
objects = [\"cube\"]
count = 9223372036854775807
min = [0.0, 0.0, 0.0]
max = [0.1, 0.1, 0.1]

[[scatter]]
objects = [\"cube\"]
count = 9223372036854775807
min = [5.0, 5.0, 5.0]
max = [5.1, 5.1, 5.1]

[[scatter]]
objects = [\"cube\"]
count = 10
min = [-5.0, -5.0, -5.0]
max = [-4.0, -4.0, -4.0]
"
        ),
        "scatter[0].count",
    );
    assert_mentions(&e, &[&scene::MAX_BODIES.to_string()]);
}

#[test]
fn scatter_that_cannot_fit_says_how_many_were_placed() {
    // Boxes 0.2 m wide whose origins all fall within 0.1 m: only one fits.
    let e = expect_error(
        &format!(
            "{WORLD}{SCATTER_CUBES}\n[[scatter]]\nobjects = [\"cube\"]\ncount = 20\n\
             min = [0.0, 0.0, 0.0]\nmax = [0.1, 0.1, 0.1]\nrandom_orientation = false\n"
        ),
        "scatter[0].count",
    );
    assert_eq!(
        e.message,
        "could place only 1 of 20 bodies without overlap; enlarge min/max or lower count"
    );
}

#[test]
fn scatter_places_every_body_without_overlap_reproducibly() {
    let text = format!(
        "{WORLD}{SCATTER_CUBES}\n[[bodies]]\nobject = \"cube\"\n\n[[scatter]]\nobjects = [\"cube\"]\n\
         count = 30\nmin = [-1.0, -1.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nseed = 7\n"
    );
    let (a, b) = (load_ok(&text), load_ok(&text));
    assert_eq!(
        a.bodies.len(),
        31,
        "the [[bodies]] one first, then 30 scattered"
    );
    for (x, y) in a.bodies.iter().zip(&b.bodies) {
        assert_eq!(x.state, y.state, "same seed, same placement");
    }
    // Placement keeps the bodies' world boxes apart, and a 0.2 m cube's box is
    // at least 0.2 m wide whatever its orientation: centres differ by ≥ 0.2 m
    // along some axis.
    for (i, x) in a.bodies.iter().enumerate() {
        for y in &a.bodies[..i] {
            let d = x.state.position - y.state.position;
            assert!(d.norm() >= 0.2 - 1e-12, "bodies overlap: {d:?}");
        }
    }
}

#[test]
fn force_on_a_body_that_does_not_exist_is_refused() {
    let text = one_object(&format!("{CUBE}\nmass = 1.0"))
        + "\n[[forces]]\nbody = 1\nforce = [1.0, 0.0, 0.0]\n";
    let e = expect_error(&text, "forces[0].body");
    assert_eq!(
        e.message,
        "no body 1 (the scene has 1 bodies, numbered from 0)"
    );
}

#[test]
fn zero_quaternion_is_refused() {
    let text = one_object(&format!("{CUBE}\nmass = 1.0")) + "orientation = [0.0, 0.0, 0.0, 0.0]\n";
    let e = expect_error(&text, "bodies[0].orientation");
    assert_eq!(e.message, "quaternion [w, x, y, z] must not be zero");
}

#[test]
fn render_size_out_of_range_is_refused() {
    for size in ["[8, 100]", "[640, 10000]"] {
        let e = expect_error(
            &format!("{WORLD}\n[render]\nsize = {size}\n"),
            "render.size",
        );
        assert_eq!(e.message, "each side must be between 16 and 8192 pixels");
    }
}

#[test]
fn negative_render_size_is_a_type_error_on_the_field() {
    let e = expect_error(
        &format!("{WORLD}\n[render]\nsize = [-640, 360]\n"),
        "render.size[0]",
    );
    assert_mentions(&e, &["line 5"]);
}

// ----------------------------------------------------------- bundled scenes

#[test]
fn every_bundled_scene_loads() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut names = Vec::new();
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let scene = scene::load(&path).unwrap_or_else(|e| panic!("{e}"));
        let name = path.file_stem().unwrap().to_str().unwrap();
        assert_eq!(scene.name, name);
        assert!(
            scene.bodies.iter().any(|b| b.is_dynamic()),
            "{name}: nothing moves"
        );
        for o in &scene.objects {
            assert!(o.mass > 0.0 && o.volume > 0.0, "{name}: object {}", o.name);
        }
        names.push(name.to_string());
    }
    names.sort();
    for required in [
        "bouncing_cube",
        "load_profile",
        "newtons_cradle",
        "nuts_and_bolts",
        "resting_stack",
        "sliding_box",
        "tumbling_box",
    ] {
        assert!(
            names.iter().any(|n| n == required),
            "scenes/{required}.toml is missing"
        );
    }
}

#[test]
fn load_profile_scene_has_the_thesis_grid_of_27_spheres() {
    let scene =
        scene::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/load_profile.toml"))
            .unwrap_or_else(|e| panic!("{e}"));
    let dynamic: Vec<_> = scene.bodies.iter().filter(|b| b.is_dynamic()).collect();
    assert_eq!(dynamic.len(), 27);
    assert_eq!(scene.settings.dt, 0.01);
    for b in &dynamic {
        assert_eq!(scene.objects[b.object.0 as usize].restitution, 1.0);
    }
}

/// Faces after coplanar merging, over all parts (a box has 6).
fn merged_faces(o: &rigidsim::body::ObjectDef) -> usize {
    o.parts.iter().map(|p| p.hull.face_count()).sum()
}

// ------------------------------------------------------------ issue 23

/// Issue 23: `fall_z` defaulted to −1 m, so a body in free flight with no
/// floor stopped as it passed z = −1. A scene without `fall_z` now stops
/// bodies 1 m below the lowest vertex of its fixed bodies, in world
/// coordinates (a cube of 1 m turned 45° about x reaches 0.707 m below its
/// centre, not 0.5 m), whatever its dynamic or driven bodies do; it has no
/// cut-off without fixed bodies; a `fall_z` it sets is kept.
#[test]
fn fall_cutoff_defaults_to_a_metre_below_the_lowest_fixed_point() {
    let block =
        "[objects.block]\nshape = { box = { half_extents = [0.5, 0.5, 0.5] } }\nmass = 1.0\n";
    let tilted = "[[bodies]]\nobject = \"block\"\nposition = [0.0, 0.0, 2.0]\n\
                  orientation = [0.9238795325112867, 0.3826834323650898, 0.0, 0.0]\nfixed = true\n";
    let higher = "[[bodies]]\nobject = \"block\"\nposition = [5.0, 0.0, 3.0]\nfixed = true\n";
    let driven = "[[bodies]]\nobject = \"block\"\nposition = [10.0, 0.0, -50.0]\n\
                  driven = { velocity = [0.0, 0.0, 1.0] }\n";
    let dynamic = "[[bodies]]\nobject = \"block\"\nposition = [-10.0, 0.0, -20.0]\n";

    let s = load_ok(&format!("{WORLD}{block}{tilted}{higher}{driven}{dynamic}"));
    let lowest = 2.0 - 0.5 * 2f64.sqrt();
    let want = lowest - scene::FALL_BELOW_FIXED;
    assert!(
        (s.settings.fall_z - want).abs() <= 1e-12,
        "fall_z {} (want {want}: 1 m below the tilted block's lowest corner)",
        s.settings.fall_z
    );
    assert_eq!(scene::FALL_BELOW_FIXED, 1.0);

    let no_fixed = load_ok(&format!("{WORLD}{block}{driven}{dynamic}"));
    assert_eq!(
        no_fixed.settings.fall_z,
        f64::NEG_INFINITY,
        "a cut-off without a floor"
    );

    let given = load_ok(&format!(
        "[world]\nduration = 1.0\nfall_z = -0.25\n{block}{tilted}"
    ));
    assert_eq!(given.settings.fall_z, -0.25);
}

/// The bounds of issue 23 admit what they state, inclusive: a body 10⁶ m
/// out on every axis at 10⁶ m/s, a cube whose corners spin at just under
/// 10⁶ m/s, masses of 10⁻¹² and 10¹² kg on objects 10 µm and 10⁶ m across,
/// and a run of exactly 10⁹ steps.
#[test]
fn numbers_at_the_bounds_load() {
    let s = load_ok(
        "[world]\ndt = 0.01\nduration = 1e7\n\
         [objects.cube]\nshape = { box = { half_extents = [0.1, 0.1, 0.1] } }\nmass = 1.0\n\
         [objects.speck]\nshape = { box = { half_extents = [5e-6, 5e-6, 5e-6] } }\nmass = 1e-12\n\
         [objects.slab]\nshape = { box = { half_extents = [5e5, 5e5, 1.0] } }\nmass = 1e12\n\
         [[bodies]]\nobject = \"cube\"\nposition = [1e6, -1e6, 1e6]\nvelocity = [0.0, 1e6, 0.0]\n\
         [[bodies]]\nobject = \"cube\"\nposition = [0.0, 0.0, 10.0]\n\
         angular_velocity = [0.0, 0.0, 5.77e6]\n\
         [[bodies]]\nobject = \"speck\"\nposition = [0.0, 0.0, 20.0]\n\
         [[bodies]]\nobject = \"slab\"\nposition = [0.0, 0.0, -1.0]\nfixed = true\n",
    );
    assert_eq!(s.settings.total_steps(), 1_000_000_000);
    assert_eq!(s.bodies.len(), 4);
}

/// The time-of-impact sampling spaces its samples by the thinnest wall of
/// either body (`ObjectDef::min_thickness`): a face glued to another part
/// is inside the body, not a wall. A nut's wall is its flats less its hole
/// (9 mm for the default nut; 16 mm high), not the 3 mm width of the
/// wedges it is made of; a box is as thick as its smallest extent, alone
/// or cut into slabs glued together.
#[test]
fn min_thickness_is_the_thinnest_wall_not_the_thinnest_part() {
    let (nut, bolt) = nut_and_bolt();
    // Each wedge's centroid lies between the hole and the flats, so twice
    // its distance to the nearer of them is below the 9 mm wall (8.9 mm);
    // its glued sides, 1.6 mm away, no longer count.
    assert!(
        (0.006..=0.009).contains(&nut.min_thickness),
        "nut: {}",
        nut.min_thickness
    );
    // The bolt's head (12 mm high) sits on its shaft: the head's bottom face
    // is partly bare, so it still counts; the shaft's top is glued.
    assert!(
        (0.010..=0.012).contains(&bolt.min_thickness),
        "bolt: {}",
        bolt.min_thickness
    );
    let cube = thing("shape = { box = { half_extents = [0.5, 0.3, 0.2] } }\nmass = 1.0");
    assert_close(cube.min_thickness, 0.4, 1e-12, "box");
    let slabs = thing(&format!(
        "shape = {{ mesh = {{ path = \"{}\" }} }}\nmass = 1.0",
        data("three_slabs.obj")
    ));
    assert_eq!(slabs.parts.len(), 3);
    assert_close(slabs.min_thickness, 0.4, 1e-12, "three glued slabs");
}
