//! The contact solver on real islands (`tests/data/islands/`, written by
//! `--capture-islands` from the 1000-body pour between 1.0 and 1.4 s, and
//! from the stacks of 50 and 100 and the pyramid of `scripts/stress.sh`):
//! every answer is checked against its systems' LCP conditions
//! (`SolveStats::worst_violation`, computed from the rows whatever method
//! answered), the pyramid's iterative answer against Dantzig's, and the
//! work each solve takes against a cap, so that a regression shows. Work is
//! counted in pivots and sweeps, which are deterministic (no timing).

mod common;

use rigidsim::contact::solver::{IslandResult, IslandTask, SolveStats, solve_island};
use std::path::Path;

fn fixture(name: &str) -> IslandTask {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/islands")
        .join(format!("{name}.bin"));
    let bytes = std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    bincode::serde::decode_from_slice(&bytes, bincode::config::standard())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .0
}

fn describe(name: &str, s: &SolveStats) -> String {
    format!(
        "{name}: rows {}, violation {:.2e} m/s, pivots {}, sweeps {}, Dantzig solves {}, \
         iterative {} ({} unconverged), compliant {}, failed {}, interior point {} \
         ({} missed, {} Newton steps)",
        s.largest_rows,
        s.worst_violation,
        s.pivots,
        s.iterative_sweeps,
        s.lcp_solves,
        s.iterative_solves,
        s.iterative_unconverged,
        s.compliant_solves,
        s.failed,
        s.interior_solves,
        s.interior_missed,
        s.interior_steps
    )
}

/// Body k's velocity and angular velocity change over the step from an
/// island's answer: its impulse and its constant force over dt.
fn velocity_change(
    task: &IslandTask,
    r: &IslandResult,
    k: usize,
) -> (nalgebra::Vector3<f64>, nalgebra::Vector3<f64>) {
    let body = &task.bodies[k];
    let dv = (r.impulse[k] + r.force[k] * task.dt) * body.inv_mass;
    let dw = body.inv_inertia * (r.angular_impulse[k] + r.torque[k] * task.dt);
    (dv, dw)
}

/// How far an answer may miss its conditions: the iterative solve's
/// tolerance (1e-8 m/s at these speeds, `ITERATIVE_FLOOR`), met on the
/// slightly compliant system, plus what that compliance (1e-9 of the
/// diagonal) makes the exact system's rows close at under the stacks'
/// loads (1e-8 m/s at the bottom of the stack of 100), which the
/// compliant retry of Dantzig's method (`methods::dantzig::COMPLIANCE`) stays within too.
const TOLERANCE: f64 = 2e-8;

/// Islands solved to the LCP's conditions, with the work they took when
/// this test was written: a pivot, sweep or Newton step count over 1.5×
/// that fails. (name, rows, pivots, sweeps, Newton steps)
const SOLVED: [(&str, u32, u64, u64, u64); 10] = [
    // The interior point (`contact::methods::interior`) on both solves.
    ("pile_96rows", 96, 0, 0, 29),
    // The interior point on its impact; its resting phase starts from the
    // last step's impulses, close enough for Dantzig's method
    // (`SolverSettings::warm_close`).
    ("pile_99rows_compliant", 99, 189, 0, 14),
    // Named when Dantzig's method failed on its exact system and solved the
    // compliant one: the interior point on both solves.
    ("pile_246rows_compliant", 246, 0, 0, 34),
    // Named when the sequential impulses missed the conditions and
    // Dantzig's method took their answer; the interior point (after 8
    // sweeps, as every system from `iterative_min_rows` rows).
    ("pile_354rows_iterative_then_dantzig", 354, 0, 16, 40),
    // Named when Dantzig's method failed on the exact and the compliant
    // system and the start sweeps' answer was kept 1.4e-5 m/s off: the
    // interior point meets the conditions.
    ("pile_108rows_failed", 108, 0, 0, 32),
    // Small islands of the 1000-body pile at 1.0-1.1 s, named when
    // Dantzig's method failed on the exact and the compliant system and
    // 1000 sweeps missed too, so that the fallback's answer was kept 3.3e-2
    // and 1.1e-2 m/s off the conditions: the interior point, tried last
    // below `SolverSettings::interior_min_rows`, meets them.
    ("pile_60rows_failed_twice", 60, 211, 1000, 18),
    ("pile_30rows_failed_twice", 30, 76, 1000, 14),
    // Sequential impulses with the subspace step: the stacks by the
    // large-island method (`pile_sweeps`, more than 48 moving bodies), the
    // pyramid after 8 sweeps.
    ("stack50", 600, 0, 20, 0),
    ("stack100", 1206, 0, 20, 0),
    ("pyramid", 312, 0, 8, 0),
];

#[test]
fn captured_islands_meet_the_lcp_conditions_within_their_work() {
    for (name, rows, pivots, sweeps, steps) in SOLVED {
        let r: IslandResult = solve_island(&fixture(name));
        let s = &r.stats;
        let seen = describe(name, s);
        eprintln!("[islands] {seen}");
        assert_eq!(s.largest_rows, rows, "{seen}");
        assert_eq!(s.failed, 0, "{seen}");
        assert!(s.worst_violation <= TOLERANCE, "{seen}");
        assert!(
            s.pivots as f64 <= 1.5 * pivots as f64,
            "{seen}: over 1.5 × {pivots} pivots"
        );
        assert!(
            s.iterative_sweeps as f64 <= 1.5 * sweeps as f64,
            "{seen}: over 1.5 × {sweeps} sweeps"
        );
        assert!(
            s.interior_steps as f64 <= 1.5 * steps as f64,
            "{seen}: over 1.5 × {steps} Newton steps"
        );
    }
}

/// The limits of today's solver, kept as they are so that they show when
/// they move (docs/architecture.md, *Known limits*): two settling pile
/// islands of more than 48 moving bodies, which the large-island method
/// (`pile_sweeps`) ends at its budget of 200 sweeps a solve, short of the
/// conditions (its answer is kept). Measured: the 597-row island's
/// impact meets them in 180 sweeps and its resting solve misses by
/// 7.2e-4 m/s; the 1362-row island (82 bodies of the 1000-body pour at
/// 1.4 s) misses by 2.2e-5 m/s in both solves. Getting worse fails here.
#[test]
fn the_known_misses_stay_where_they_are() {
    // (name, unconverged solves, sweeps, worst violation allowed)
    for (name, unconverged, sweeps, worst) in [
        ("pile_597rows_iterative_unconverged", 1, 380, 1e-3),
        ("pile_1362rows_82bodies", 2, 400, 5e-5),
    ] {
        let r = solve_island(&fixture(name));
        let seen = describe(name, &r.stats);
        eprintln!("[islands] {seen}");
        assert_eq!(r.stats.iterative_unconverged, unconverged, "{seen}");
        assert_eq!(r.stats.iterative_sweeps, sweeps, "{seen}");
        assert_eq!(r.stats.interior_steps + r.stats.pivots, 0, "{seen}");
        assert!(r.stats.worst_violation <= worst, "{seen}");
    }
}

/// The pyramid's island solved by sequential impulses and by Dantzig's
/// method (`iterative_min_rows` past its rows): both meet the conditions,
/// and every body ends the step with the same velocity change to 1e-8 m/s
/// and rad/s (9e-10 when written). (The impulses themselves are not unique: a cube on two
/// cubes below may rest on either more.)
#[test]
fn the_pyramid_answers_alike_by_both_methods() {
    let task = fixture("pyramid");
    let iterative = solve_island(&task);
    let exact = solve_island(&IslandTask {
        iterative_min_rows: u32::MAX,
        island_blocks: 1,
        ..task.clone()
    });
    for (name, r) in [("iterative", &iterative), ("Dantzig", &exact)] {
        let seen = describe(name, &r.stats);
        eprintln!("[islands] pyramid, {seen}");
        assert!(r.stats.worst_violation <= TOLERANCE, "{seen}");
    }
    assert!(iterative.stats.iterative_solves > 0 && exact.stats.iterative_solves == 0);
    let mut worst: f64 = 0.0;
    for k in 0..task.bodies.len() {
        let change = |r: &IslandResult| velocity_change(&task, r, k);
        let ((v1, w1), (v2, w2)) = (change(&iterative), change(&exact));
        worst = worst.max((v1 - v2).norm()).max((w1 - w2).norm());
    }
    eprintln!("[islands] pyramid: largest difference in a body's velocity change {worst:.2e}");
    assert!(worst <= 1e-8, "{worst:e}");
}

/// `--capture-islands` writes the islands a run solves and leaves the run
/// as it was: the resting stack's islands (down to one row) decode as
/// tasks that solve, the file names carry their rows, and the state hash
/// is the one of the same run without capturing.
#[test]
fn capture_writes_islands_and_changes_nothing() {
    let root = tempfile::tempdir().unwrap();
    let dir = root.path().join("islands");
    let scene = common::bundled("resting_stack.toml");
    let run = |out: &str, capture: bool| {
        let out = root.path().join(out);
        let mut args = vec![
            scene.to_str().unwrap().to_string(),
            "--duration".into(),
            "0.1".into(),
            "--no-render".into(),
            "--no-progress".into(),
            "--out".into(),
            out.to_str().unwrap().into(),
        ];
        if capture {
            args.extend([
                "--capture-islands".into(),
                dir.to_str().unwrap().into(),
                "--capture-min-rows".into(),
                "1".into(),
            ]);
        }
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = common::rigidsim(&args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let summary: serde_json::Value =
            serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
        summary["state_hash"].clone()
    };
    let plain = run("plain", false);
    let captured = run("captured", true);
    assert_eq!(plain, captured, "capturing changed the run");
    let files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert!(!files.is_empty(), "nothing captured");
    for path in files {
        let bytes = std::fs::read(&path).unwrap();
        let task: IslandTask =
            bincode::serde::decode_from_slice(&bytes, bincode::config::standard())
                .unwrap()
                .0;
        let rows: usize = task
            .contacts
            .iter()
            .map(|c| if c.friction > 0.0 { 3 } else { 1 })
            .sum();
        let name = path.file_name().unwrap().to_str().unwrap();
        assert!(
            name.ends_with(&format!("_{rows}rows.bin")),
            "{name}: {rows} rows"
        );
        let r = solve_island(&task);
        assert_eq!(r.impulse.len(), task.bodies.len());
        assert!(
            r.stats.worst_violation <= TOLERANCE,
            "{name}: {:e}",
            r.stats.worst_violation
        );
    }
}

/// The interior point's answers on the pile's islands against Dantzig's
/// method alone (`iterative_min_rows` = u32::MAX), on their resting
/// phases (the bodies' velocities set to zero, so that nothing approaches
/// and no impact is solved), where Dantzig's method succeeds on the exact
/// system: the bodies' velocity changes agree as closely as two answers
/// that each meet the conditions to ε = `TOLERANCE` can, not to ε itself:
/// a redundant system's impulses are not unique, and for two answers p¹,
/// p² of the same system (friction bounds held fixed) the difference of
/// the velocities they give, in the mass metric, is ΔpᵀAΔp = ΔpᵀΔw ≤
/// 2ε(‖p¹‖₁ + ‖p²‖₁), so a body moves apart by at most √(2εP/m) and turns
/// by √(2εP/I_min), P = ‖p¹‖₁ + ‖p²‖₁ (seen: at most 3.5e-6 of it); and,
/// as a guard against a change that keeps within that loose bound, by at
/// most 1e-6 m/s and rad/s (seen: 4.4e-8, on `pile_99rows_compliant`).
/// Impacts are not compared: with friction an impact of redundant contacts
/// can have several answers, and on `pile_354rows_iterative_then_dantzig`
/// the two methods' answers (both within 6e-9 m/s of the conditions) move
/// a body 0.16 m/s apart, the interior point's with 0.3 % less kinetic
/// energy. Where Dantzig's method fails only the conditions are checked.
#[test]
fn interior_answers_move_the_bodies_as_dantzig_does() {
    let mut compared = 0;
    for name in [
        "pile_96rows",
        "pile_99rows_compliant",
        "pile_108rows_failed",
        "pile_246rows_compliant",
        "pile_354rows_iterative_then_dantzig",
    ] {
        let mut task = fixture(name);
        for body in &mut task.bodies {
            body.velocity = nalgebra::Vector3::zeros();
            body.angular_velocity = nalgebra::Vector3::zeros();
        }
        let interior = solve_island(&task);
        let exact = solve_island(&IslandTask {
            iterative_min_rows: u32::MAX,
            island_blocks: 1,
            ..task.clone()
        });
        let seen = describe(name, &interior.stats);
        eprintln!(
            "[islands] at rest, {seen}; Dantzig alone: {}",
            describe(name, &exact.stats)
        );
        assert!(interior.stats.worst_violation <= TOLERANCE, "{seen}");
        assert_eq!(exact.stats.interior_solves, 0);
        if interior.stats.interior_solves == 0
            || exact.stats.failed > 0
            || exact.stats.compliant_solves > 0
        {
            continue;
        }
        let total = |r: &IslandResult| -> f64 {
            r.contact_force.iter().map(|f| f.abs()).sum::<f64>()
                + r.contact_friction.iter().map(|f| f.norm()).sum::<f64>()
        };
        let p = (total(&interior) + total(&exact)) * task.dt;
        let (mut worst, mut apart): (f64, f64) = (0.0, 0.0);
        for (k, body) in task.bodies.iter().enumerate() {
            let change = |r: &IslandResult| velocity_change(&task, r, k);
            let ((dv, dw), (ev, ew)) = (change(&interior), change(&exact));
            let spin = body.inv_inertia.symmetric_eigenvalues().max();
            let (bound_v, bound_w) = (
                (2.0 * TOLERANCE * p * body.inv_mass).sqrt(),
                (2.0 * TOLERANCE * p * spin).sqrt(),
            );
            apart = apart.max((dv - ev).norm()).max((dw - ew).norm());
            if body.inv_mass > 0.0 {
                worst = worst
                    .max((dv - ev).norm() / bound_v)
                    .max((dw - ew).norm() / bound_w);
            }
        }
        eprintln!(
            "[islands] {name}: velocity changes apart by {apart:.1e}, {worst:.1e} of the bound"
        );
        assert!(worst <= 1.0, "{name}: {worst}");
        assert!(apart <= 1e-6, "{name}: {apart:e}");
        compared += 1;
    }
    assert!(compared >= 2, "compared {compared} of the islands");
}
