//! One-rank runs started side by side on one machine, as a user's scripts
//! and this test suite start them.
//!
//! Without `mpirun`, Open MPI kept every such process's temporary files
//! under one folder per user (`/tmp/ompi.<host>.<uid>/`); a process that
//! ended removed it while another that started was making its own inside,
//! and that one failed at `MPI_Init` ("A call to mkdir was unable to create
//! the desired directory", exit 1): 4 of 240 runs, four loops side by side,
//! twice, before each run got a temporary folder of its own
//! (`MpiTempDir` in `src/main.rs`), none of 480 after. This test runs 64
//! (four loops of 16): the build before failed in 3 of 8 such rounds (7 of
//! 512 runs), so it is a net with holes, not a proof; it also checks that
//! every run removes its temporary folder, and that a folder left by a run
//! that was killed goes at the next run.

mod common;

#[test]
fn one_rank_runs_side_by_side_all_start() {
    let root = tempfile::tempdir().unwrap();
    // The runs' temporary folder (their Open MPI folders go there), so
    // that what they leave is theirs alone.
    let tmp = root.path().join("tmp");
    std::fs::create_dir(&tmp).unwrap();
    // What a killed run leaves: the folder of a process that is gone (no
    // process has this number: Linux's largest is 2^22).
    std::fs::create_dir_all(tmp.join("rigidsim-4194305/ompi.pc.0/jf.0")).unwrap();
    let scene = common::bundled("bouncing_cube.toml");
    let loops: Vec<_> = (0..4)
        .map(|l| {
            let out = root.path().join(format!("loop{l}"));
            let (scene, tmp) = (scene.clone(), tmp.clone());
            std::thread::spawn(move || {
                let mut failures = Vec::new();
                for k in 0..16 {
                    let o = common::command(env!("CARGO_BIN_EXE_rigidsim"))
                        .arg(&scene)
                        .args([
                            "--duration",
                            "0.01",
                            "--no-render",
                            "--no-progress",
                            "--out",
                        ])
                        .arg(&out)
                        .env("TMPDIR", &tmp)
                        .output()
                        .expect("cannot start rigidsim");
                    if !o.status.success() {
                        failures.push(format!(
                            "loop {l}, run {k}: {}",
                            String::from_utf8_lossy(&o.stderr)
                        ));
                    }
                }
                failures
            })
        })
        .collect();
    let failures: Vec<String> = loops.into_iter().flat_map(|h| h.join().unwrap()).collect();
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    // Each run removed its Open MPI folder, and the first the stale one.
    let left: Vec<_> = std::fs::read_dir(&tmp)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert!(left.is_empty(), "left behind in TMPDIR: {left:?}");
}
