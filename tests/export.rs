//! `rigidsim export SCENE --to FILE` and the subcommand command line
//! (issue 22, item 1): the exported bodies are the ones `run` simulates, in
//! its order, with its masses and shapes; exported vertices placed by the
//! exported pose land where the scene file puts the shape; `run SCENE` and
//! the short form `SCENE` are the same run; a bad scene is refused like
//! `run` refuses it; export needs no mpirun and never starts MPI (it works
//! where MPI cannot start).

use serde_json::Value;
use std::path::Path;
use std::process::{Command, Output, Stdio};

/// Exported coordinates, transformed, against the scene file's (m).
const PLACEMENT_TOL: f64 = 1e-12;

mod common;
use common::{bundled, rigidsim};

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Exports `scene` into `dir` and parses the file.
fn export(scene: &Path, dir: &Path) -> Value {
    let to = dir.join("bodies.json");
    let o = rigidsim(&[
        "export",
        &scene.display().to_string(),
        "--to",
        &to.display().to_string(),
    ]);
    assert_eq!(o.status.code(), Some(0), "stderr:\n{}", stderr(&o));
    serde_json::from_str(&std::fs::read_to_string(&to).unwrap()).unwrap()
}

fn vec3(v: &Value) -> [f64; 3] {
    let a: Vec<f64> = v
        .as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    a.try_into().unwrap()
}

/// `x + R(q) v` with q = [w, x, y, z], computed here, not by nalgebra.
fn place(x: [f64; 3], q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    let [w, qx, qy, qz] = q;
    let r = [
        [
            1.0 - 2.0 * (qy * qy + qz * qz),
            2.0 * (qx * qy - w * qz),
            2.0 * (qx * qz + w * qy),
        ],
        [
            2.0 * (qx * qy + w * qz),
            1.0 - 2.0 * (qx * qx + qz * qz),
            2.0 * (qy * qz - w * qx),
        ],
        [
            2.0 * (qx * qz - w * qy),
            2.0 * (qy * qz + w * qx),
            1.0 - 2.0 * (qx * qx + qy * qy),
        ],
    ];
    [0, 1, 2].map(|i| x[i] + r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
}

/// World positions of every vertex of every part of body `index`, per part.
fn world_parts(export: &Value, index: usize) -> Vec<Vec<[f64; 3]>> {
    let body = &export["bodies"][index];
    let x = vec3(&body["initial"]["position"]);
    let q: Vec<f64> = body["initial"]["orientation"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_f64().unwrap())
        .collect();
    let q: [f64; 4] = q.try_into().unwrap();
    let object = &export["objects"][body["object"].as_u64().unwrap() as usize];
    object["parts"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| {
            p["vertices"]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| place(x, q, vec3(v)))
                .collect()
        })
        .collect()
}

/// Each expected corner is an exported vertex within `PLACEMENT_TOL`, and
/// there are no others.
fn assert_same_points(got: &[[f64; 3]], want: &[[f64; 3]], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: vertex count");
    for w in want {
        let nearest = got
            .iter()
            .map(|g| (0..3).map(|i| (g[i] - w[i]).abs()).fold(0.0, f64::max))
            .fold(f64::INFINITY, f64::min);
        assert!(
            nearest <= PLACEMENT_TOL,
            "{what}: corner {w:?} is {nearest:e} m from the nearest exported vertex"
        );
    }
}

/// The eight corners of a box of half extents `h` centred at `c`, rotated by
/// `q` about the shape origin and moved to `origin`.
fn box_corners(origin: [f64; 3], q: [f64; 4], c: [f64; 3], h: [f64; 3]) -> Vec<[f64; 3]> {
    let mut out = Vec::new();
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                out.push(place(
                    origin,
                    q,
                    [c[0] + sx * h[0], c[1] + sy * h[1], c[2] + sz * h[2]],
                ));
            }
        }
    }
    out
}

#[test]
fn exported_bodies_are_the_simulated_bodies_in_trajectory_order() {
    let dir = tempfile::tempdir().unwrap();
    let scene_path = bundled("nuts_and_bolts.toml");
    let e = export(&scene_path, dir.path());
    assert_eq!(e["format"], 1);
    assert_eq!(e["scene"], "nuts_and_bolts");
    assert_eq!(e["world"]["fall_z"], -1.0);
    assert_eq!(e["world"]["until_rest"], true);
    assert_eq!(e["world"]["duration"], Value::Null);
    assert_eq!(e["world"]["restitution_rule"], "min");
    assert_eq!(e["world"]["friction_rule"], "min");

    // A 0 s run writes the initial state: one row per simulated body.
    let out = dir.path().join("run");
    let o = rigidsim(&[
        &scene_path.display().to_string(),
        "--duration",
        "0",
        "--no-render",
        "--no-progress",
        "--out",
        &out.display().to_string(),
    ]);
    assert_eq!(o.status.code(), Some(0), "stderr:\n{}", stderr(&o));
    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .filter(|r: &Vec<f64>| r[0] == 0.0)
        .collect();
    let bodies = e["bodies"].as_array().unwrap();
    assert_eq!(bodies.len(), 21, "the floor and 20 scattered bodies");
    assert_eq!(bodies.len() as u64, summary["bodies"].as_u64().unwrap());
    assert_eq!(bodies.len(), rows.len());

    // The library's own load of the scene: masses and shapes as simulated.
    let scene = rigidsim::scene::load(&scene_path).unwrap();
    for (i, (b, row)) in bodies.iter().zip(&rows).enumerate() {
        assert_eq!(b["index"], i);
        assert_eq!(row[1], i as f64);
        let object = &scene.objects[scene.bodies[i].object.0 as usize];
        assert_eq!(b["object_name"], object.name.as_str());
        assert_eq!(b["mass"].as_f64().unwrap(), object.mass, "body {i} mass");
        let exported = &e["objects"][b["object"].as_u64().unwrap() as usize];
        assert_eq!(exported["name"], object.name.as_str());
        let parts = exported["parts"].as_array().unwrap();
        assert_eq!(parts.len(), object.parts.len(), "body {i} part count");
        for (p, part) in parts.iter().zip(&object.parts) {
            assert_eq!(
                p["vertices"].as_array().unwrap().len(),
                part.hull.vertex_count()
            );
            assert_eq!(p["faces"].as_array().unwrap().len(), part.hull.face_count());
        }
        // Bit for bit the state the trajectory starts from (both round-trip).
        let initial = &b["initial"];
        let state: Vec<f64> = ["position", "orientation", "velocity", "angular_velocity"]
            .iter()
            .flat_map(|k| initial[k].as_array().unwrap().clone())
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(
            state,
            row[2..],
            "body {i}: exported state against trajectory row"
        );
    }
    assert_eq!(bodies[0]["kind"], "fixed");
    assert_eq!(bodies[0]["mass"], 1.0);
    assert!(bodies[1..].iter().all(|b| b["kind"] == "dynamic"));
}

#[test]
fn exported_vertices_placed_by_the_exported_pose_give_the_scene_corners() {
    let dir = tempfile::tempdir().unwrap();
    let e = export(&bundled("bouncing_cube.toml"), dir.path());
    // bouncing_cube: the floor (half extents 1, 1, 0.1) at z = -0.1, the cube
    // (half extents 0.05) at z = 1.05, both unrotated.
    let id = [1.0, 0.0, 0.0, 0.0];
    let floor = box_corners([0.0, 0.0, -0.1], id, [0.0; 3], [1.0, 1.0, 0.1]);
    let cube = box_corners([0.0, 0.0, 1.05], id, [0.0; 3], [0.05; 3]);
    assert_same_points(&world_parts(&e, 0)[0], &floor, "floor");
    assert_same_points(&world_parts(&e, 1)[0], &cube, "cube");

    // A rotated compound whose centre of mass is far from its shape origin:
    // the body frame is the centre of mass, the scene places the origin.
    let q = [0.8, 0.2, -0.4, 0.4]; // unit: 0.64 + 0.04 + 0.16 + 0.16
    let origin = [0.3, -1.2, 2.0];
    let scene = format!(
        "[world]\ndt = 0.01\nduration = 1.0\n\n\
         [objects.hammer]\n\
         shape = {{ compound = [\n  \
           {{ shape = {{ box = {{ half_extents = [0.1, 0.2, 0.3] }} }}, position = [0.5, 0.0, 0.0] }},\n  \
           {{ shape = {{ box = {{ half_extents = [0.05, 0.05, 0.4] }} }}, position = [-0.2, 0.1, 0.0] }},\n\
         ] }}\n\
         density = 1000.0\nrestitution = 0.5\nfriction = 0.4\n\n\
         [[bodies]]\nobject = \"hammer\"\nposition = {origin:?}\norientation = {q:?}\n"
    );
    let path = dir.path().join("hammer.toml");
    std::fs::write(&path, scene).unwrap();
    let e = export(&path, dir.path());
    let parts = world_parts(&e, 0);
    assert_eq!(parts.len(), 2);
    assert_same_points(
        &parts[0],
        &box_corners(origin, q, [0.5, 0.0, 0.0], [0.1, 0.2, 0.3]),
        "hammer head",
    );
    assert_same_points(
        &parts[1],
        &box_corners(origin, q, [-0.2, 0.1, 0.0], [0.05, 0.05, 0.4]),
        "hammer handle",
    );
    // The shape origin sits at −(centre of mass) in the body frame: the
    // volume-weighted centre of the two boxes.
    let (va, vb) = (0.2 * 0.4 * 0.6, 0.1 * 0.1 * 0.8);
    let com = [0.5 * va - 0.2 * vb, 0.1 * vb, 0.0].map(|c| c / (va + vb));
    let origin_body = vec3(&e["objects"][0]["shape_origin"]);
    for k in 0..3 {
        assert!(
            (origin_body[k] + com[k]).abs() < PLACEMENT_TOL,
            "shape_origin {origin_body:?}"
        );
    }
    let b = &e["bodies"][0];
    assert_eq!(b["kind"], "dynamic");
    assert_eq!(b["driven"], Value::Null);
    assert_eq!(b["restitution"], 0.5);
    assert_eq!(b["friction"], 0.4);
    assert!((b["mass"].as_f64().unwrap() - 1000.0 * (va + vb)).abs() < 1e-9);
    // No fixed body and no fall_z: no cut-off, written as null.
    assert_eq!(e["world"]["fall_z"], Value::Null);
}

#[test]
fn exported_faces_run_counter_clockwise_seen_from_outside() {
    let dir = tempfile::tempdir().unwrap();
    let e = export(&bundled("bouncing_cube.toml"), dir.path());
    let part = &e["objects"][0]["parts"][0];
    let verts: Vec<[f64; 3]> = part["vertices"]
        .as_array()
        .unwrap()
        .iter()
        .map(vec3)
        .collect();
    let faces = part["faces"].as_array().unwrap();
    assert_eq!(faces.len(), 6, "a box has six merged faces");
    for f in faces {
        let loop_: Vec<usize> = f
            .as_array()
            .unwrap()
            .iter()
            .map(|i| i.as_u64().unwrap() as usize)
            .collect();
        // Newell's normal of the loop points away from the centre of mass (the origin).
        let mut n = [0.0; 3];
        for k in 0..loop_.len() {
            let (a, b) = (verts[loop_[k]], verts[loop_[(k + 1) % loop_.len()]]);
            n[0] += (a[1] - b[1]) * (a[2] + b[2]);
            n[1] += (a[2] - b[2]) * (a[0] + b[0]);
            n[2] += (a[0] - b[0]) * (a[1] + b[1]);
        }
        let a = verts[loop_[0]];
        assert!(
            n[0] * a[0] + n[1] * a[1] + n[2] * a[2] > 0.0,
            "face {loop_:?} is wound inward"
        );
    }
}

#[test]
fn run_subcommand_and_short_form_are_the_same_run() {
    let dir = tempfile::tempdir().unwrap();
    let scene = bundled("resting_stack.toml").display().to_string();
    let hash = |args: &[&str], out: &str| {
        let out = dir.path().join(out).display().to_string();
        let mut all = args.to_vec();
        all.extend([
            scene.as_str(),
            "--duration",
            "0.1",
            "--no-render",
            "--no-progress",
            "--out",
            &out,
        ]);
        let o = rigidsim(&all);
        assert_eq!(o.status.code(), Some(0), "{all:?}; stderr:\n{}", stderr(&o));
        let s: Value = serde_json::from_str(
            &std::fs::read_to_string(Path::new(&out).join("summary.json")).unwrap(),
        )
        .unwrap();
        (s["state_hash"].clone(), s["steps"].clone())
    };
    let long = hash(&["run"], "run");
    let short = hash(&[], "short");
    assert!(
        long.0.is_string() || long.0.is_u64(),
        "state_hash {}",
        long.0
    );
    assert_eq!(long, short);
}

#[test]
fn export_of_a_bad_scene_exits_2_with_one_line_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.toml");
    std::fs::write(
        &path,
        "[world]\ndt = 0.01\nduration = 1.0\n\n[[bodies]]\nobject = \"nothing\"\n",
    )
    .unwrap();
    let to = dir.path().join("bodies.json");
    let (p, t) = (path.display().to_string(), to.display().to_string());
    let export = rigidsim(&["export", &p, "--to", &t]);
    let err = stderr(&export);
    assert_eq!(export.status.code(), Some(2), "stderr:\n{err}");
    assert_eq!(err.lines().count(), 1, "stderr:\n{err}");
    assert!(err.contains(&p), "does not name the file: {err}");
    assert!(
        err.contains("bodies[0].object"),
        "does not name the field: {err}"
    );
    assert!(!to.exists(), "a JSON file was written for a bad scene");
    // The very line `run` gives.
    let run = rigidsim(&[
        &p,
        "--no-progress",
        "--out",
        &dir.path().join("out").display().to_string(),
    ]);
    assert_eq!(run.status.code(), Some(2));
    assert_eq!(stderr(&run), err);
}

/// Open MPI's `MPI_Init` aborts when asked for a messaging layer that does
/// not exist: under this setting any MPI initialisation fails.
const BREAK_MPI: (&str, &str) = ("OMPI_MCA_pml", "no_such_pml");

#[test]
fn export_needs_neither_mpirun_nor_mpi() {
    let dir = tempfile::tempdir().unwrap();
    let scene = bundled("bouncing_cube.toml").display().to_string();
    // Control: `run` initialises MPI, so under BREAK_MPI it fails.
    let out = dir.path().join("out").display().to_string();
    let run = Command::new(env!("CARGO_BIN_EXE_rigidsim"))
        .args([
            &scene,
            "--duration",
            "0",
            "--no-render",
            "--no-progress",
            "--out",
            &out,
        ])
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env(BREAK_MPI.0, BREAK_MPI.1)
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert_ne!(
        run.status.code(),
        Some(0),
        "{}={} did not stop MPI from starting (is this Open MPI?), so it proves nothing here",
        BREAK_MPI.0,
        BREAK_MPI.1
    );
    // Export, run directly (no mpirun), under the same setting, and without
    // the variables Open MPI wants for root: it never initialises MPI.
    let to = dir.path().join("nested/bodies.json");
    let o = Command::new(env!("CARGO_BIN_EXE_rigidsim"))
        .args(["export", &scene, "--to"])
        .arg(&to)
        .env(BREAK_MPI.0, BREAK_MPI.1)
        .env_remove("OMPI_ALLOW_RUN_AS_ROOT")
        .env_remove("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(0), "stderr:\n{}", stderr(&o));
    assert!(o.stderr.is_empty(), "stderr:\n{}", stderr(&o));
    let e: Value = serde_json::from_str(&std::fs::read_to_string(&to).unwrap()).unwrap();
    assert_eq!(e["bodies"].as_array().unwrap().len(), 2);
}

#[test]
fn help_lists_the_subcommands_and_run_help_the_run_options() {
    let top = rigidsim(&["--help"]);
    assert_eq!(top.status.code(), Some(0));
    let text = String::from_utf8_lossy(&top.stdout);
    for word in ["run", "export"] {
        assert!(
            text.lines().any(|l| l.trim_start().starts_with(word)),
            "--help lacks {word}:\n{text}"
        );
    }
    let run = rigidsim(&["run", "--help"]);
    assert_eq!(run.status.code(), Some(0));
    let text = String::from_utf8_lossy(&run.stdout);
    for option in [
        "--out",
        "--duration",
        "--no-render",
        "--resume",
        "--slow-rank",
    ] {
        assert!(text.contains(option), "run --help lacks {option}:\n{text}");
    }
    let export = rigidsim(&["export", "--help"]);
    assert!(String::from_utf8_lossy(&export.stdout).contains("--to"));
}
