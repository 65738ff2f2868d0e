//! Contact patches (`collision::patch`) on real islands: an island whose
//! pairs keep only their patches' hull vertices and deepest points moves
//! its bodies as the island with every point does, where that island's
//! solve met the LCP's conditions.
//!
//! The fixtures (`tests/data/islands/`) were captured before patches, so
//! their pairs carry interior points. `RIGIDSIM_PATCH_ISLANDS=DIR cargo test
//! --release --test patches -- --ignored` runs the same check over a folder
//! written by `--capture-islands` and prints the distribution.

use nalgebra::Vector3;
use rigidsim::collision::patch;
use rigidsim::contact::solver::{IslandResult, IslandTask, solve_island};
use std::collections::BTreeMap;
use std::path::Path;

/// What an island's full solve must meet to be a reference (m/s).
const REFERENCE_VIOLATION: f64 = 1e-8;
/// The agreement asked of the reduced solve, at every contact point (m/s).
const AGREEMENT: f64 = 1e-6;

fn read(path: &Path) -> IslandTask {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    bincode::serde::decode_from_slice(&bytes, bincode::config::standard())
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .0
}

/// The island's contacts in patches: each body pair's patches (in the
/// order of their first contacts), each patch's contacts in the order they
/// came, and of each patch only its hull's vertices and deepest point where
/// `reduce` says so. The narrowphase gives a pair's points patch by patch,
/// and the solver takes a patch's consecutive contacts as one; the full
/// island is put in that order too, which changes nothing else.
fn in_patches(task: &IslandTask, reduce: bool) -> IslandTask {
    let mut pairs: BTreeMap<(u32, u32, bool), Vec<usize>> = BTreeMap::new();
    for (k, c) in task.contacts.iter().enumerate() {
        pairs.entry((c.a, c.b, c.near)).or_default().push(k);
    }
    let mut keep = Vec::new();
    for members in pairs.values() {
        let normals: Vec<Vector3<f64>> = members.iter().map(|&k| task.contacts[k].normal).collect();
        for group in patch::patches(&normals) {
            let at: Vec<usize> = group.iter().map(|&g| members[g]).collect();
            if !reduce {
                keep.extend(at);
                continue;
            }
            let points: Vec<Vector3<f64>> = at.iter().map(|&k| task.contacts[k].point).collect();
            let gaps: Vec<f64> = at.iter().map(|&k| task.contacts[k].separation).collect();
            let normal = task.contacts[at[0]].normal;
            keep.extend(patch::kept_points(&points, &normal, &gaps).map(|i| at[i]));
        }
    }
    IslandTask {
        contacts: keep.into_iter().map(|k| task.contacts[k].clone()).collect(),
        ..task.clone()
    }
}

/// Body k's velocity at world point `p` after the step's answer `r`.
fn point_velocity(task: &IslandTask, r: &IslandResult, k: usize, p: &Vector3<f64>) -> Vector3<f64> {
    let body = &task.bodies[k];
    let dv = (r.impulse[k] + r.force[k] * task.dt) * body.inv_mass;
    let dw = body.inv_inertia * (r.angular_impulse[k] + r.torque[k] * task.dt);
    dv + dw.cross(&(p - body.position))
}

/// The largest difference between two answers in a body's velocity at any
/// of the full island's contact points (m/s).
fn largest_difference(task: &IslandTask, x: &IslandResult, y: &IslandResult) -> f64 {
    let mut worst: f64 = 0.0;
    for c in &task.contacts {
        for k in [c.a as usize, c.b as usize] {
            let d = point_velocity(task, x, k, &c.point) - point_velocity(task, y, k, &c.point);
            worst = worst.max(d.norm());
        }
    }
    worst
}

/// One island checked: (rows before, rows after, difference), or None
/// where the full solve is no reference.
fn check(task: &IslandTask) -> Option<(usize, usize, f64)> {
    let task = &in_patches(task, false);
    let full = solve_island(task);
    if full.stats.failed > 0 || full.stats.worst_violation > REFERENCE_VIOLATION {
        return None;
    }
    let small = in_patches(task, true);
    let answer = solve_island(&small);
    let difference = largest_difference(task, &full, &answer);
    Some((task.contacts.len(), small.contacts.len(), difference))
}

#[test]
fn patches_move_the_fixtures_bodies_as_every_point_does() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/islands");
    let mut names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    names.sort();
    let mut checked = 0;
    for path in names {
        let Some((before, after, difference)) = check(&read(&path)) else {
            continue;
        };
        eprintln!(
            "[patches] {}: {before} → {after} contacts, largest difference {difference:.2e} m/s",
            path.file_name().unwrap().to_string_lossy()
        );
        assert!(after <= before);
        assert!(
            difference <= AGREEMENT,
            "{}: {difference:e}",
            path.display()
        );
        checked += 1;
    }
    assert!(checked >= 6, "only {checked} fixtures were references");
}

#[test]
#[ignore = "a measurement over a captured folder: RIGIDSIM_PATCH_ISLANDS=DIR"]
fn patches_over_a_captured_folder() {
    let Ok(dir) = std::env::var("RIGIDSIM_PATCH_ISLANDS") else {
        panic!("set RIGIDSIM_PATCH_ISLANDS to a folder written by --capture-islands");
    };
    let mut paths: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    paths.sort();
    for friction in [true, false] {
        let tasks = paths.iter().map(|p| read(p));
        let tasks = tasks.map(|t| if friction { t } else { frictionless(t) });
        report(
            &tasks.collect::<Vec<_>>(),
            if friction {
                "as captured"
            } else {
                "frictionless"
            },
        );
    }
}

/// The island with every contact's friction taken away.
fn frictionless(mut task: IslandTask) -> IslandTask {
    for c in &mut task.contacts {
        c.friction = 0.0;
        c.warm_friction = Vector3::zeros();
    }
    task
}

/// Checks every island and prints the distribution of the differences.
fn report(tasks: &[IslandTask], what: &str) {
    let (mut before, mut after, mut skipped) = (0, 0, 0);
    let mut differences = Vec::new();
    for task in tasks {
        match check(task) {
            Some((b, a, d)) => {
                before += b;
                after += a;
                differences.push(d);
            }
            None => skipped += 1,
        }
    }
    differences.sort_by(f64::total_cmp);
    let at = |q: f64| differences[((differences.len() - 1) as f64 * q) as usize];
    eprintln!(
        "[patches] {what}: {} islands checked, {skipped} not references; contacts {before} → {after}; \
         difference median {:.1e}, 90 % {:.1e}, 99 % {:.1e}, largest {:.1e} m/s; over {AGREEMENT:e}: {}",
        differences.len(),
        at(0.5),
        at(0.9),
        at(0.99),
        at(1.0),
        differences.iter().filter(|&&d| d > AGREEMENT).count()
    );
}
