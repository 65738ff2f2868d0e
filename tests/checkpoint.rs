//! Checkpoints and runs that survive faults (issue 8).
//!
//! A run resumed from a checkpoint ends with the same `state_hash` (the exact
//! bits of every body) as an uninterrupted one: in the library at several
//! moments (in flight, in contact, resting, after a wake), and through the
//! binary across a change of rank count (1 → 2 and 2 → 1 under `mpirun`) and
//! after a `kill -9`. A checkpoint of another scene, another dt or another
//! `--no-sleep` is refused with a message that says which; a damaged file is
//! an error, never a panic. A numerical failure keeps the last good
//! checkpoint, a trajectory of complete, finite lines, and a summary with
//! `end_reason = "failed"` naming the body, the stage and the time. A
//! resumed run with rendering ends with a `video.mp4` of the whole run.

mod common;

use proptest::prelude::*;
use rigidsim::output::checkpoint::{Checkpoint, FILE_NAME};
use rigidsim::scene::{self, Scene};
use rigidsim::step::{Inline, World};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_rigidsim");

/// Everything the checkpoint must carry: a pile of nuts and bolts falling on
/// a floor (contacts, cached V-Clip features, resting systems), a stack of
/// three boxes that rests until a late box lands on it (sleep timers and
/// groups, wakes), a driven paddle (a body state that is not integrated) and
/// a force window that starts mid-run.
const SCENE: &str = r#"
[world]
dt = 0.01
duration = 3.0

[objects.floor]
shape = { box = { half_extents = [1.0, 1.0, 0.1] } }
mass = 1.0
restitution = 0.5
friction = 0.5

[objects.nut]
shape = { nut = {} }
density = 7850.0
restitution = 0.6
friction = 0.5

[objects.bolt]
shape = { bolt = {} }
density = 7850.0
restitution = 0.6
friction = 0.5

[objects.cube]
shape = { box = { half_extents = [0.05, 0.05, 0.05] } }
mass = 1.0
restitution = 0.2
friction = 0.6

[objects.paddle]
shape = { box = { half_extents = [0.02, 0.2, 0.05] } }
mass = 1.0
restitution = 0.3
friction = 0.3

[[bodies]]
object = "floor"
position = [0.0, 0.0, -0.1]
fixed = true

[[bodies]]
object = "cube"
position = [0.6, 0.6, 0.05]
[[bodies]]
object = "cube"
position = [0.6, 0.6, 0.15]
[[bodies]]
object = "cube"
position = [0.6, 0.6, 0.25]
# Lands on the stack at t ≈ 1.9 s and wakes it.
[[bodies]]
object = "cube"
position = [0.6, 0.6, 18.0]

[[bodies]]
object = "paddle"
position = [-0.6, -0.1, 0.05]
driven = { velocity = [0.0, 0.2, 0.0] }

[[bodies]]
object = "cube"
position = [-0.6, 0.6, 0.05]

[[forces]]
body = 6
force = [10.0, 0.0, 0.0]
start = 1.2
end = 1.5

[[scatter]]
objects = ["nut", "bolt"]
count = 16
min = [-0.25, -0.25, 0.05]
max = [0.25, 0.25, 0.5]
seed = 3
"#;

fn load(text: &str) -> Scene {
    scene::from_str(text, Path::new("checkpointed.toml"), Path::new("."))
        .unwrap_or_else(|e| panic!("{e}"))
}

fn run_to(w: &mut World, exec: &mut Inline, steps: u64) {
    while w.state.steps < steps {
        w.step(exec)
            .unwrap_or_else(|e| panic!("{e} (at step {})", w.state.steps));
    }
}

/// Checkpoints taken at several moments, written to bytes, read back and
/// restored into a freshly loaded scene, continue to the very same bits as
/// the run that was never stopped: state hash, activity, counters.
#[test]
fn resumed_world_ends_with_the_same_state_hash() {
    let end = 300;
    let mut reference = World::new(load(SCENE));
    let mut exec = Inline::default();
    let mut checkpoints = Vec::new();
    let stops = [1u64, 7, 40, 110, 150, 185, 200, 260];
    for &k in &stops {
        run_to(&mut reference, &mut exec, k);
        checkpoints.push((k, reference.checkpoint().to_bytes()));
    }
    run_to(&mut reference, &mut exec, end);
    // The scene must exercise what the checkpoint carries.
    assert!(reference.diagnostics.counters.wakes > 0, "nothing woke up");
    assert!(reference.diagnostics.counters.toi_events > 0);
    let sleeping_somewhere = checkpoints.iter().any(|(_, bytes)| {
        let ck = Checkpoint::from_bytes(bytes, Path::new("mem")).unwrap();
        ck.bodies
            .iter()
            .any(|b| b.activity == rigidsim::body::Activity::Sleeping)
    });
    assert!(sleeping_somewhere, "no checkpoint holds a resting body");

    for (k, bytes) in &checkpoints {
        let ck = Checkpoint::from_bytes(bytes, Path::new("mem")).unwrap();
        assert_eq!(ck.steps, *k);
        let mut resumed = World::restore(load(SCENE), ck).unwrap_or_else(|e| panic!("{e}"));
        // What restore rebuilt writes back to the very same bytes.
        assert_eq!(&resumed.checkpoint().to_bytes(), bytes, "step {k}");
        run_to(&mut resumed, &mut Inline::default(), end);
        assert_eq!(
            resumed.state_hash(),
            reference.state_hash(),
            "resumed at step {k}"
        );
        for (i, (a, b)) in resumed
            .state
            .bodies
            .iter()
            .zip(&reference.state.bodies)
            .enumerate()
        {
            assert_eq!(a.activity, b.activity, "body {i}, resumed at step {k}");
        }
        assert_eq!(
            resumed.diagnostics.counters.steps,
            reference.diagnostics.counters.steps
        );
        assert_eq!(
            resumed.diagnostics.counters.wakes,
            reference.diagnostics.counters.wakes
        );
        assert_eq!(
            resumed.diagnostics.max_penetration,
            reference.diagnostics.max_penetration
        );
    }
}

/// The fall times `summary.json` lists (`WorldState::fallen`) are part of the
/// checkpoint (since format 8): resumed before, between and after two falls
/// beside a floor, a run lists the same falls at the same times.
#[test]
fn fall_times_survive_a_resume() {
    let text = r#"
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
object = "floor"
position = [0.0, 0.0, -0.05]
fixed = true
[[bodies]]
object = "cube"
position = [2.0, 0.0, 0.5]
[[bodies]]
object = "cube"
position = [-3.0, 0.0, 0.0]
"#;
    let mut reference = World::new(load(text));
    let mut exec = Inline::default();
    let mut checkpoints = Vec::new();
    for k in [30u64, 52, 70] {
        run_to(&mut reference, &mut exec, k);
        checkpoints.push(reference.checkpoint().to_bytes());
    }
    run_to(&mut reference, &mut exec, 100);
    let falls: Vec<(u32, f64)> = reference
        .state
        .fallen
        .iter()
        .map(|f| (f.body.0, f.time))
        .collect();
    assert_eq!(falls, [(2, 48.0 * 0.01), (1, 58.0 * 0.01)]);
    for bytes in &checkpoints {
        let ck = Checkpoint::from_bytes(bytes, Path::new("mem")).unwrap();
        let steps = ck.steps;
        let mut resumed = World::restore(load(text), ck).unwrap_or_else(|e| panic!("{e}"));
        run_to(&mut resumed, &mut Inline::default(), 100);
        assert_eq!(
            resumed.state.fallen, reference.state.fallen,
            "resumed at step {steps}"
        );
    }
}

#[test]
fn checkpoint_of_another_scene_or_dt_is_refused_by_name() {
    let mut w = World::new(load(SCENE));
    run_to(&mut w, &mut Inline::default(), 5);
    let ck = w.checkpoint();

    let heavier = load(&SCENE.replace(
        "mass = 1.0\nrestitution = 0.2",
        "mass = 2.0\nrestitution = 0.2",
    ));
    let e = World::restore(heavier, ck.clone())
        .err()
        .expect("another scene must be refused");
    let msg = e.to_string();
    assert!(
        msg.contains("checkpointed") && msg.contains("fingerprint"),
        "{msg}"
    );
    assert!(!msg.contains('\n'), "{msg}");

    let mut finer = load(SCENE);
    finer.settings.dt = 0.005;
    let msg = World::restore(finer, ck.clone()).err().unwrap().to_string();
    assert!(
        msg.contains("dt 0.005 s here, 0.01 s in the checkpoint"),
        "{msg}"
    );

    // A longer duration is what resuming is for: accepted.
    let mut longer = load(SCENE);
    longer.settings.duration = Some(100.0);
    assert!(World::restore(longer, ck.clone()).is_ok());

    let msg = ck.check_sleep(false).unwrap_err().to_string();
    assert!(msg.contains("--no-sleep"), "{msg}");
}

/// Every truncation and every single-byte change of a real checkpoint file
/// is refused with one line naming the file; none panics.
#[test]
fn damaged_checkpoint_files_are_refused_not_trusted() {
    let mut w = World::new(load(SCENE));
    run_to(&mut w, &mut Inline::default(), 60);
    let bytes = w.checkpoint().to_bytes();
    let file = Path::new("runs/ck.bin");
    let step = (bytes.len() / 200).max(1);
    for cut in (0..bytes.len()).step_by(step) {
        let e = Checkpoint::from_bytes(&bytes[..cut], file).unwrap_err();
        assert!(e.to_string().starts_with("runs/ck.bin: "), "{e}");
    }
    for at in (0..bytes.len()).step_by(step) {
        let mut bad = bytes.clone();
        bad[at] ^= 0x5a;
        let e = Checkpoint::from_bytes(&bad, file).unwrap_err().to_string();
        assert!(e.starts_with("runs/ck.bin: ") && !e.contains('\n'), "{e}");
    }
    let e = Checkpoint::read(Path::new("/nonexistent/ck.bin"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("/nonexistent/ck.bin") && e.contains("cannot read"),
        "{e}"
    );
}

/// A header with a valid checksum around arbitrary bytes: what a hand-made
/// or foreign file looks like once it gets past the checksum.
fn framed(payload: &[u8]) -> Vec<u8> {
    let mut sum: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in payload {
        sum ^= b as u64;
        sum = sum.wrapping_mul(0x0000_0100_0000_01b3);
    }
    let mut out = b"RSIMCKPT".to_vec();
    out.extend_from_slice(&1u32.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&sum.to_le_bytes());
    out.extend_from_slice(payload);
    out
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]
    #[test]
    fn arbitrary_checkpoint_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
        prop_assert!(Checkpoint::from_bytes(&bytes, Path::new("x.bin")).is_err());
        let framed = framed(&bytes);
        if let Ok(ck) = Checkpoint::from_bytes(&framed, Path::new("x.bin")) {
            // Decoded by chance: restoring it into a real scene must still
            // refuse rather than index out of bounds.
            prop_assert!(World::restore(load(SCENE), ck).is_err());
        }
    }
}

// ------------------------------------------------------------------ the binary

/// One binary run at a time in this file (each may take every core).
fn one_at_a_time() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    LOCK.lock().unwrap_or_else(|e| e.into_inner())
}

fn mpirun() -> PathBuf {
    std::env::var_os("PATH")
        .and_then(|p| {
            std::env::split_paths(&p)
                .map(|d| d.join("mpirun"))
                .find(|m| m.is_file())
        })
        .expect("mpirun is not on PATH: these tests need Open MPI (run scripts/setup.sh)")
}

/// `rigidsim SCENE ARGS` alone (np = 1) or under `mpirun -np N`.
fn command(np: u32, args: &[&str]) -> Command {
    let mut c = if np == 1 {
        Command::new(BIN)
    } else {
        let mut c = Command::new(mpirun());
        c.args(["--oversubscribe", "-np", &np.to_string(), BIN]);
        c.env("OMPI_ALLOW_RUN_AS_ROOT", "1")
            .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
            .env("OMPI_MCA_rmaps_base_oversubscribe", "1");
        c
    };
    c.args(args).args(["--no-progress", "--no-render"]);
    c
}

struct Outcome {
    code: Option<i32>,
    stderr: String,
}

fn run(np: u32, args: &[&str]) -> Outcome {
    let out = command(np, args)
        .stdin(Stdio::null())
        .output()
        .expect("cannot start rigidsim");
    Outcome {
        code: out.status.code(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

fn summary(dir: &Path) -> Value {
    let text = std::fs::read_to_string(dir.join("summary.json"))
        .unwrap_or_else(|e| panic!("{}: {e}", dir.join("summary.json").display()));
    serde_json::from_str(&text).unwrap()
}

fn hash(dir: &Path) -> String {
    summary(dir)["state_hash"].as_str().unwrap().to_string()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// The pile of `SCENE`, written to a file with `extra` appended.
fn scene_file(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Checks that every line ends with a newline and has the 15 finite fields
/// of the header; returns the data rows' times.
fn trajectory_times(path: &Path) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(
        text.ends_with('\n'),
        "{}: last line is torn",
        path.display()
    );
    let mut lines = text.lines();
    assert_eq!(
        lines.next(),
        Some(rigidsim::output::trajectory::HEADER),
        "{}",
        path.display()
    );
    lines
        .map(|l| {
            let fields: Vec<f64> = l
                .split(',')
                .map(|f| f.parse::<f64>().unwrap_or(f64::NAN))
                .collect();
            assert_eq!(fields.len(), 15, "{l}");
            assert!(fields.iter().all(|x| x.is_finite()), "non-finite row: {l}");
            fields[0]
        })
        .collect()
}

/// `--checkpoint-every` on one rank, `--resume` on two (every stage forced
/// onto the worker), and the other way round: the same state hash and the
/// same trajectory bytes as an uninterrupted one-rank run.
#[test]
fn resume_across_rank_counts_gives_the_same_state_hash() {
    let _one = one_at_a_time();
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let scene = scene_file(root, "pile.toml", SCENE);
    let whole = root.join("whole");
    let r = run(1, &[s(&scene), "--duration", "2.0", "--out", s(&whole)]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);

    for (first, second) in [(1, 2), (2, 1)] {
        let dir = root.join(format!("np{first}to{second}"));
        let mut args = vec![
            s(&scene),
            "--duration",
            "0.9",
            "--checkpoint-every",
            "0.3",
            "--out",
            s(&dir),
        ];
        if first > 1 {
            args.push("--force-distribute");
        }
        let r = run(first, &args);
        assert_eq!(r.code, Some(0), "first part on {first} ranks: {}", r.stderr);
        let ck = Checkpoint::read(&dir.join(FILE_NAME)).unwrap();
        assert_eq!(ck.steps, 90);
        let resume = dir.join("resume-from.bin");
        std::fs::rename(dir.join(FILE_NAME), &resume).unwrap();
        let mut args = vec![
            s(&scene),
            "--duration",
            "2.0",
            "--resume",
            s(&resume),
            "--out",
            s(&dir),
        ];
        if second > 1 {
            args.push("--force-distribute");
        }
        let r = run(second, &args);
        assert_eq!(r.code, Some(0), "resumed on {second} ranks: {}", r.stderr);
        assert_eq!(
            hash(&dir),
            hash(&whole),
            "{first} → {second} ranks: state hash differs from the uninterrupted run"
        );
        assert_eq!(summary(&dir)["ranks"], second);
        assert_eq!(summary(&dir)["steps"], 200);
        assert!(
            std::fs::read(dir.join("trajectory.csv")).unwrap()
                == std::fs::read(whole.join("trajectory.csv")).unwrap(),
            "{first} → {second} ranks: trajectory differs"
        );
    }
}

/// A run killed with SIGKILL after writing a checkpoint loses nothing:
/// resumed into the same folder it ends with the uninterrupted run's state
/// hash and trajectory (the torn tail is cut back to the checkpoint).
#[test]
fn killed_run_resumes_to_the_same_result() {
    let _one = one_at_a_time();
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    // Heavier than `SCENE` so the run is still going when it is killed.
    let text = SCENE.replace("count = 16", "count = 60").replace(
        "min = [-0.25, -0.25, 0.05]\nmax = [0.25, 0.25, 0.5]",
        "min = [-0.4, -0.4, 0.05]\nmax = [0.4, 0.4, 0.8]",
    );
    let scene = scene_file(root, "crowd.toml", &text);
    let whole = root.join("whole");
    let r = run(
        1,
        &[
            s(&scene),
            "--duration",
            "3.0",
            "--no-sleep",
            "--out",
            s(&whole),
        ],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);

    let dir = root.join("killed");
    let mut child = command(
        1,
        &[
            s(&scene),
            "--duration",
            "3.0",
            "--no-sleep",
            "--checkpoint-every",
            "0.1",
            "--out",
            s(&dir),
        ],
    )
    .stdin(Stdio::null())
    .stderr(Stdio::null())
    .spawn()
    .unwrap();
    let started = Instant::now();
    let ck_path = dir.join(FILE_NAME);
    while !ck_path.exists() {
        assert!(
            started.elapsed() < Duration::from_secs(60),
            "no checkpoint after 60 s"
        );
        if child.try_wait().unwrap().is_some() {
            panic!("the run ended before its first checkpoint");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    std::thread::sleep(Duration::from_millis(150));
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert!(
        status.code().is_none(),
        "the run finished before it could be killed; make the scene heavier"
    );
    assert!(!dir.join("summary.json").exists());
    let ck = Checkpoint::read(&ck_path).unwrap_or_else(|e| panic!("{e}"));
    assert!(
        ck.steps > 0 && ck.steps < 300,
        "checkpoint at step {}",
        ck.steps
    );

    let r = run(
        1,
        &[
            s(&scene),
            "--duration",
            "3.0",
            "--no-sleep",
            "--resume",
            s(&ck_path),
            "--out",
            s(&dir),
        ],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert_eq!(hash(&dir), hash(&whole));
    trajectory_times(&dir.join("trajectory.csv"));
    assert!(
        std::fs::read(dir.join("trajectory.csv")).unwrap()
            == std::fs::read(whole.join("trajectory.csv")).unwrap(),
        "trajectory differs from the uninterrupted run (killed at step ≥ {})",
        ck.steps
    );
}

/// A 10⁹ N force (on 1 kg: the largest acceleration a scene may give,
/// `scene::bounds::MAX_ACCELERATION`) from t = 0.505 s sends a cube past
/// 10⁶ m/s in the step that starts at 0.51 s (10⁷ m/s in its 0.01 s): the run stops with exit status 3, a summary that
/// names the body, the stage and the time, the checkpoint of t = 0.5 s, and
/// a trajectory whose every line is complete and finite.
#[test]
fn numerical_failure_keeps_the_last_checkpoint_and_complete_lines() {
    let _one = one_at_a_time();
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let scene = scene_file(
        root,
        "boom.toml",
        r#"
[world]
dt = 0.01
duration = 2.0
[objects.floor]
shape = { box = { half_extents = [1.0, 1.0, 0.1] } }
mass = 1.0
[objects.cube]
shape = { box = { half_extents = [0.1, 0.1, 0.1] } }
mass = 1.0
[[bodies]]
object = "floor"
position = [0.0, 0.0, -0.1]
fixed = true
[[bodies]]
object = "cube"
position = [0.0, 0.0, 0.1]
[[forces]]
body = 1
force = [1e9, 0.0, 0.0]
start = 0.505
"#,
    );
    for np in [1, 2] {
        let dir = root.join(format!("np{np}"));
        let r = run(
            np,
            &[
                s(&scene),
                "--checkpoint-every",
                "0.1",
                "--sample-every",
                "0.03",
                "--out",
                s(&dir),
            ],
        );
        assert_eq!(r.code, Some(3), "{np} ranks: {}", r.stderr);
        let sum = summary(&dir);
        assert_eq!(sum["end_reason"], "failed");
        let why = sum["failure"].as_str().unwrap();
        for part in [
            "t = 0.520000 s",
            // The force did it, over the step: not a contact solve.
            "in stage integrate",
            "body 1",
            "exploded",
            "last good checkpoint",
            "(t = 0.5 s)",
        ] {
            assert!(
                why.contains(part),
                "{np} ranks: '{part}' missing from: {why}"
            );
        }
        assert!(r.stderr.contains(why), "{}", r.stderr);
        let ck = Checkpoint::read(&dir.join(FILE_NAME)).unwrap();
        assert_eq!(ck.steps, 50);
        assert!(ck.bodies[1].state.velocity.norm() == 0.0);
        let times = trajectory_times(&dir.join("trajectory.csv"));
        let last = *times.last().unwrap();
        assert!(last <= 0.51 + 1e-12, "a row after the failure: t = {last}");
        assert!(
            (last - 0.51).abs() < 1e-9,
            "the last good sample is missing: {last}"
        );
        // The last good checkpoint resumes (and fails again at the same step).
        let again = root.join(format!("again{np}"));
        let r = run(
            1,
            &[
                s(&scene),
                "--resume",
                s(&dir.join(FILE_NAME)),
                "--out",
                s(&again),
            ],
        );
        assert_eq!(r.code, Some(3), "{}", r.stderr);
        assert!(
            summary(&again)["failure"]
                .as_str()
                .unwrap()
                .contains("t = 0.520000 s")
        );
    }
}

#[test]
fn refused_resume_ends_every_rank_with_status_2() {
    let _one = one_at_a_time();
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let scene = scene_file(root, "pile.toml", SCENE);
    let other = scene_file(
        root,
        "other.toml",
        &SCENE.replace("count = 16", "count = 15"),
    );
    let dir = root.join("a");
    let r = run(
        1,
        &[
            s(&scene),
            "--duration",
            "0.1",
            "--checkpoint-every",
            "0.1",
            "--out",
            s(&dir),
        ],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let ck = dir.join(FILE_NAME);
    let junk = scene_file(root, "junk.bin", "not a checkpoint");
    let cases: [(&[&str], &str); 5] = [
        (
            &[s(&other), "--resume", s(&ck)],
            "was written for scene 'pile'",
        ),
        (
            &[s(&scene), "--resume", s(&ck), "--dt", "0.005"],
            "dt 0.005 s here",
        ),
        (&[s(&scene), "--resume", s(&ck), "--no-sleep"], "--no-sleep"),
        (
            &[s(&scene), "--resume", s(&junk)],
            "junk.bin: is not a rigidsim checkpoint",
        ),
        (
            &[s(&scene), "--checkpoint-every", "0"],
            "--checkpoint-every must be positive",
        ),
    ];
    for np in [1, 3] {
        for (args, words) in cases {
            let mut args = args.to_vec();
            let out = root.join("refused");
            args.extend(["--out", s(&out)]);
            let started = Instant::now();
            let r = run(np, &args);
            assert_eq!(r.code, Some(2), "{np} ranks, {args:?}: {}", r.stderr);
            assert!(
                r.stderr.contains(words),
                "{np} ranks: '{words}' not in {}",
                r.stderr
            );
            assert_eq!(
                r.stderr.matches("rigidsim: error").count(),
                1,
                "one rank reports: {}",
                r.stderr
            );
            assert!(started.elapsed() < Duration::from_secs(30));
        }
    }
}

/// A resumed run appends only to the trajectory its checkpoint's run wrote.
/// In a folder holding another run's `trajectory.csv`, or that run's file
/// cut shorter than at the checkpoint, `--resume` is refused with exit 2 by
/// every rank, naming the file, and the file is left as it was; with the
/// file as the checkpoint left it, the same resume runs.
#[test]
fn resume_refuses_a_trajectory_it_did_not_write() {
    let _one = one_at_a_time();
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let scene = scene_file(root, "pile.toml", SCENE);
    let dir = root.join("a");
    let first = [
        s(&scene),
        "--duration",
        "0.3",
        "--checkpoint-every",
        "0.2",
        "--out",
        s(&dir),
    ];
    let r = run(1, &first);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let ck = root.join("resume-from.bin");
    std::fs::rename(dir.join(FILE_NAME), &ck).unwrap();
    let traj = dir.join("trajectory.csv");
    let original = std::fs::read(&traj).unwrap();
    // Another run's trajectory, longer than the checkpoint's: the same
    // scene with one body fewer, run twice as long.
    let other = scene_file(
        root,
        "other.toml",
        &SCENE.replace("count = 16", "count = 15"),
    );
    let r = run(
        1,
        &[s(&other), "--duration", "0.6", "--out", s(&root.join("b"))],
    );
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let foreign = std::fs::read(root.join("b/trajectory.csv")).unwrap();
    let header = original.iter().position(|&c| c == b'\n').unwrap() + 1;
    let cases: [(&[u8], &str); 2] = [
        (&foreign, "is not the file the checkpoint's run wrote"),
        (&original[..header + 10], "is shorter"),
    ];
    let resume = [
        s(&scene),
        "--duration",
        "0.3",
        "--resume",
        s(&ck),
        "--out",
        s(&dir),
    ];
    for np in [1, 2] {
        for (content, words) in cases {
            std::fs::write(&traj, content).unwrap();
            let r = run(np, &resume);
            assert_eq!(r.code, Some(2), "{np} ranks, {words}: {}", r.stderr);
            assert!(
                r.stderr.contains("trajectory.csv: ") && r.stderr.contains(words),
                "{np} ranks: '{words}' not in {}",
                r.stderr
            );
            assert_eq!(
                r.stderr.matches("rigidsim: error").count(),
                1,
                "{}",
                r.stderr
            );
            assert_eq!(
                std::fs::read(&traj).unwrap(),
                content,
                "the file was changed"
            );
        }
    }
    std::fs::write(&traj, &original).unwrap();
    let r = run(1, &resume);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert_eq!(std::fs::read(&traj).unwrap(), original);
}

// ------------------------------------------------------------ rendered runs

/// `rigidsim ARGS` on one rank with rendering on (`command` turns it off).
fn run_rendered(args: &[&str]) -> Outcome {
    let out = Command::new(BIN)
        .args(args)
        .arg("--no-progress")
        .stdin(Stdio::null())
        .output()
        .expect("cannot start rigidsim");
    Outcome {
        code: out.status.code(),
        stderr: String::from_utf8_lossy(&out.stderr).into_owned(),
    }
}

fn installed(tool: &str) -> bool {
    Command::new(tool)
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// The number of frames in a video, counted by decoding every one.
fn video_frames(path: &Path) -> u64 {
    let out = Command::new("ffprobe")
        .args(["-v", "error", "-count_frames", "-select_streams", "v:0"])
        .args(["-show_entries", "stream=nb_read_frames", "-of", "csv=p=0"])
        .arg(path)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    text.trim()
        .parse()
        .unwrap_or_else(|_| panic!("ffprobe on {}: {text:?}", path.display()))
}

/// One MD5 line per decoded frame, in order.
fn video_frame_hashes(path: &Path) -> String {
    let out = Command::new("ffmpeg")
        .args(["-v", "error", "-i"])
        .arg(path)
        .args(["-f", "framemd5", "-"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "ffmpeg could not decode {}",
        path.display()
    );
    String::from_utf8(out.stdout).unwrap()
}

/// Issue 8, "Resuming with rendering": a resumed run's `video.mp4` holds the
/// whole run, the stopped run's frames up to the checkpoint and then its
/// own, not only the frames after the checkpoint; the frames the stopped run
/// drew after its checkpoint are not in it twice. A frame file gone missing
/// is left out with one note, and the run still succeeds.
#[test]
fn resumed_run_video_holds_the_whole_run() {
    if !installed("ffmpeg") || !installed("ffprobe") {
        println!("skipped: ffmpeg or ffprobe is not installed (scripts/setup.sh installs them)");
        return;
    }
    let _one = one_at_a_time();
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    // 0.5 s, a frame every 0.05 s from t = 0: 11 frames.
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/render_check.toml");
    let whole = root.join("whole");
    let r = run_rendered(&[s(&scene), "--out", s(&whole)]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let whole_frames = video_frames(&whole.join("video.mp4"));
    assert_eq!(whole_frames, 11, "the uninterrupted run");

    // A run that checkpoints at t = 0.2 s (frames 0–4 drawn, next index 5)
    // and draws frames 5–7 before it stops at 0.35 s: the same run to 0.2 s
    // with a checkpoint, then to 0.35 s without one, into the same folder.
    let dir = root.join("stopped");
    let r = run_rendered(&[
        s(&scene),
        "--duration",
        "0.2",
        "--checkpoint-every",
        "0.1",
        "--out",
        s(&dir),
    ]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let resume = root.join("resume-from.bin");
    std::fs::rename(dir.join(FILE_NAME), &resume).unwrap();
    assert_eq!(Checkpoint::read(&resume).unwrap().run.frame_index, 5);
    let r = run_rendered(&[s(&scene), "--duration", "0.35", "--out", s(&dir)]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(dir.join("frames/frame_00007.png").exists());

    let r = run_rendered(&[s(&scene), "--resume", s(&resume), "--out", s(&dir)]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert_eq!(
        video_frames(&dir.join("video.mp4")),
        whole_frames,
        "the resumed run's video.mp4 does not hold the whole run"
    );
    assert_eq!(summary(&dir)["frames_rendered"], 6, "frames 5–10");
    // The same images in the same order: rendering and libx264 are
    // deterministic on one machine.
    assert!(
        video_frame_hashes(&dir.join("video.mp4")) == video_frame_hashes(&whole.join("video.mp4")),
        "the resumed run's video differs from the uninterrupted run's"
    );
    let notes = summary(&dir)["notes"].to_string();
    assert!(!notes.contains("video.mp4"), "unexpected note: {notes}");

    // A frame from before the checkpoint gone missing: left out, said once.
    std::fs::remove_file(dir.join("frames/frame_00002.png")).unwrap();
    let r = run_rendered(&[s(&scene), "--resume", s(&resume), "--out", s(&dir)]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert_eq!(video_frames(&dir.join("video.mp4")), whole_frames - 1);
    let notes = summary(&dir)["notes"].as_array().unwrap().clone();
    let about_video: Vec<_> = notes
        .iter()
        .filter_map(|n| n.as_str())
        .filter(|n| n.contains("video.mp4"))
        .collect();
    assert_eq!(about_video.len(), 1, "{notes:?}");
    assert!(
        about_video[0].contains("1 of the 5 frames") && about_video[0].contains("frame_00002.png"),
        "{}",
        about_video[0]
    );

    // Frames in the folder that are not the checkpoint's run's: another
    // frame's image under frame 3's name, and an unmarked PNG under frame
    // 1's. Each PNG carries the digest of the poses it drew, and the
    // checkpoint the digests of the frames its run published: both are
    // left out (before, both went into the video as the run's own).
    std::fs::copy(
        whole.join("frames/frame_00004.png"),
        dir.join("frames/frame_00003.png"),
    )
    .unwrap();
    let image = rigidsim::render::read_png(whole.join("frames/frame_00001.png")).unwrap();
    rigidsim::render::write_png(dir.join("frames/frame_00001.png"), &image).unwrap();
    let r = run_rendered(&[s(&scene), "--resume", s(&resume), "--out", s(&dir)]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert_eq!(video_frames(&dir.join("video.mp4")), whole_frames - 3);
    let notes = summary(&dir)["notes"].to_string();
    assert!(
        notes.contains("3 of the 5 frames")
            && notes.contains("frame_00001.png: not this run's frame (marked \\\"nothing\\\""),
        "{notes}"
    );
    // The run's own frames back (from the uninterrupted run, which drew
    // the same poses): taken again, the video is the whole run's.
    for k in 1..=3 {
        let name = format!("frames/frame_{k:05}.png");
        std::fs::copy(whole.join(&name), dir.join(&name)).unwrap();
    }
    let r = run_rendered(&[s(&scene), "--resume", s(&resume), "--out", s(&dir)]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    assert!(
        video_frame_hashes(&dir.join("video.mp4")) == video_frame_hashes(&whole.join("video.mp4")),
        "the frames put back were not taken as the run's own"
    );
}
