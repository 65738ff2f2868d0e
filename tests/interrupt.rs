//! Ctrl-C keeps the work (issue 54, item 6): SIGINT or SIGTERM on a run,
//! alone or to `mpirun`, ends it at a step boundary with the trajectory's
//! last sample complete, `summary.json` saying `end_reason =
//! "interrupted"`, and a checkpoint that `--resume` continues from to the
//! very state an uninterrupted run reaches; the exit status is the shell's
//! for the signal (130, 143).

mod common;

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Child, ExitStatus};
use std::time::{Duration, Instant};

/// Four cubes tumbling on a floor at a small step, so a run takes real
/// time and (with `--no-sleep`) never ends by itself before it is signalled.
fn scene_in(_dir: &Path) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/tumbling_cubes.toml")
}

fn mpirun() -> PathBuf {
    std::env::var_os("PATH")
        .and_then(|paths| {
            std::env::split_paths(&paths)
                .map(|d| d.join("mpirun"))
                .find(|p| p.is_file())
        })
        .expect("mpirun is not on PATH: run scripts/setup.sh")
}

/// Starts `rigidsim run SCENE --out OUT --no-sleep --no-progress` (under
/// `mpirun -np N` when `np` is given), logs next to `out`.
fn start(np: Option<u32>, scene: &Path, out: &Path, extra: &[&str]) -> Child {
    let bin = env!("CARGO_BIN_EXE_rigidsim");
    let mut cmd = match np {
        None => common::command(bin),
        Some(np) => {
            let mut c = common::command(mpirun().to_str().unwrap());
            c.args(["--oversubscribe", "-np", &np.to_string(), bin]);
            c
        }
    };
    cmd.arg("run")
        .arg(scene)
        .arg("--out")
        .arg(out)
        .args(["--no-sleep", "--no-progress", "--no-render"])
        .args(extra)
        .env("NODEVICE_SELECT", "1")
        .stdout(std::fs::File::create(out.with_extension("stdout")).unwrap())
        .stderr(std::fs::File::create(out.with_extension("stderr")).unwrap());
    cmd.spawn().expect("cannot start rigidsim")
}

fn signal(child: &Child, sig: i32) {
    // SAFETY: kill(2) on the pid of a child this test started and has not
    // yet reaped.
    let rc = unsafe { libc::kill(child.id() as libc::pid_t, sig) };
    assert_eq!(rc, 0, "kill({}, {sig})", child.id());
}

fn wait(child: &mut Child, limit: Duration) -> ExitStatus {
    let until = Instant::now() + limit;
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            return s;
        }
        if Instant::now() > until {
            let _ = child.kill();
            let _ = child.wait();
            panic!("still running {limit:?} after the signal");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn summary(out: &Path) -> Value {
    let text = std::fs::read_to_string(out.join("summary.json")).unwrap_or_else(|e| {
        panic!(
            "no summary.json in {}: {e}; stderr: {}",
            out.display(),
            std::fs::read_to_string(out.with_extension("stderr")).unwrap_or_default()
        )
    });
    serde_json::from_str(&text).unwrap()
}

/// The trajectory ends with a whole sample at the summary's time: every
/// body's row, each of 15 numbers, and a final newline.
fn assert_last_sample_complete(out: &Path, bodies: usize, sim_time: f64) {
    let text = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    assert!(text.ends_with('\n'), "trajectory.csv ends inside a row");
    let last: Vec<&str> = text.lines().rev().take(bodies).collect();
    for (k, row) in last.iter().enumerate() {
        let fields: Vec<f64> = row.split(',').map(|f| f.parse().unwrap()).collect();
        assert_eq!(fields.len(), 15, "row {row}");
        assert_eq!(fields[0], sim_time, "last sample's time");
        assert_eq!(
            fields[1] as usize,
            bodies - 1 - k,
            "bodies of the last sample"
        );
    }
}

/// A signal, then the checks common to one rank and mpirun: the run ended
/// at a step boundary with everything written; returns its summary.
fn interrupt(np: Option<u32>, sig: i32, dir: &Path, name: &str) -> (ExitStatus, Value, PathBuf) {
    let scene = scene_in(dir);
    let out = dir.join(name);
    let mut child = start(np, &scene, &out, &[]);
    // Long enough for MPI to start and the run to take steps.
    std::thread::sleep(Duration::from_millis(2500));
    signal(&child, sig);
    let status = wait(&mut child, Duration::from_secs(20));
    let s = summary(&out);
    assert_eq!(s["end_reason"], "interrupted", "{s}");
    let steps = s["steps"].as_u64().unwrap();
    assert!(steps > 0, "no step taken before the signal");
    assert_last_sample_complete(&out, 5, s["sim_time_s"].as_f64().unwrap());
    assert!(out.join("checkpoint.bin").is_file(), "no checkpoint.bin");
    (status, s, out)
}

#[test]
fn ctrl_c_keeps_a_resumable_run_and_exits_130() {
    let dir = tempfile::tempdir().unwrap();
    let (status, s, out) = interrupt(None, libc::SIGINT, dir.path(), "ctrl_c");
    assert_eq!(status.code(), Some(130), "{status:?}");
    assert!(
        s["notes"]
            .as_array()
            .unwrap()
            .iter()
            .any(|n| n.as_str().unwrap().contains("last checkpoint")),
        "{s}"
    );

    // Resumed 50 steps further, it ends where a run never interrupted does.
    let steps = s["steps"].as_u64().unwrap();
    let until = format!("{}", (steps + 50) as f64 * 0.001);
    let scene = scene_in(dir.path());
    let common = ["--no-sleep", "--no-progress", "--duration", &until];
    let resumed = common::rigidsim(
        &[
            &[
                "run",
                scene.to_str().unwrap(),
                "--out",
                out.to_str().unwrap(),
            ][..],
            &common[..],
            &["--resume", out.join("checkpoint.bin").to_str().unwrap()][..],
        ]
        .concat(),
    );
    assert!(resumed.status.success(), "{resumed:?}");
    let straight_out = dir.path().join("straight");
    let straight = common::rigidsim(
        &[
            &[
                "run",
                scene.to_str().unwrap(),
                "--out",
                straight_out.to_str().unwrap(),
            ][..],
            &common[..],
        ]
        .concat(),
    );
    assert!(straight.status.success(), "{straight:?}");
    let (a, b) = (summary(&out), summary(&straight_out));
    assert_eq!(a["steps"], b["steps"]);
    assert_eq!(a["state_hash"], b["state_hash"], "resumed ≠ uninterrupted");
    // The resumed trajectory is the uninterrupted one, byte for byte.
    assert_eq!(
        std::fs::read(out.join("trajectory.csv")).unwrap(),
        std::fs::read(straight_out.join("trajectory.csv")).unwrap()
    );
}

#[test]
fn sigterm_keeps_the_run_and_exits_143() {
    let dir = tempfile::tempdir().unwrap();
    let (status, _, _) = interrupt(None, libc::SIGTERM, dir.path(), "term");
    assert_eq!(status.code(), Some(143), "{status:?}");
}

/// Ctrl-C to `mpirun`: it signals every rank; the workers keep answering
/// rank 0, which ends the run and writes every output of both ranks.
#[test]
fn ctrl_c_to_mpirun_keeps_the_run_of_every_rank() {
    let dir = tempfile::tempdir().unwrap();
    let (status, s, _) = interrupt(Some(2), libc::SIGINT, dir.path(), "mpi");
    assert!(!status.success(), "{status:?}");
    assert_eq!(s["per_rank"].as_array().unwrap().len(), 2, "{s}");
}

/// A second Ctrl-C does not wait for the step under way: the process ends
/// at once, with the same status and without a summary. The scene is the
/// 300-body pour (`scripts/crowd.sh`'s `crowd_of 300`), whose steps take
/// tens of milliseconds while it pours, far longer than the 5 ms between
/// the signals.
#[test]
fn a_second_ctrl_c_ends_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let thesis = std::fs::read_to_string(common::bundled("nuts_and_bolts.toml")).unwrap();
    let pour: String = thesis
        .split_inclusive('\n')
        .take_while(|l| !l.starts_with("[render]"))
        .map(|l| match l.split_whitespace().next() {
            Some("count") => "count = 300\n",
            _ => l,
        })
        .collect();
    let scene = dir.path().join("pour300.toml");
    std::fs::write(&scene, pour).unwrap();
    let out = dir.path().join("twice");
    let mut child = start(None, &scene, &out, &[]);
    std::thread::sleep(Duration::from_millis(2500));
    signal(&child, libc::SIGINT);
    std::thread::sleep(Duration::from_millis(5));
    signal(&child, libc::SIGINT);
    let status = wait(&mut child, Duration::from_secs(20));
    assert_eq!(status.code(), Some(130), "{status:?}");
    assert!(
        !out.join("summary.json").exists(),
        "the second Ctrl-C waited for the outputs"
    );
}
