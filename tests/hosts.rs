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
//! same code, and the test shows nothing there.

mod common;

use std::path::Path;
use std::process::{Command, Stdio};

/// glibc's switch (2.26 and later) that hides these CPU features from its
/// own choice of routines; the old and the new spellings of the names.
const WITHOUT_FMA: &str = "glibc.cpu.hwcaps=-AVX2_Usable,-FMA_Usable,-AVX2,-FMA,-FMA4";

fn run(out: &Path, tunables: Option<&str>) -> (String, String) {
    let scene = common::bundled("nuts_and_bolts.toml");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_rigidsim"));
    cmd.arg(&scene)
        .args(["--duration", "0.6", "--no-render", "--no-progress", "--out"])
        .arg(out)
        .env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .env_remove("GLIBC_TUNABLES")
        .stdin(Stdio::null());
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
