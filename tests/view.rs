//! `rigidsim view SCENE OUT_DIR [--serve PORT]` (issue 24): the page embeds
//! the run it was written from (its samples, the body positions to f32, the
//! energies `summary.json` reports), refuses with one line and exit status 2
//! every folder not written from that scene as it is now, never panics,
//! serves the page on loopback, and starts no MPI. What the page draws is
//! checked in a real browser by viewer/test/replay_in_chromium.mjs
//! (scripts/test.sh).

use base64::Engine;
use serde_json::Value;
use std::io::{BufRead, Read, Write};
use std::path::Path;
use std::process::{Command, Output, Stdio};

/// Energies recomputed from the trajectory against `summary.json`'s (J,
/// relative): the same terms, ω instead of L, so rounding only.
const ENERGY_TOL: f64 = 1e-9;

mod common;
// `common::rigidsim` sets Open MPI's root variables, even for `run` alone;
// `view` must not need them, so `view` calls go through `rigidsim_bare`.
use common::{bundled, rigidsim};

/// A component Open MPI cannot load: `run` fails to start MPI under it.
const BREAK_MPI: (&str, &str) = ("OMPI_MCA_pml", "no_such_pml");

fn rigidsim_bare(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rigidsim"))
        .args(args)
        .env(BREAK_MPI.0, BREAK_MPI.1)
        .env_remove("OMPI_ALLOW_RUN_AS_ROOT")
        .env_remove("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM")
        .stdin(Stdio::null())
        .output()
        .expect("cannot start rigidsim")
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// Runs `scene` alone for `duration` s into `out`.
fn run(scene: &Path, out: &Path, duration: &str) {
    let o = rigidsim(&[
        &scene.display().to_string(),
        "--duration",
        duration,
        "--no-render",
        "--no-progress",
        "--out",
        &out.display().to_string(),
    ]);
    assert_eq!(o.status.code(), Some(0), "run failed:\n{}", text(&o.stderr));
}

fn view(scene: &Path, out: &Path) -> Output {
    rigidsim_bare(&[
        "view",
        &scene.display().to_string(),
        &out.display().to_string(),
    ])
}

/// The text between `start` and the next `</script>` of the page.
fn script_text<'a>(page: &'a str, start: &str) -> &'a str {
    let from = page.find(start).unwrap_or_else(|| panic!("no {start}")) + start.len();
    &page[from..from + page[from..].find("</script>").unwrap()]
}

#[test]
fn a_replay_embeds_the_run_it_was_written_from() {
    let dir = tempfile::tempdir().unwrap();
    let scene = bundled("render_check.toml");
    let out = dir.path().join("out");
    run(&scene, &out, "0.5");

    let o = view(&scene, &out);
    assert_eq!(
        o.status.code(),
        Some(0),
        "view failed:\n{}",
        text(&o.stderr)
    );
    let page_path = out.join("replay.html");
    assert_eq!(text(&o.stdout).trim(), page_path.display().to_string());
    let page = std::fs::read_to_string(&page_path).unwrap();

    let summary: Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let csv = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    let rows: Vec<Vec<f64>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    let bodies = summary["bodies"].as_u64().unwrap() as usize;
    let samples = rows.len() / bodies;

    let header: Value = serde_json::from_str(script_text(
        &page,
        r#"<script id="replay-header" type="application/json">"#,
    ))
    .unwrap();
    assert_eq!(header["samples"].as_u64().unwrap() as usize, samples);
    assert_eq!(header["sim_time_s"], summary["sim_time_s"]);
    let energy = |k: usize| {
        header["kinetic_j"][k].as_f64().unwrap() + header["potential_j"][k].as_f64().unwrap()
    };
    for (k, field) in [(0, "energy_initial_j"), (samples - 1, "energy_final_j")] {
        let want = summary[field].as_f64().unwrap();
        assert!(
            (energy(k) - want).abs() <= ENERGY_TOL * want.abs().max(1.0),
            "sample {k}: kinetic + potential {} J, summary.json's {field} {want} J",
            energy(k)
        );
    }

    // Every body's position at every sample, as the page will read it.
    let data = base64::engine::general_purpose::STANDARD
        .decode(script_text(
            &page,
            r#"<script id="replay-data" type="application/octet-stream">"#,
        ))
        .unwrap();
    let at = |slice: &Value| slice["offset"].as_u64().unwrap() as usize;
    let times = at(&header["times"]);
    let positions = at(&header["positions"]);
    for (r, row) in rows.iter().enumerate() {
        let k = r / bodies;
        let time = f64::from_le_bytes(data[times + 8 * k..][..8].try_into().unwrap());
        assert_eq!(time, row[0]);
        for axis in 0..3 {
            let i = positions + 4 * (3 * r + axis);
            let p = f32::from_le_bytes(data[i..i + 4].try_into().unwrap());
            assert_eq!(p, row[2 + axis] as f32, "row {r} axis {axis}");
        }
    }
    // The viewer's script is inlined, and nothing names a place to fetch from.
    assert!(page.contains("rigidsimReplay"));
    for fetch in ["<script src", "<link", "import(", "@import"] {
        assert!(!page.contains(fetch), "the page contains {fetch}");
    }
}

/// Asserts `o` is a refusal: exit status 2, one line on stderr that names
/// `what`, no panic.
fn assert_refused(o: &Output, what: &str) {
    let err = text(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "stderr:\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "not one line:\n{err}");
    assert!(err.starts_with("rigidsim: error: "), "{err}");
    assert!(err.contains(what), "'{what}' not in: {err}");
}

#[test]
fn a_folder_written_from_another_scene_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cube");
    run(&bundled("bouncing_cube.toml"), &out, "0.2");
    let o = view(&bundled("render_check.toml"), &out);
    assert_refused(&o, "was not written from");
    assert_refused(&o, "bouncing_cube.toml");
    assert!(!out.join("replay.html").exists());
}

#[test]
fn a_folder_written_from_an_earlier_version_of_the_scene_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("drop.toml");
    std::fs::copy(bundled("render_check.toml"), &scene).unwrap();
    let out = dir.path().join("out");
    run(&scene, &out, "0.1");
    assert_eq!(view(&scene, &out).status.code(), Some(0));
    let mut edited = std::fs::read_to_string(&scene).unwrap();
    edited.push_str("# edited after the run\n");
    std::fs::write(&scene, edited).unwrap();
    assert_refused(&view(&scene, &out), "as it is now");
}

#[test]
fn folders_that_are_not_a_finished_run_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let scene = bundled("render_check.toml");
    let out = dir.path().join("out");
    assert_refused(&view(&scene, &out), "no such output folder");
    std::fs::create_dir_all(&out).unwrap();
    assert_refused(&view(&scene, &out), "has no summary.json");
    std::fs::write(out.join("summary.json"), "{ not json").unwrap();
    assert_refused(&view(&scene, &out), "not a rigidsim summary");

    run(&scene, &out, "0.1");
    let summary_path = out.join("summary.json");
    let summary = std::fs::read_to_string(&summary_path).unwrap();
    let mut older: Value = serde_json::from_str(&summary).unwrap();
    older.as_object_mut().unwrap().remove("scene_digest");
    std::fs::write(&summary_path, older.to_string()).unwrap();
    assert_refused(&view(&scene, &out), "does not record the scene");
    std::fs::write(&summary_path, &summary).unwrap();

    let trajectory_path = out.join("trajectory.csv");
    let trajectory = std::fs::read_to_string(&trajectory_path).unwrap();
    let cut = &trajectory[..trajectory.len() - trajectory.lines().last().unwrap().len() - 1];
    for (bad, what) in [
        (String::new(), "the header is not"),
        (cut.to_string(), "cut short"),
        (
            trajectory.replace(",1,", ",7,"),
            "not a trajectory of this scene",
        ),
        (trajectory.replacen("0.45", "NaN", 1), "not a finite number"),
    ] {
        std::fs::write(&trajectory_path, bad).unwrap();
        assert_refused(&view(&scene, &out), what);
    }
    std::fs::remove_file(&trajectory_path).unwrap();
    assert_refused(&view(&scene, &out), "trajectory.csv: cannot read");
}

#[test]
fn a_bad_scene_is_refused_as_run_refuses_it() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("broken.toml");
    std::fs::write(&scene, "[world]\ndt = -1.0\n").unwrap();
    let o = view(&scene, dir.path());
    assert_refused(&o, "broken.toml");
}

/// `--serve 0`: the page, byte for byte, at http://127.0.0.1:PORT/.
#[test]
fn serve_answers_with_the_page_on_loopback() {
    let dir = tempfile::tempdir().unwrap();
    let scene = bundled("render_check.toml");
    let out = dir.path().join("out");
    run(&scene, &out, "0.1");
    let mut child = Command::new(env!("CARGO_BIN_EXE_rigidsim"))
        .args([
            "view",
            &scene.display().to_string(),
            &out.display().to_string(),
            "--serve",
            "0",
        ])
        .env(BREAK_MPI.0, BREAK_MPI.1)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut lines = std::io::BufReader::new(child.stdout.take().unwrap()).lines();
    let page_path = lines.next().unwrap().unwrap();
    let serving = lines.next().unwrap().unwrap();
    let address = serving
        .split_whitespace()
        .find(|w| w.starts_with("http://127.0.0.1:"))
        .unwrap_or_else(|| panic!("no address in: {serving}"));
    let port: u16 = address["http://127.0.0.1:".len()..]
        .trim_end_matches('/')
        .parse()
        .unwrap();
    let get = |path: &str| {
        let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
        write!(s, "GET {path} HTTP/1.1\r\nHost: localhost\r\n\r\n").unwrap();
        let mut response = Vec::new();
        s.read_to_end(&mut response).unwrap();
        let split = response.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
        (text(&response[..split]), response[split + 4..].to_vec())
    };
    let (head, body) = get("/");
    let (missing, _) = get("/elsewhere");
    let _ = child.kill();
    let _ = child.wait();
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    assert_eq!(body, std::fs::read(&page_path).unwrap());
    assert!(missing.starts_with("HTTP/1.1 404"), "{missing}");
}
