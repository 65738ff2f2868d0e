//! Results that do not depend on which kind of PC computes them.
//!
//! glibc picks its `sin`, `cos` and `atan2` for the CPU when a program
//! starts (`__sin_fma` where the CPU has FMA), and the routines differ in
//! the last bit. A lab of mixed PCs would then end a run on a state hash
//! that depends on where each group step ran. `src/math.rs` takes those
//! functions from the `libm` crate instead; this test runs the bundled
//! scene (spinning nuts and bolts, whose shapes and rotations take sines)
//! once as glibc chooses and once with glibc told to skip its FMA and AVX2
//! code (`GLIBC_TUNABLES`, as on a PC without them), and asks for one state
//! hash and one trajectory. Before `src/math.rs`, `crowd200.toml` for 2 s
//! ended on two hashes this way. On a CPU without FMA both runs take the
//! same code, and the test shows nothing there; the two tests below run the
//! binary on an emulated older CPU instead (`qemu-x86_64 -cpu Nehalem`), alone
//! and as one rank of two, which shows it on any x86-64 host.

mod common;

use std::path::Path;
use std::process::Command;

/// glibc's switch (2.26 and later) that hides these CPU features from its
/// own choice of routines; the old and the new spellings of the names.
const WITHOUT_FMA: &str = "glibc.cpu.hwcaps=-AVX2_Usable,-FMA_Usable,-AVX2,-FMA,-FMA4";

/// The run every test here makes of the bundled scene (its output folder
/// follows).
const RUN_ARGS: [&str; 5] = ["--duration", "0.6", "--no-render", "--no-progress", "--out"];

/// `program` as the tests start it (`common::command`), glibc left to
/// choose.
fn command(program: &str) -> Command {
    let mut cmd = common::command(program);
    cmd.env_remove("GLIBC_TUNABLES");
    cmd
}

fn run(out: &Path, tunables: Option<&str>) -> (String, String) {
    let scene = common::bundled("nuts_and_bolts.toml");
    let mut cmd = command(env!("CARGO_BIN_EXE_rigidsim"));
    cmd.arg(&scene).args(RUN_ARGS).arg(out);
    if let Some(t) = tunables {
        cmd.env("GLIBC_TUNABLES", t);
    }
    let output = cmd.output().expect("cannot start rigidsim");
    assert!(
        output.status.success(),
        "rigidsim failed: {}",
        String::from_utf8_lossy(&output.stderr)
    );
    let summary: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    let hash = summary["state_hash"].as_str().unwrap().to_string();
    let trajectory = std::fs::read_to_string(out.join("trajectory.csv")).unwrap();
    (hash, trajectory)
}

#[test]
fn glibc_code_path_for_the_cpu_leaves_the_result_unchanged() {
    let root = tempfile::tempdir().unwrap();
    let (hash, trajectory) = run(&root.path().join("as_chosen"), None);
    let (hash_without, trajectory_without) =
        run(&root.path().join("without_fma"), Some(WITHOUT_FMA));
    assert_eq!(
        hash, hash_without,
        "state hash depends on glibc's code path"
    );
    assert!(
        trajectory == trajectory_without,
        "trajectory depends on glibc's code path"
    );
}

/// An older CPU, emulated (`qemu-x86_64` from Debian's `qemu-user`):
/// SSE4.2 and no AVX, so glibc, faer and the Rust standard library's
/// feature checks all take their plain-SSE code.
#[cfg(target_arch = "x86_64")]
const OLDER_CPU: [&str; 2] = ["-cpu", "Nehalem"];

#[cfg(target_arch = "x86_64")]
fn summary_of(out: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap()
}

#[cfg(target_arch = "x86_64")]
fn succeeded(what: &str, output: std::process::Output) {
    assert!(
        output.status.success(),
        "{what} failed (is qemu-user installed? scripts/setup.sh installs it): {}",
        String::from_utf8_lossy(&output.stderr)
    );
}

/// The bundled scene on an emulated CPU without AVX ends where it ends on
/// this one; the emulated run reports its CPU as `sse2`, so the emulation
/// really hid the wider units.
#[cfg(target_arch = "x86_64")]
#[test]
fn an_older_cpu_generation_ends_on_the_same_hash() {
    let root = tempfile::tempdir().unwrap();
    let (hash, trajectory) = run(&root.path().join("native"), None);
    let out = root.path().join("older");
    let output = command("qemu-x86_64")
        .args(OLDER_CPU)
        .arg(env!("CARGO_BIN_EXE_rigidsim"))
        .arg(common::bundled("nuts_and_bolts.toml"))
        .args(RUN_ARGS)
        .arg(&out)
        .output()
        .expect("cannot start qemu-x86_64 (scripts/setup.sh installs qemu-user)");
    succeeded("rigidsim under qemu-x86_64 -cpu Nehalem", output);
    let summary = summary_of(&out);
    assert_eq!(summary["per_rank"][0]["vector_units"], "sse2");
    assert_eq!(summary["state_hash"].as_str().unwrap(), hash);
    assert!(
        std::fs::read_to_string(out.join("trajectory.csv")).unwrap() == trajectory,
        "trajectory differs on the older CPU"
    );
}

/// A worker on another generation of CPU (one rank native, one emulated,
/// under one `mpirun`) is named in a warning, and the run still ends on
/// the one-rank hash (this scene's solves reach no kernel that differs).
#[cfg(target_arch = "x86_64")]
#[test]
fn a_rank_on_another_cpu_generation_is_warned_of() {
    let root = tempfile::tempdir().unwrap();
    let (hash, _) = run(&root.path().join("one_rank"), None);
    let out = root.path().join("mixed");
    let scene = common::bundled("nuts_and_bolts.toml");
    let bin = env!("CARGO_BIN_EXE_rigidsim");
    let output = command("mpirun")
        .args(["--oversubscribe", "-np", "1", bin])
        .arg(&scene)
        .args(RUN_ARGS)
        .arg(&out)
        .args([":", "-np", "1", "qemu-x86_64"])
        .args(OLDER_CPU)
        .arg(bin)
        .arg(&scene)
        .args(RUN_ARGS)
        .arg(&out)
        // Open MPI's single-copy transfers read the other process's memory
        // by a system call qemu-user does not provide.
        .env("OMPI_MCA_btl_vader_single_copy_mechanism", "none")
        .output()
        .expect("cannot start mpirun (scripts/setup.sh installs Open MPI)");
    let stderr = String::from_utf8_lossy(&output.stderr).into_owned();
    succeeded("mpirun with a rank under qemu-x86_64 -cpu Nehalem", output);
    let summary = summary_of(&out);
    let native = rigidsim::cluster::vector_units();
    assert_eq!(summary["per_rank"][0]["vector_units"], native);
    assert_eq!(summary["per_rank"][1]["vector_units"], "sse2");
    // On a host that is itself SSE2 only, the two ranks are of one kind.
    let mixed = native != "sse2";
    let warned = |text: &str| text.contains("warning: the ranks' CPUs differ in vector units");
    let notes = summary["notes"].as_array().unwrap();
    assert_eq!(
        notes.iter().any(|n| warned(n.as_str().unwrap())),
        mixed,
        "{notes:?}"
    );
    assert_eq!(warned(&stderr), mixed, "rank 0's messages: {stderr}");
    assert_eq!(summary["state_hash"].as_str().unwrap(), hash);
}
