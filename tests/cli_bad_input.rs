//! The `rigidsim` binary run alone (one rank, no mpirun): bad input ends with
//! exit status 2, one stderr line naming the file and the field, no panic, no
//! hang and no output folder that looks complete; a good tiny scene writes
//! `trajectory.csv` and `summary.json` in the format issue 2 fixes.

use std::collections::BTreeSet;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A refused input must be refused within this (MPI start-up included).
const QUICK: Duration = Duration::from_secs(10);
/// A run still going after this is killed and reported as a hang.
const HANG: Duration = Duration::from_secs(60);

struct Outcome {
    code: Option<i32>,
    stderr: String,
    elapsed: Duration,
}

/// Runs the binary in `dir` and waits at most `deadline`, killing it after.
fn run_with_deadline(dir: &Path, args: &[&str], deadline: Duration) -> Outcome {
    let started = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_rigidsim"))
        .args(args)
        .current_dir(dir)
        // The binary initialises MPI even alone; Open MPI refuses root without these.
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("cannot start rigidsim");
    // Read stderr on a thread so a chatty child cannot block on a full pipe.
    let mut pipe = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = pipe.read_to_string(&mut s);
        s
    });
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if started.elapsed() > deadline {
            child.kill().unwrap();
            child.wait().unwrap();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let elapsed = started.elapsed();
    let stderr = reader.join().unwrap();
    match status {
        Some(s) => Outcome {
            code: s.code(),
            stderr,
            elapsed,
        },
        None => {
            panic!("rigidsim {args:?} still running after {deadline:?}: killed\nstderr:\n{stderr}")
        }
    }
}

fn rigidsim(dir: &Path, args: &[&str]) -> Outcome {
    run_with_deadline(dir, args, HANG)
}

/// A temporary folder holding `scene.toml` and, after a run, `out/`.
struct Case {
    dir: tempfile::TempDir,
}

impl Case {
    fn new(scene: &str) -> Case {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("scene.toml"), scene).unwrap();
        Case { dir }
    }
    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }
    fn scene(&self) -> String {
        self.path("scene.toml").display().to_string()
    }
    fn out(&self) -> String {
        self.path("out").display().to_string()
    }
    fn run(&self, extra: &[&str]) -> Outcome {
        let (scene, out) = (self.scene(), self.out());
        let mut args = vec![scene.as_str(), "--out", out.as_str(), "--no-progress"];
        args.extend_from_slice(extra);
        rigidsim(self.dir.path(), &args)
    }
}

fn assert_no_panic(o: &Outcome) {
    assert!(
        !o.stderr.contains("panicked"),
        "panic on stderr:\n{}",
        o.stderr
    );
    assert!(
        !o.stderr.contains("RUST_BACKTRACE"),
        "panic on stderr:\n{}",
        o.stderr
    );
}

/// Exit 2, quickly, without panic, one stderr line naming `names`, and no
/// output folder that could pass for a finished run. Returns the line.
fn assert_refused(case: &Case, names: &[&str]) -> String {
    let o = case.run(&[]);
    assert_no_panic(&o);
    assert_eq!(o.code, Some(2), "exit status; stderr:\n{}", o.stderr);
    assert!(o.elapsed < QUICK, "took {:?} to refuse", o.elapsed);
    let lines: Vec<&str> = o.stderr.lines().collect();
    assert_eq!(lines.len(), 1, "stderr should be one line:\n{}", o.stderr);
    let line = lines[0];
    assert!(
        line.contains(&case.scene()),
        "line does not name the scene file: {line}"
    );
    for n in names {
        assert!(line.contains(n), "line does not mention {n:?}: {line}");
    }
    for file in ["summary.json", "trajectory.csv"] {
        assert!(
            !case.path("out").join(file).exists(),
            "out/{file} written on bad input"
        );
    }
    line.to_string()
}

fn data(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
        .display()
        .to_string()
}

const WORLD: &str = "[world]\ndt = 0.01\nduration = 1.0\n";
const CUBE: &str = "shape = { box = { half_extents = [0.1, 0.1, 0.1] } }";

fn one_object(object: &str) -> String {
    format!("{WORLD}\n[objects.thing]\n{object}\n\n[[bodies]]\nobject = \"thing\"\n")
}

// ----------------------------------------------------------------- bad input

#[test]
fn malformed_toml_exits_2_naming_the_line() {
    assert_refused(
        &Case::new("[world]\nduration = 1.0\ndt = 0.01 0.02\n"),
        &["line 3"],
    );
}

#[test]
fn misspelt_field_exits_2_naming_it() {
    let case = Case::new("[world]\nduration = 1.0\ngravty = [0.0, 0.0, -1.0]\n");
    assert_refused(&case, &["world.gravty", "unknown field"]);
}

#[test]
fn unknown_object_exits_2_naming_the_field() {
    let case = Case::new(&format!(
        "{WORLD}[objects.cube]\n{CUBE}\nmass = 1.0\n\n[[bodies]]\nobject = \"cub\"\n"
    ));
    assert_refused(&case, &["bodies[0].object", "unknown object 'cub'"]);
}

#[test]
fn missing_mesh_file_exits_2_naming_the_path() {
    let case = Case::new(&one_object(
        "shape = { mesh = { path = \"gone.obj\" } }\nmass = 1.0",
    ));
    assert_refused(&case, &["objects.thing.shape.mesh.path", "gone.obj"]);
}

#[test]
fn zero_and_negative_mass_exit_2() {
    for mass in ["0.0", "-2.0"] {
        let case = Case::new(&one_object(&format!("{CUBE}\nmass = {mass}")));
        assert_refused(&case, &["objects.thing.mass", "positive"]);
    }
}

#[test]
fn non_finite_numbers_exit_2() {
    let nan_position = one_object(&format!("{CUBE}\nmass = 1.0")) + "position = [0.0, nan, 1.0]\n";
    assert_refused(&Case::new(&nan_position), &["bodies[0].position", "finite"]);
    let inf_gravity = "[world]\nduration = 1.0\ngravity = [0.0, 0.0, inf]\n";
    assert_refused(&Case::new(inf_gravity), &["world.gravity", "finite"]);
}

#[test]
fn non_convex_part_exits_2_naming_the_part() {
    let case = Case::new(&one_object(&format!(
        "shape = {{ mesh = {{ path = \"{}\" }} }}\nmass = 1.0",
        data("l_shape.obj")
    )));
    assert_refused(&case, &["part 'ell'", "is not convex"]);
}

#[test]
fn zero_volume_shape_exits_2() {
    let case = Case::new(&one_object(&format!(
        "shape = {{ mesh = {{ path = \"{}\" }} }}\nmass = 1.0",
        data("flat.obj")
    )));
    assert_refused(&case, &["part 'sheet'", "zero volume"]);
    let flat_box = one_object("shape = { box = { half_extents = [0.1, 0.1, 0.0] } }\nmass = 1.0");
    assert_refused(
        &Case::new(&flat_box),
        &["objects.thing.shape.box.half_extents"],
    );
}

#[test]
fn inertia_not_positive_definite_exits_2() {
    let case = Case::new(&one_object(&format!(
        "{CUBE}\nmass = 1.0\ninertia = [[0.01, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.01]]"
    )));
    assert_refused(&case, &["objects.thing.inertia", "positive definite"]);
}

/// An inertia no body of its mass and shape can have (here 1e200 kg·m²
/// for a 1 kg cube of 0.2 m, which reaches at most 2·m·r² = 0.06 in its
/// diagonal's sum) is refused; a hollow cube's, near that bound, is not.
#[test]
fn inertia_beyond_its_mass_and_shape_exits_2() {
    let case = Case::new(&one_object(&format!(
        "{CUBE}\nmass = 1.0\ninertia = [[1e200, 0.0, 0.0], [0.0, 1e200, 0.0], [0.0, 0.0, 1e200]]"
    )));
    assert_refused(&case, &["objects.thing.inertia", "larger than any body"]);
    let just_over = Case::new(&one_object(&format!(
        "{CUBE}\nmass = 1.0\ninertia = [[0.021, 0.0, 0.0], [0.0, 0.021, 0.0], [0.0, 0.0, 0.021]]"
    )));
    assert_refused(&just_over, &["objects.thing.inertia", "at most 2·mass·r²"]);
    // All the mass on the corners: 2/3 of m·r² = 0.02 about each axis.
    let corners = Case::new(&one_object(&format!(
        "{CUBE}\nmass = 1.0\ninertia = [[0.02, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, 0.02]]"
    )));
    let o = corners.run(&["--duration", "0.02", "--no-render"]);
    assert_eq!(o.code, Some(0), "stderr:\n{}", o.stderr);
}

#[test]
fn scatter_of_a_billion_bodies_exits_2_quickly() {
    let case = Case::new(&format!(
        "{WORLD}[objects.cube]\n{CUBE}\nmass = 1.0\n\n[[scatter]]\nobjects = [\"cube\"]\n\
         count = 1000000000\nmin = [-1.0, -1.0, 0.0]\nmax = [1.0, 1.0, 1.0]\n"
    ));
    assert_refused(&case, &["scatter", "200000"]);
}

#[test]

fn scatter_counts_that_overflow_exit_2_quickly() {
    // 2 x (2^63 - 1) + 10 wraps to 8 in u64, under the body limit; the first
    // scatter then tries to place 2^63 - 1 cubes in a 200 m box.
    let scatter = |count: &str, min: f64, max: f64| {
        format!(
            "\n[[scatter]]\nobjects = [\"cube\"]\ncount = {count}\n\
             min = [{min:?}, {min:?}, {min:?}]\nmax = [{max:?}, {max:?}, {max:?}]\n"
        )
    };
    let case = Case::new(&format!(
        "{WORLD}[objects.cube]\n{CUBE}\nmass = 1.0\n{}{}{}",
        scatter("9223372036854775807", -100.0, 100.0),
        scatter("9223372036854775807", 200.0, 300.0),
        scatter("10", -300.0, -200.0),
    ));
    let o = run_with_deadline(
        case.dir.path(),
        &[&case.scene(), "--out", &case.out()],
        QUICK,
    );
    assert_eq!(o.code, Some(2), "stderr:\n{}", o.stderr);
    assert!(o.stderr.contains("200000"), "{}", o.stderr);
}

#[test]
fn missing_scene_file_exits_2_without_panic() {
    let dir = tempfile::tempdir().unwrap();
    let o = rigidsim(dir.path(), &["no_such_scene.toml", "--no-progress"]);
    assert_no_panic(&o);
    assert_eq!(o.code, Some(2), "stderr:\n{}", o.stderr);
    assert_eq!(o.stderr.lines().count(), 1, "stderr:\n{}", o.stderr);
    assert!(o.stderr.contains("no_such_scene.toml"), "{}", o.stderr);
    assert!(
        !dir.path().join("out").exists(),
        "an output folder was made"
    );
}

#[test]
fn unknown_cli_flag_exits_2_without_panic() {
    let case = Case::new(&one_object(&format!("{CUBE}\nmass = 1.0")));
    let o = rigidsim(case.dir.path(), &[&case.scene(), "--bogus-flag"]);
    assert_no_panic(&o);
    assert_eq!(o.code, Some(2), "stderr:\n{}", o.stderr);
    assert!(o.stderr.contains("--bogus-flag"), "{}", o.stderr);
    assert!(!case.path("out").exists(), "an output folder was made");
}

#[test]
fn bad_command_line_override_exits_2_naming_the_option() {
    let case = Case::new(&one_object(&format!("{CUBE}\nmass = 1.0")));
    for (flag, value) in [
        ("--dt", "0"),
        ("--duration", "-1.0"),
        ("--sample-every", "nan"),
        ("--link-latency-us", "-1"),
        ("--link-bytes-per-s", "0"),
        ("--island-blocks", "0"),
        ("--island-blocks", "257"),
    ] {
        let arg = format!("{flag}={value}");
        let o = case.run(&[&arg]);
        assert_no_panic(&o);
        assert_eq!(o.code, Some(2), "{flag} {value}; stderr:\n{}", o.stderr);
        assert_eq!(o.stderr.lines().count(), 1, "stderr:\n{}", o.stderr);
        assert!(o.stderr.contains(flag), "{}", o.stderr);
        assert!(!case.path("out").join("summary.json").exists());
    }
}

// ------------------------------------------- bodies placed inside each other

/// Two cubes of `half` m half-extent, their centres `gap` m apart along x
/// (`2 half` is touching), after `extra` (a floor, a scatter).
fn two_cubes(half: f64, gap: f64, extra: &str) -> String {
    format!(
        "{WORLD}[objects.cube]\nshape = {{ box = {{ half_extents = [{half}, {half}, {half}] }} }}\n\
         mass = 1.0\n\n[[bodies]]\nobject = \"cube\"\nposition = [0.0, 0.0, 1.0]\n\n\
         [[bodies]]\nobject = \"cube\"\nposition = [{gap}, 0.0, 1.0]\n{extra}"
    )
}

const FLOOR: &str = "
[objects.floor]
shape = { box = { half_extents = [1.0, 1.0, 0.1] } }
mass = 1.0

[[bodies]]
object = \"floor\"
position = [0.0, 0.0, -0.1]
fixed = true
";

/// Issue 23: two 0.2 m cubes placed 0.05 m apart (0.15 m of overlap) ran
/// to the end with exit status 0. Bodies overlapping at the start by more
/// than the contact tolerance are bad input: exit 2 and one line with the
/// file, both bodies, their objects and the depth (as the step measures it,
/// to four digits), quickly, whether the other body is dynamic or a fixed
/// floor.
#[test]
fn bodies_overlapping_at_the_start_are_rejected() {
    let line = assert_refused(
        &Case::new(&two_cubes(0.1, 0.05, "")),
        &["bodies[1]", "bodies[0]", "object 'cube'", "0.1500 m"],
    );
    assert!(line.contains("overlaps"), "{line}");
    // A cube sunk 1 cm into a fixed floor (listed first: body 0).
    let sunk = format!(
        "{WORLD}{FLOOR}\n[objects.cube]\n{CUBE}\nmass = 1.0\n\n\
         [[bodies]]\nobject = \"cube\"\nposition = [0.3, 0.0, 0.09]\n"
    );
    assert_refused(
        &Case::new(&sunk),
        &[
            "bodies[1]",
            "object 'cube'",
            "bodies[0] (object 'floor')",
            "0.01000 m",
        ],
    );
}

/// Bodies that touch, or overlap within the contact tolerance (10 µm), are
/// fine: face to face, 5 µm into each other, resting on a floor, and
/// scattered around a fixed post (the scatter's placement keeps clear of
/// it, and of every body placed before it).
#[test]
fn touching_bodies_at_the_start_are_accepted() {
    let post = "
[objects.post]
shape = { box = { half_extents = [0.05, 0.05, 0.5] } }
mass = 1.0

[[bodies]]
object = \"post\"
position = [0.0, 0.3, 0.5]
fixed = true

[[scatter]]
objects = [\"cube\"]
count = 40
min = [-0.4, -0.4, 0.1]
max = [0.4, 0.4, 1.0]
seed = 7
";
    for scene in [
        two_cubes(0.1, 0.2, ""),
        two_cubes(0.1, 0.2 - 5e-6, ""),
        two_cubes(0.1, 0.2, FLOOR).replace("1.0]\n", "0.1]\n"),
        two_cubes(0.05, 0.3, post),
    ] {
        let case = Case::new(&scene);
        let o = case.run(&["--duration", "0.05"]);
        assert_no_panic(&o);
        assert_eq!(o.code, Some(0), "scene:\n{scene}\nstderr:\n{}", o.stderr);
        assert!(case.path("out/summary.json").exists());
    }
}

// ------------------------------------------------ absurd but finite numbers

/// A scene with one cube, its `[[bodies]]` entry ending with `extra`.
fn cube_with(extra: &str) -> String {
    one_object(&format!("{CUBE}\nmass = 1.0")) + extra + "\n"
}

/// Issue 23's absurd numbers, for what accelerates bodies: `gravity =
/// [0, 0, -1e308]` loaded and failed at t = 0 with exit status 3. Gravity,
/// or a force on the body it pushes, above 10⁹ m/s² (10⁸ g) is bad input
/// naming the field; a strong but sane force runs.
#[test]
fn absurd_gravity_and_forces_are_bad_input() {
    let heavy = cube_with("").replace("[world]\n", "[world]\ngravity = [0.0, 0.0, -1e308]\n");
    let line = assert_refused(&Case::new(&heavy), &["world.gravity", "1e9 m/s²"]);
    assert!(!line.contains("numerical failure"), "{line}");
    for (force, field) in [
        ("force = [1e30, 0.0, 0.0]", "forces[0].force"),
        (
            "force = [0.0, 0.0, 0.0]\ntorque = [0.0, 0.0, 1e30]",
            "forces[0].torque",
        ),
    ] {
        let scene = cube_with(&format!("\n[[forces]]\nbody = 0\n{force}\n"));
        let line = assert_refused(&Case::new(&scene), &[field, "1e9 m/s²"]);
        assert!(!line.contains("numerical failure"), "{line}");
    }
    // 1000 N on the 1 kg cube: 10³ m/s², well inside the bound.
    let sane = Case::new(&cube_with(
        "\n[[forces]]\nbody = 0\nforce = [1000.0, 0.0, 0.0]\n",
    ));
    let o = sane.run(&["--duration", "0.02"]);
    assert_eq!(o.code, Some(0), "stderr:\n{}", o.stderr);
}

/// Issue 23: `velocity = [1e308, 0, 0]` loaded, then failed at t = 0 with
/// exit status 3 ("numerical failure … solve_islands"). A speed above the
/// step's own bound (10⁶ m/s), or a spin at which the body's surface would
/// move faster, is bad input naming the field.
#[test]
fn absurd_speed_is_bad_input() {
    for (extra, field) in [
        ("velocity = [1e308, 0.0, 0.0]", "bodies[0].velocity"),
        ("velocity = [0.0, -1.1e6, 0.0]", "bodies[0].velocity"),
        (
            "angular_velocity = [0.0, 0.0, 1e308]",
            "bodies[0].angular_velocity",
        ),
        // |ω| × 0.173 m (the cube's corner) = 1.7e6 m/s.
        (
            "angular_velocity = [1e7, 0.0, 0.0]",
            "bodies[0].angular_velocity",
        ),
        (
            "driven = { velocity = [0.0, 0.0, -1e300] }",
            "bodies[0].driven.velocity",
        ),
    ] {
        let line = assert_refused(&Case::new(&cube_with(extra)), &[field, "1e6 m/s"]);
        assert!(!line.contains("numerical failure"), "{line}");
    }
    let scatter = format!(
        "{WORLD}[objects.cube]\n{CUBE}\nmass = 1.0\n\n[[scatter]]\nobjects = [\"cube\"]\n\
         count = 2\nmin = [-1.0, -1.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nvelocity = [1e20, 0.0, 0.0]\n"
    );
    assert_refused(&Case::new(&scatter), &["scatter[0].velocity", "1e6 m/s"]);
    // Fast but within the bound: runs (a step at 10⁶ m/s itself would end
    // the run, gravity adding to the speed).
    let fast = Case::new(&cube_with("velocity = [5e5, 0.0, 0.0]"));
    let o = fast.run(&["--duration", "0.02"]);
    assert_eq!(o.code, Some(0), "stderr:\n{}", o.stderr);
}

/// A body placed beyond 10⁶ m from the origin on some axis (or a scatter
/// box reaching there) is bad input naming the field.
#[test]
fn absurd_position_is_bad_input() {
    for (extra, field) in [
        ("position = [0.0, 0.0, 1e300]", "bodies[0].position"),
        ("position = [-2e6, 0.0, 0.0]", "bodies[0].position"),
    ] {
        assert_refused(&Case::new(&cube_with(extra)), &[field, "1e6 m"]);
    }
    let scatter = format!(
        "{WORLD}[objects.cube]\n{CUBE}\nmass = 1.0\n\n[[scatter]]\nobjects = [\"cube\"]\n\
         count = 2\nmin = [-1.0, -1.0, 0.0]\nmax = [1.0, 1.0, 1e300]\n"
    );
    assert_refused(&Case::new(&scatter), &["scatter[0].max", "1e6 m"]);
}

/// Masses outside 10⁻¹² to 10¹² kg (given, or from a density) and objects
/// smaller than the contact tolerance or larger than 10⁶ m are bad input
/// naming the field.
#[test]
fn absurd_masses_and_sizes_are_bad_input() {
    for (object, field) in [
        (format!("{CUBE}\nmass = 1e300"), "objects.thing.mass"),
        (format!("{CUBE}\nmass = 1e-300"), "objects.thing.mass"),
        (format!("{CUBE}\ndensity = 1e300"), "objects.thing.density"),
        (
            "shape = { box = { half_extents = [1e200, 1e200, 1e200] } }\nmass = 1.0".into(),
            "objects.thing.shape",
        ),
        (
            "shape = { sphere = { radius = 1e-50 } }\nmass = 1.0".into(),
            "objects.thing.shape",
        ),
    ] {
        assert_refused(
            &Case::new(&one_object(&object)),
            &[field, "must be between"],
        );
    }
}

/// A run that needs more than 10⁹ steps (duration, or max_duration for an
/// until_rest scene, over dt; from the scene or from --duration / --dt) is
/// bad input naming the field or the option, refused at once.
#[test]
fn too_many_steps_is_bad_input() {
    let long = format!("[world]\ndt = 0.01\nduration = 1e8\n[objects.thing]\n{CUBE}\nmass = 1.0\n");
    assert_refused(
        &Case::new(&long),
        &["world.duration", "1.000e10 steps", "1e9"],
    );
    let restless = format!(
        "[world]\ndt = 1e-3\nuntil_rest = true\nmax_duration = 1e300\n[objects.thing]\n{CUBE}\nmass = 1.0\n"
    );
    assert_refused(&Case::new(&restless), &["world.max_duration", "1e9"]);
    let case = Case::new(&cube_with(""));
    for args in [["--duration", "1e12"], ["--dt", "1e-12"]] {
        let o = case.run(&args);
        assert_no_panic(&o);
        assert_eq!(o.code, Some(2), "{args:?}; stderr:\n{}", o.stderr);
        assert!(o.elapsed < QUICK, "took {:?} to refuse", o.elapsed);
        assert_eq!(o.stderr.lines().count(), 1, "stderr:\n{}", o.stderr);
        for name in [case.scene().as_str(), args[0], "1e9"] {
            assert!(
                o.stderr.contains(name),
                "{args:?} does not name {name}: {}",
                o.stderr
            );
        }
        assert!(!case.path("out/summary.json").exists());
    }
}

// ------------------------------------------------------------ fallen bodies

/// A floor 1 m across, 10 cm thick (lowest point z = −0.1 m, so the
/// default fall_z is −1.1 m), a cube resting on it and two cubes dropped
/// beside it.
const BESIDE_THE_FLOOR: &str = "
[world]
dt = 0.01
duration = 1.0

[objects.floor]
shape = { box = { half_extents = [0.5, 0.5, 0.05] } }
mass = 1.0

[objects.cube]
shape = { box = { half_extents = [0.05, 0.05, 0.05] } }
mass = 1.0

[[bodies]]
object = \"floor\"
position = [0.0, 0.0, -0.05]
fixed = true

[[bodies]]
object = \"cube\"
position = [2.0, 0.0, 0.5]

[[bodies]]
object = \"cube\"
position = [-3.0, 0.0, 0.0]

[[bodies]]
object = \"cube\"
position = [0.0, 0.0, 0.05]
";

/// summary.json lists the bodies that fell, each with the simulated time
/// of the step that found it below fall_z, in the order they fell, beside
/// the count `bodies_fallen` it always had. In free fall from z0 the
/// centre is at z0 − g t²/2 (exact to rounding), so body 2 (z0 = 0) passes
/// −1.1 m in step 48 and body 1 (z0 = 0.5 m) in step 58; the cube on the
/// floor never falls. A fallen body's rows in trajectory.csv keep the
/// state it fell with, sample after sample (the README says so).
#[test]
fn fallen_bodies_are_listed_with_their_time() {
    let case = Case::new(BESIDE_THE_FLOOR);
    let o = case.run(&[]);
    assert_no_panic(&o);
    assert_eq!(o.code, Some(0), "stderr:\n{}", o.stderr);
    let text = std::fs::read_to_string(case.path("out/summary.json")).unwrap();
    let s: serde_json::Value = serde_json::from_str(&text).unwrap();
    let step_of = |z0: f64| (1..).find(|&k| z0 - 0.5 * 9.81 * (k as f64 * 0.01).powi(2) < -1.1);
    let (k2, k1) = (step_of(0.0).unwrap(), step_of(0.5).unwrap());
    assert_eq!((k2, k1), (48, 58));
    let expected = serde_json::json!([
        { "body": 2, "time": k2 as f64 * 0.01 },
        { "body": 1, "time": k1 as f64 * 0.01 },
    ]);
    assert_eq!(s["fallen"], expected, "summary: {text}");
    assert_eq!(s["bodies_fallen"], 2);

    let csv = std::fs::read_to_string(case.path("out/trajectory.csv")).unwrap();
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    for (body, k) in [(1.0, k1), (2.0, k2)] {
        let fell = k as f64 * 0.01;
        let mine: Vec<&Vec<f64>> = rows.iter().filter(|r| r[1] == body).collect();
        let at_fall = mine
            .iter()
            .find(|r| (r[0] - fell).abs() < 1e-9)
            .expect("a row at the fall");
        assert!(at_fall[4] < -1.1 && at_fall[11] < 0.0, "row {at_fall:?}");
        for r in mine.iter().filter(|r| r[0] > fell + 1e-9) {
            assert_eq!(r[2..], at_fall[2..], "body {body} moved after it fell");
        }
    }
}

// ------------------------------------------------------------- a good scene

/// A free-falling cube and an off-centre compound (its centre of mass 0.2 m
/// from its shape origin along the body x axis, turned a quarter about z).
const TINY: &str = "
[world]
dt = 0.01
duration = 1.0

[output]
sample_every = 0.02

[objects.cube]
shape = { box = { half_extents = [0.1, 0.1, 0.1] } }
mass = 1.0

[objects.offcentre]
shape = { compound = [
  { shape = { box = { half_extents = [0.1, 0.1, 0.1] } } },
  { shape = { box = { half_extents = [0.2, 0.1, 0.1] } }, position = [0.3, 0.0, 0.0] },
] }
density = 1000.0

[[bodies]]
object = \"cube\"
position = [0.0, 0.0, 1.0]

[[bodies]]
object = \"offcentre\"
position = [1.0, 2.0, 3.0]
orientation = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]
";

const HEADER: &str = "time,body,x,y,z,qw,qx,qy,qz,vx,vy,vz,wx,wy,wz";

fn run_tiny() -> (Case, Vec<Vec<f64>>, serde_json::Value) {
    let case = Case::new(TINY);
    let o = case.run(&["--duration", "0.05"]);
    assert_no_panic(&o);
    assert_eq!(o.code, Some(0), "stderr:\n{}", o.stderr);
    let csv = std::fs::read_to_string(case.path("out/trajectory.csv")).unwrap();
    let mut lines = csv.lines();
    assert_eq!(lines.next(), Some(HEADER));
    let rows: Vec<Vec<f64>> = lines
        .map(|l| {
            let row: Vec<f64> = l.split(',').map(|x| x.parse().unwrap()).collect();
            assert_eq!(row.len(), 15, "row {l}");
            assert!(row.iter().all(|x| x.is_finite()), "row {l}");
            row
        })
        .collect();
    let summary = std::fs::read_to_string(case.path("out/summary.json")).unwrap();
    let summary: serde_json::Value = serde_json::from_str(&summary).unwrap();
    (case, rows, summary)
}

#[test]
fn good_scene_trajectory_has_rows_at_start_every_sample_and_end() {
    let (_case, rows, _) = run_tiny();
    // dt 0.01, samples every 0.02, stopped at 0.05 by --duration.
    let times = [0.0, 0.02, 0.04, 0.05];
    assert_eq!(rows.len(), times.len() * 2, "two bodies per sample");
    for (k, t) in times.iter().enumerate() {
        for body in 0..2 {
            let row = &rows[2 * k + body];
            assert!((row[0] - t).abs() < 1e-12, "row time {} for {t}", row[0]);
            assert_eq!(row[1], body as f64);
        }
    }
    // Free fall: every step adds g dt to the vertical velocity.
    for row in &rows {
        assert!(
            (row[11] + 9.81 * row[0]).abs() < 1e-9,
            "vz {} at t = {}",
            row[11],
            row[0]
        );
    }
}

#[test]
fn trajectory_reports_the_centre_of_mass_not_the_shape_origin() {
    let (_case, rows, _) = run_tiny();
    let expected = [
        [0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0],
        [1.0, 2.2, 3.0, 0.5f64.sqrt(), 0.0, 0.0, 0.5f64.sqrt()],
    ];
    for body in 0..2 {
        let row = &rows[body];
        for (k, want) in expected[body].iter().enumerate() {
            assert!(
                (row[2 + k] - want).abs() < 1e-12,
                "body {body} column {k}: {} != {want}",
                row[2 + k]
            );
        }
    }
}

#[test]
fn good_scene_summary_has_every_field_issue_2_lists() {
    let (_case, _, s) = run_tiny();
    for field in [
        "scene",
        "ranks",
        "bodies",
        "steps",
        "sim_time_s",
        "wall_time_s",
        "frame_interval_s",
        "worst_frame_s",
        "realtime_factor",
        "end_reason",
        "max_penetration_m",
        "energy_initial_j",
        "energy_final_j",
        "stage_seconds",
        "per_rank",
        "state_hash",
    ] {
        assert!(s.get(field).is_some(), "summary.json lacks {field}: {s}");
    }
    assert_eq!(s["scene"], "scene");
    assert_eq!(s["ranks"], 1);
    assert_eq!(s["bodies"], 2);
    assert_eq!(s["steps"], 5);
    assert_eq!(s["end_reason"], "duration");
    let num = |k: &str| {
        s[k].as_f64()
            .unwrap_or_else(|| panic!("{k} is not a number: {s}"))
    };
    assert!((num("sim_time_s") - 0.05).abs() < 1e-12);
    assert!((num("frame_interval_s") - 1.0 / 60.0).abs() < 1e-12);
    let wall = num("wall_time_s");
    assert!(wall > 0.0 && num("worst_frame_s") >= 0.0 && num("worst_frame_s") <= wall);
    assert!(
        (num("realtime_factor") - num("sim_time_s") / wall).abs() <= 1e-9 * num("realtime_factor")
    );
    assert!(num("max_penetration_m") >= 0.0);
    // Potential energy m g z at rest: 1 kg at z = 1 and 24 kg at z = 3.
    let e0 = 9.81 * (1.0 + 24.0 * 3.0);
    assert!(
        (num("energy_initial_j") - e0).abs() < 1e-9 * e0,
        "energy {}",
        num("energy_initial_j")
    );
    assert!(num("energy_final_j").is_finite());

    let stages: BTreeSet<&str> = s["stage_seconds"]
        .as_object()
        .expect("stage_seconds is an object")
        .keys()
        .map(String::as_str)
        .collect();
    let expected: BTreeSet<&str> = [
        "integrate",
        "broadphase",
        "narrowphase",
        "time_of_impact",
        "build_islands",
        "solve_islands",
        "communication",
        "render",
    ]
    .into();
    assert_eq!(stages, expected);
    let per_rank = s["per_rank"].as_array().expect("per_rank is an array");
    assert_eq!(per_rank.len(), 1, "one entry per rank");
    for key in [
        "role",
        "busy_s",
        "waiting_s",
        "tasks",
        "bytes_sent",
        "bytes_received",
    ] {
        assert!(per_rank[0].get(key).is_some(), "per_rank[0] lacks {key}");
    }
    let hash = s["state_hash"].as_str().expect("state_hash is a string");
    assert!(!hash.is_empty());
}

#[test]
fn same_scene_twice_gives_the_same_state_hash() {
    let (_a, rows_a, a) = run_tiny();
    let (_b, rows_b, b) = run_tiny();
    assert_eq!(a["state_hash"], b["state_hash"]);
    assert_eq!(rows_a, rows_b, "trajectories differ between identical runs");
}

/// A trajectory that cannot be written (a full disk: `trajectory.csv` links
/// to /dev/full) ends the run with one line naming the file and the
/// system's reason and a non-zero exit, without a panic or a hang: rows
/// are written on a thread of their own, and its error reaches the run.
#[test]
fn a_full_disk_ends_the_run_naming_the_trajectory() {
    if !Path::new("/dev/full").exists() {
        eprintln!("skipped: no /dev/full here");
        return;
    }
    let case = Case::new(TINY);
    std::fs::create_dir(case.path("out")).unwrap();
    std::os::unix::fs::symlink("/dev/full", case.path("out/trajectory.csv")).unwrap();
    let o = case.run(&["--duration", "0.5"]);
    assert_no_panic(&o);
    assert_ne!(o.code, Some(0), "stderr:\n{}", o.stderr);
    let line = o
        .stderr
        .lines()
        .find(|l| l.starts_with("rigidsim: error:"))
        .unwrap_or_else(|| panic!("no error line:\n{}", o.stderr));
    assert!(
        line.contains("trajectory.csv") && line.contains("No space left"),
        "{line}"
    );
}
