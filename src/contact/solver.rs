//! Contact impulses and forces of one island (SPEC 2.4), as a pure function
//! over plain data so any rank can solve any island.
//!
//! Each contact i between bodies A and B at point P with unit normal n (out of
//! B towards A) contributes a normal row and, where μ > 0, two friction rows.
//! A row with direction d has Jacobian J = [d, r_A×d | −d, −r_B×d] and the
//! LCP matrix is A = J M⁻¹ Jᵀ (effect of a unit impulse on row j upon the
//! relative velocity of row i).
//!
//! Two solves per island and step:
//! 1. **Impact** (instantaneous): only when some contact approaches. Normal
//!    rows: V' = A p + V with V = (1+ε)v_N for a collision faster than the
//!    threshold g·dt/2 (SPEC 2.6: slower ones converge to contact, ε = 0), the
//!    LCP V' ≥ 0, p ≥ 0, pᵀV' = 0 (SPEC eq. 3.15). Friction rows stop the
//!    tangential motion with |p_t| ≤ μ p_N.
//! 2. **Resting forces** over the step: the same LCP on the velocities the
//!    bodies would have at the end of the step without contact (v + h·F/m), so
//!    the contact force F = p/h keeps every contact from approaching by the end
//!    of the step (one already separating at its start, at speed u, may close
//!    again at up to u: it still ends no closer than it began, and a body
//!    lifting off is not stopped by a force that carries it up meanwhile).
//!    A body at rest gets exactly its weight back; stacks carry
//!    k·m·g under the k-th body. Friction rows target zero tangential velocity
//!    at the end of the step, bounded by ±μ F_N: a sliding body hits the bound
//!    (kinetic friction), a slow one is stopped (static).
//!
//! The first friction direction is the slip direction (or, at rest, the
//! direction the external forces push), so kinetic friction is exactly
//! opposite the slip and isotropic; the second direction is perpendicular.
//!
//! Each phase's system (`system::PhaseSystem`) goes through the methods
//! the policy chooses for it (`policy`, `chain`, `methods`), and its
//! answer through the checks (`guard`) before it is applied.

use super::chain::{ByBlocks, Chain};
use super::methods::block_sweeps::{BlockRunner, InlineBlocks};
use super::policy::{self, SolverSettings};
use super::restitution::{bounce_basis, meeting_speed};
use super::system::{Phase, PhaseSystem, Row, SEPARATING_EPS, normal_rows};
use super::task::closing_allowed;
use crate::collision::manifold::NormalTurn;
use nalgebra::Vector3;

pub use super::methods::sweeps::projected_gauss_seidel;
pub use super::policy::ITERATIVE_MIN_ROWS;
pub use super::task::{
    FAILURES_KEPT, IslandBody, IslandContact, IslandResult, IslandTask, LARGE_SYSTEM_ROWS,
    SPECULATIVE_GAP, SolveStats,
};

/// Contacts approaching slower than this (m/s) need no impact solve.
const APPROACH_EPS: f64 = 1e-9;

/// Solves one island: impact impulses, then resting forces.
pub fn solve_island(task: &IslandTask) -> IslandResult {
    solve_island_with(task, &mut InlineBlocks)
}

/// The same, with `runner` sweeping the blocks of a large island cut in
/// blocks (`IslandTask::island_blocks`): the same answer whoever sweeps them.
pub fn solve_island_with(task: &IslandTask, runner: &mut dyn BlockRunner) -> IslandResult {
    let Some(merged) = merge_coincident_contacts(task) else {
        return solve_distinct(task, runner);
    };
    let mut r = solve_distinct(&merged.task, runner);
    // Each merged contact's force goes to the first of its copies (which
    // warm-starts the merged contact again next step: see
    // `merge_coincident_contacts`).
    let force = std::mem::take(&mut r.contact_force);
    let friction = std::mem::take(&mut r.contact_friction);
    let carried = std::mem::take(&mut r.carried);
    let pushed = std::mem::take(&mut r.pushed);
    for &(k, first) in &merged.into {
        r.pushed.push(pushed[k]);
        r.contact_force.push(if first { force[k] } else { 0.0 });
        r.contact_friction
            .push(if first { friction[k] } else { Vector3::zeros() });
        r.carried.push(carried[k]);
    }
    r
}

/// Whether the island's solve would sweep it by blocks: cut in blocks,
/// with the rows and moving bodies for the large-island method
/// (`policy::attempts`; each phase decides on its own rows, so this is
/// where the blocks are worth handing to other ranks, not a promise).
pub fn sweeps_by_blocks(task: &IslandTask) -> bool {
    let settings = SolverSettings::default();
    let moving = task.bodies.iter().filter(|b| b.inv_mass > 0.0).count();
    task.island_blocks > 1
        && task.rows() >= task.iterative_min_rows as usize
        && moving > settings.large_island_bodies
}

/// Contacts closer than this (metres) with normals closer than this count
/// as one: the copies, equal to rounding, that a body made of convex parts
/// gives where two parts share a vertex.
const COINCIDENT: f64 = 1e-9;

/// An island with its coincident contacts merged, and where each of the
/// original contacts went (index in the merged task, first copy or not).
struct MergedIsland {
    task: IslandTask,
    into: Vec<(usize, bool)>,
}

/// Merges contacts of one pair at the same point with the same normal, or
/// None if there are none. They are the same row of the LCP twice (the same
/// Jacobian, normal and friction directions), so merging them changes no
/// body's motion: impulses on identical rows act only through their sum,
/// a sum within friction bounds μ(p₁ + p₂) splits into shares within
/// μp₁ and μp₂, and of two targets the more demanding one decides (the
/// copy with the smaller target ends with p = 0), so the merged contact
/// keeps the deeper separation. What it removes is the redundancy: a system
/// with rows repeated is singular, which Dantzig's method meets as broken
/// pivots and compliant retries. The warm starts add up.
fn merge_coincident_contacts(task: &IslandTask) -> Option<MergedIsland> {
    let mut contacts: Vec<IslandContact> = Vec::with_capacity(task.contacts.len());
    let mut into = Vec::with_capacity(task.contacts.len());
    // A pair's contacts are consecutive in the task (`Region::contact_phase`).
    let mut pair_start = 0;
    for c in &task.contacts {
        if contacts
            .last()
            .is_some_and(|last: &IslandContact| (last.a, last.b) != (c.a, c.b))
        {
            pair_start = contacts.len();
        }
        // contacts[pair_start..] are this pair's.
        let copy_of = contacts[pair_start..].iter().position(|k| {
            (k.point - c.point).norm() <= COINCIDENT && (k.normal - c.normal).norm() <= COINCIDENT
        });
        match copy_of {
            Some(k) => {
                let kept = &mut contacts[pair_start + k];
                kept.separation = kept.separation.min(c.separation);
                kept.warm_force += c.warm_force;
                kept.warm_friction += c.warm_friction;
                kept.approach = kept.approach.min(c.approach);
                into.push((pair_start + k, false));
            }
            None => {
                into.push((contacts.len(), true));
                contacts.push(c.clone());
            }
        }
    }
    (contacts.len() < task.contacts.len()).then(|| MergedIsland {
        task: IslandTask {
            bodies: task.bodies.clone(),
            contacts,
            ..*task
        },
        into,
    })
}

/// `solve_island` on an island without coincident contacts.
fn solve_distinct(task: &IslandTask, runner: &mut dyn BlockRunner) -> IslandResult {
    let n = task.bodies.len();
    let mut out = IslandResult {
        impulse: vec![Vector3::zeros(); n],
        angular_impulse: vec![Vector3::zeros(); n],
        force: vec![Vector3::zeros(); n],
        torque: vec![Vector3::zeros(); n],
        ..Default::default()
    };
    let mut v: Vec<Vector3<f64>> = task.bodies.iter().map(|b| b.velocity).collect();
    let mut w: Vec<Vector3<f64>> = task.bodies.iter().map(|b| b.angular_velocity).collect();

    // 1. Impact.
    let start_speed: Vec<f64> = task
        .contacts
        .iter()
        .map(|c| {
            Row::new(&task.bodies, c.a as usize, c.b as usize, &c.point, c.normal).velocity(&v, &w)
        })
        .collect();
    let approaching = task.contacts.iter().zip(&start_speed).any(|(c, &vn)| {
        vn + closing_allowed(c, task.dt) < -APPROACH_EPS
            || bounce_basis(c, vn, task) < -task.restitution_threshold
    });
    let mut pushed = vec![false; task.contacts.len()];
    if approaching {
        let (rows, p, sum) = solve_phase(task, &v, &w, Phase::Impact, &mut out.stats, runner);
        out.normal_impulse_sum = sum;
        for (row, &pi) in rows.iter().zip(&p) {
            row.apply(pi, &mut out.impulse, &mut out.angular_impulse);
            row.change_velocities(pi, &mut v, &mut w);
        }
        for (k, r) in normal_rows(task).into_iter().enumerate() {
            pushed[k] |= p[r] > 0.0;
        }
    }

    // 2. Resting forces on the end-of-step velocities.
    solve_resting(task, (&v, &w), &mut out, &mut pushed, runner);
    out.carried = carried(task, &start_speed, &pushed);
    out.pushed = pushed;
    out
}

/// The resting solve on the velocities `v`, `w` after the impact, where
/// some contact would approach by the end of the step: the forces into
/// `out`, and which contacts pushed into `pushed`.
fn solve_resting(
    task: &IslandTask,
    (v, w): (&[Vector3<f64>], &[Vector3<f64>]),
    out: &mut IslandResult,
    pushed: &mut [bool],
    runner: &mut dyn BlockRunner,
) {
    let vf: Vec<Vector3<f64>> = v
        .iter()
        .zip(&task.bodies)
        .map(|(v, b)| v + b.external_dv)
        .collect();
    let wf: Vec<Vector3<f64>> = w
        .iter()
        .zip(&task.bodies)
        .map(|(w, b)| w + b.external_dw)
        .collect();
    let curvature = curvatures(task, v, w);
    let needed = task.contacts.iter().zip(&curvature).any(|(c, k)| {
        let row = Row::new(&task.bodies, c.a as usize, c.b as usize, &c.point, c.normal);
        let gap = closing_allowed(c, task.dt);
        let allowed = if gap > 0.0 {
            row.velocity(v, w) + 2.0 * gap
        } else {
            0.0
        };
        row.velocity(&vf, &wf) + allowed + k * task.dt < 0.0
    });
    if !needed {
        out.stats.skipped_solves += 1;
        out.contact_force = vec![0.0; task.contacts.len()];
        out.contact_friction = vec![Vector3::zeros(); task.contacts.len()];
        return;
    }
    let (rows, p, sum) = solve_phase(
        task,
        &vf,
        &wf,
        Phase::Resting {
            start: (v, w),
            curvature: &curvature,
        },
        &mut out.stats,
        runner,
    );
    out.normal_force_sum = sum / task.dt;
    for (c, r) in task.contacts.iter().zip(normal_rows(task)) {
        out.contact_force.push(p[r] / task.dt);
        out.contact_friction.push(if c.friction > 0.0 {
            (rows[r + 1].lin * p[r + 1] + rows[r + 2].lin * p[r + 2]) / task.dt
        } else {
            Vector3::zeros()
        });
    }
    for (row, &pi) in rows.iter().zip(&p) {
        row.apply(pi / task.dt, &mut out.force, &mut out.torque);
    }
    for (k, r) in normal_rows(task).into_iter().enumerate() {
        pushed[k] |= p[r] > 0.0;
    }
}

/// Each contact's `gap_curvature` on the velocities `v`, `w`. Below
/// SEPARATING_EPS over the step it is rounding (a resting stack's spins
/// are 1e-9 rad/s): left out, so that near-degenerate resting systems
/// (1 kg under 10 000 kg) see exactly the targets they did.
fn curvatures(task: &IslandTask, v: &[Vector3<f64>], w: &[Vector3<f64>]) -> Vec<f64> {
    let spin_rate: Vec<Vector3<f64>> = task
        .bodies
        .iter()
        .zip(w)
        .map(|(b, w)| gyroscopic(b, w))
        .collect();
    task.contacts
        .iter()
        // A speculative contact's points are apart: the gap's curvature
        // there is no prediction of a touch (a spinning body's far corner
        // turns away within the step), so its row asks only what the
        // velocities give.
        .map(|c| {
            if c.near {
                0.0
            } else {
                gap_curvature(task, c, v, w, &spin_rate)
            }
        })
        .map(|k| {
            if k.abs() * task.dt < SEPARATING_EPS {
                0.0
            } else {
                k
            }
        })
        .collect()
}

/// Per contact, the approach a speculative contact that pushed carries to
/// its pair's next solve (`IslandResult::carried`), where it is faster
/// than the restitution threshold; else zero. `start_speed`: each
/// contact's normal speed at the start of the step.
fn carried(task: &IslandTask, start_speed: &[f64], pushed: &[bool]) -> Vec<f64> {
    let external_dv: Vec<Vector3<f64>> = task.bodies.iter().map(|b| b.external_dv).collect();
    let external_dw: Vec<Vector3<f64>> = task.bodies.iter().map(|b| b.external_dw).collect();
    task.contacts
        .iter()
        .zip(start_speed)
        .zip(pushed)
        .map(|((c, &vn), &pushed)| {
            if pushed && closing_allowed(c, task.dt) > 0.0 {
                let row = Row::new(&task.bodies, c.a as usize, c.b as usize, &c.point, c.normal);
                meeting_speed(task, c, vn, row.velocity(&external_dv, &external_dw))
            } else {
                0.0
            }
        })
        .map(|v| {
            if v < -task.restitution_threshold {
                v
            } else {
                0.0
            }
        })
        .collect()
}

/// The gap's acceleration at contact `c` that the velocities alone give,
/// with no force acting (the velocity-product term J̇v of Baraff's
/// "Fast contact force computation", 1994): along the normal, each contact
/// point's centripetal ω×(ω×r) and gyroscopic ω̇×r acceleration, plus
/// 2ṅ·(v_A − v_B) as the normal turns under the relative velocity. The
/// resting solve's prediction J·(v + h·a) misses it; where it is large (two
/// spinning hulls sliding edge on edge: −245 m/s²) the gap closed again
/// 28 µs after every impact, and a step took 256 impact events of 0.1 µm
/// each (docs/stability.md, *Regression scenes*).
///
/// `spin_rate` is each body's `gyroscopic` ω̇.
fn gap_curvature(
    task: &IslandTask,
    c: &IslandContact,
    v: &[Vector3<f64>],
    w: &[Vector3<f64>],
    spin_rate: &[Vector3<f64>],
) -> f64 {
    let (ia, ib) = (c.a as usize, c.b as usize);
    let (ba, bb) = (&task.bodies[ia], &task.bodies[ib]);
    let (wa, wb) = (w[ia], w[ib]);
    let (ra, rb) = (c.point - ba.position, c.point - bb.position);
    let accel =
        |i: usize, w: &Vector3<f64>, r: &Vector3<f64>| spin_rate[i].cross(r) + w.cross(&w.cross(r));
    let relative_velocity = (v[ia] + wa.cross(&ra)) - (v[ib] + wb.cross(&rb));
    let n = c.normal;
    let turning = match c.turns {
        NormalTurn::WithA => wa.cross(&n),
        NormalTurn::WithB => wb.cross(&n),
        NormalTurn::Edges(ea, eb) => {
            let m = ea.cross(&eb);
            let len = m.norm();
            let dm = wa.cross(&ea).cross(&eb) + ea.cross(&wb.cross(&eb));
            let u = m / len;
            let du = (dm - u * u.dot(&dm)) / len;
            if u.dot(&n) >= 0.0 { du } else { -du }
        }
    };
    n.dot(&(accel(ia, &wa, &ra) - accel(ib, &wb, &rb))) + 2.0 * turning.dot(&relative_velocity)
}

/// How fast torque-free spin still turns ω as the inertia turns:
/// I ω̇ = (I ω) × ω. Zero for fixed and driven bodies (no inverse inertia).
fn gyroscopic(body: &IslandBody, w: &Vector3<f64>) -> Vector3<f64> {
    match body.inv_inertia.try_inverse() {
        Some(inertia) => body.inv_inertia * (inertia * w).cross(w),
        None => Vector3::zeros(),
    }
}

/// Builds and solves the LCP of one phase: the policy's attempts in turn
/// (`policy::attempts`) up to the first answer, then its checks. Returns
/// the rows, their impulses and the sum of the normal impulses.
fn solve_phase(
    task: &IslandTask,
    v: &[Vector3<f64>],
    w: &[Vector3<f64>],
    phase: Phase,
    stats: &mut SolveStats,
    runner: &mut dyn BlockRunner,
) -> (Vec<Row>, Vec<f64>, f64) {
    let system = PhaseSystem::build(task, v, w, phase);
    system.count(stats);
    let settings = SolverSettings::default();
    let by_blocks = (task.island_blocks > 1).then_some(ByBlocks {
        bodies: &task.bodies,
        count: task.island_blocks as usize,
        runner,
    });
    let mut chain = Chain::new(
        &system,
        task.iterative_min_rows,
        v.len(),
        &settings,
        by_blocks,
    );
    let attempts = policy::attempts(&chain.facts, &settings);
    let (attempt, p) = chain.walk(&attempts, stats);
    let p = chain.guard(attempt, p, (v, w), stats);
    let sum = system.normal_sum(&p);
    (system.rows, p, sum)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyId;
    use crate::contact::lcp;
    use crate::contact::methods::dantzig::RowFactorsOf;
    use crate::contact::task::{fixed_body, resting_contact, stacked_cube};
    use nalgebra::Matrix3;

    /// A fixed floor and `n` 1 kg unit bodies stacked on it under gravity
    /// over a 0.01 s step, the top one moving along x at `slide` m/s.
    fn stacked_bodies(n: usize, slide: f64) -> Vec<IslandBody> {
        let mut bodies = vec![fixed_body(Vector3::zeros())];
        for k in 1..=n {
            let velocity = Vector3::new(if k == n { slide } else { 0.0 }, 0.0, 0.0);
            bodies.push(IslandBody {
                external_dv: Vector3::new(0.0, 0.0, -9.81 * 0.01),
                ..stacked_cube(k, velocity)
            });
        }
        bodies
    }

    /// A frictionless stack of `n` 1 kg bodies at rest on a fixed floor, as
    /// an island task (resting phase only: nothing approaches).
    fn resting_stack_task(n: usize, iterative_min_rows: u32) -> IslandTask {
        stack_task(n, &[(0.0, 0.0)], 0.0, 0.0, iterative_min_rows)
    }

    /// A stack of `n` 1 kg cubes (side 1 m) on a fixed floor, each resting
    /// on the one below at its four corners with friction (12 rows a cube:
    /// four corners carry each load, so the rows are redundant and the
    /// impulses not unique). The top cube slides along x at `slide` m/s.
    fn cube_stack_task(n: usize, slide: f64, iterative_min_rows: u32) -> IslandTask {
        let corners = [(0.5, 0.5), (-0.5, 0.5), (-0.5, -0.5), (0.5, -0.5)];
        stack_task(n, &corners, 0.5, slide, iterative_min_rows)
    }

    /// `stacked_bodies`, each on the one below at `points` (x, y) of the
    /// plane between them, with friction coefficient `friction`.
    fn stack_task(
        n: usize,
        points: &[(f64, f64)],
        friction: f64,
        slide: f64,
        iterative_min_rows: u32,
    ) -> IslandTask {
        let mut contacts = Vec::new();
        for k in 0..n {
            for &(x, y) in points {
                contacts.push(resting_contact(
                    k + 1,
                    k,
                    Vector3::new(x, y, k as f64),
                    Vector3::z(),
                    friction,
                ));
            }
        }
        IslandTask {
            bodies: stacked_bodies(n, slide),
            contacts,
            dt: 0.01,
            restitution_threshold: 0.05,
            iterative_min_rows,
            island_blocks: 1,
        }
    }

    /// The interior point on the stack of six cubes (72 rows, from no warm
    /// start), at rest and with the top cube sliding at 1 m/s: each cube's
    /// four corners carry k·m·g together; at rest no friction acts, and
    /// under the sliding cube every contact holds μ·m·g against the slide
    /// (kinetic on top, static below, passed down); every body's velocity
    /// change is Dantzig's (the task with `iterative_min_rows` = u32::MAX,
    /// Dantzig's method alone). To 1e-8 m/s, the conditions' tolerance
    /// (`ITERATIVE_FLOOR`), and in force to what that is over the step,
    /// 1e-8 m/s · 1 kg / 0.01 s = 1e-6 N (seen: 4e-8 N, 2e-10 m/s).
    #[test]
    fn interior_point_holds_a_redundant_stack_as_dantzig_does() {
        let (n, mu, g) = (6, 0.5, 9.81);
        let (mut worst_force, mut worst_velocity) = (0.0f64, 0.0f64);
        for slide in [0.0, 1.0] {
            let task = cube_stack_task(n, slide, ITERATIVE_MIN_ROWS as u32);
            let r = solve_island(&task);
            assert_eq!(r.stats.largest_rows, 72);
            assert_eq!(
                (
                    r.stats.interior_solves,
                    r.stats.lcp_solves,
                    r.stats.iterative_solves
                ),
                (1, 0, 0),
                "{:?}",
                r.stats
            );
            for k in 0..n {
                let load: f64 = r.contact_force[4 * k..4 * k + 4].iter().sum();
                let expected = (n - k) as f64 * g;
                assert!((load - expected).abs() <= 1e-6, "contact {k}: {load} N");
                let friction: Vector3<f64> = r.contact_friction[4 * k..4 * k + 4].iter().sum();
                let held = Vector3::new(-mu * g * slide, 0.0, 0.0);
                assert!(
                    (friction - held).norm() <= 1e-6,
                    "contact {k}: friction {friction}"
                );
                worst_force = worst_force
                    .max((load - expected).abs())
                    .max((friction - held).norm());
            }
            let exact = solve_island(&cube_stack_task(n, slide, u32::MAX));
            assert_eq!(
                (exact.stats.interior_solves, exact.stats.lcp_solves),
                (0, 1)
            );
            for k in 1..=n {
                let change = |r: &IslandResult| {
                    let body = &task.bodies[k];
                    (
                        (r.impulse[k] + r.force[k] * task.dt) * body.inv_mass,
                        body.inv_inertia * (r.angular_impulse[k] + r.torque[k] * task.dt),
                    )
                };
                let ((dv, dw), (ev, ew)) = (change(&r), change(&exact));
                assert!(
                    (dv - ev).norm() <= 1e-8 && (dw - ew).norm() <= 1e-8,
                    "slide {slide}, body {k}: {dv} {dw} vs {ev} {ew}"
                );
                worst_velocity = worst_velocity.max((dv - ev).norm()).max((dw - ew).norm());
            }
        }
        eprintln!(
            "cube stack: worst force {worst_force:.1e} N, worst velocity {worst_velocity:.1e} m/s"
        );
    }

    /// The system sizes and sweeps a solve reports (`summary.json`'s
    /// `counters.solve`): a stack of 320 frictionless bodies is one system
    /// of 320 rows, large, solved iteratively to the LCP's conditions in
    /// fewer sweeps than the cap, carrying the stack's weight;
    /// a stack of 40 solved by Dantzig's method takes no sweeps.
    #[test]
    fn solve_stats_report_system_sizes_and_sweeps() {
        let r = solve_island(&resting_stack_task(320, ITERATIVE_MIN_ROWS as u32));
        let s = &r.stats;
        assert_eq!(
            (s.lcp_solves, s.iterative_solves, s.iterative_unconverged),
            (0, 1, 0)
        );
        assert_eq!((s.largest_rows, s.large_systems), (320, 1));
        let cap = SolverSettings::default().iterative_sweeps as u64;
        assert!(s.iterative_sweeps > 0 && s.iterative_sweeps < cap);
        // The compliance (`ITERATIVE_COMPLIANCE`) costs a chain this long
        // up to 1e-4 of its load: its smallest eigenvalue is about 1.2e-5
        // of its diagonal, so c = 1e-9 moves the load by up to
        // c / 1.2e-5 ≈ 8e-5 (as in `subspace_step_carries_a_tall_stack_from_any_start`).
        let bottom = r.contact_force[0];
        assert!((bottom - 320.0 * 9.81).abs() <= 1e-4 * bottom, "{bottom} N");

        let r = solve_island(&resting_stack_task(40, ITERATIVE_MIN_ROWS as u32));
        let s = &r.stats;
        assert_eq!(
            (s.lcp_solves, s.iterative_solves, s.iterative_sweeps),
            (1, 0, 0)
        );
        assert_eq!((s.largest_rows, s.large_systems), (40, 0));
        let mut all = SolveStats::default();
        all.add(&solve_island(&resting_stack_task(320, 300)).stats);
        all.add(&s.clone());
        assert_eq!((all.largest_rows, all.large_systems), (320, 1));
    }

    /// Dantzig's method with the system's factors (`lcp::RowFactors`) and
    /// with its dense matrix only: on a resting frictionless stack of 80
    /// (80 rows, one answer) both meet the conditions and agree to 1e-12 of
    /// the load; the factors are checked on the way in.
    #[test]
    fn dantzig_with_row_factors_gives_the_dense_answer() {
        let task = resting_stack_task(80, u32::MAX);
        let rows: Vec<Row> = task
            .contacts
            .iter()
            .map(|c| Row::new(&task.bodies, c.a as usize, c.b as usize, &c.point, c.normal))
            .collect();
        let m = rows.len();
        let v: Vec<Vector3<f64>> = task
            .bodies
            .iter()
            .map(|b| b.velocity + b.external_dv)
            .collect();
        let w = vec![Vector3::zeros(); task.bodies.len()];
        let b: Vec<f64> = rows.iter().map(|r| r.velocity(&v, &w)).collect();
        let a: Vec<f64> = (0..m * m)
            .map(|k| rows[k / m].coupling(&rows[k % m]))
            .collect();
        let storage = RowFactorsOf::new(&rows);
        let factors = storage.view(task.bodies.len());
        let dense = lcp::solve_standard(&a, &b).expect("the dense solve");
        let factored = lcp::solve(&lcp::LcpProblem::standard(&a, &b).with_factors(factors))
            .expect("the factored solve");
        let load = dense.x[0];
        assert!((load - 80.0 * 9.81 * 0.01).abs() <= 1e-9 * load, "{load}");
        for (x, y) in dense.x.iter().zip(&factored.x) {
            assert!((x - y).abs() <= 1e-12 * load, "{x} against {y}");
        }
        let wrong = [[0u32, 99]; 80];
        let bad = lcp::RowFactors {
            body: &wrong,
            ..factors
        };
        assert!(matches!(
            lcp::solve(&lcp::LcpProblem::standard(&a, &b).with_factors(bad)),
            Err(lcp::LcpError::InvalidInput { .. })
        ));
    }

    /// A 1 kg cube resting on a fixed floor on its four bottom corners,
    /// pushed sideways by less than friction holds (μ = 0.5, push 0.3 g),
    /// solved (resting phase) with every corner given twice (the
    /// copies 2 µm deeper at two corners) and with the copies merged by
    /// hand: the same forces on the cube to the LCP's tolerance, the
    /// deeper separation deciding, and each copy's force on its first.
    #[test]
    fn coincident_contacts_are_one_row() {
        let floor = fixed_body(Vector3::new(0.0, 0.0, -1.0));
        let cube = IslandBody {
            id: BodyId(1),
            inv_mass: 1.0,
            inv_inertia: Matrix3::identity() * 6.0,
            position: Vector3::new(0.0, 0.0, 0.5),
            external_dv: Vector3::new(0.3 * 9.81, 0.0, -9.81) * 0.01,
            ..floor.clone()
        };
        let corner = |x: f64, y: f64, separation: f64| IslandContact {
            a: 1,
            b: 0,
            point: Vector3::new(x, y, 0.0),
            normal: Vector3::z(),
            restitution: 0.0,
            friction: 0.5,
            separation,
            warm_force: 0.0,
            warm_friction: Vector3::zeros(),
            turns: NormalTurn::WithB,
            approach: 0.0,
            near: false,
        };
        let corners = [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)];
        let deeper = |k: usize| if k < 2 { -2e-6 } else { 0.0 };
        let task = |contacts: Vec<IslandContact>| IslandTask {
            bodies: vec![floor.clone(), cube.clone()],
            contacts,
            dt: 0.01,
            restitution_threshold: 0.05,
            iterative_min_rows: ITERATIVE_MIN_ROWS as u32,
            island_blocks: 1,
        };
        let twice = task(
            corners
                .iter()
                .enumerate()
                .flat_map(|(k, &(x, y))| [corner(x, y, 0.0), corner(x, y, deeper(k))])
                .collect(),
        );
        let once = task(
            corners
                .iter()
                .enumerate()
                .map(|(k, &(x, y))| corner(x, y, deeper(k)))
                .collect(),
        );
        let merged = solve_island(&twice);
        let unmerged = solve_distinct(&twice, &mut InlineBlocks);
        let by_hand = solve_distinct(&once, &mut InlineBlocks);
        assert_eq!(
            merged.stats.rows, 12,
            "four contacts of three rows, one phase"
        );
        assert_eq!(unmerged.stats.rows, 24);
        assert_eq!(merged.force, by_hand.force);
        assert_eq!(merged.torque, by_hand.torque);
        // The copies hold the same total on the cube (Dantzig's answer on
        // 24 rows, verified to its tolerance of 1e-9 of the system's scale).
        let weight = 9.81;
        for (f, g) in merged.force.iter().zip(&unmerged.force) {
            assert!((f - g).norm() <= 1e-8 * weight, "{f:?} against {g:?}");
        }
        for (t, u) in merged.torque.iter().zip(&unmerged.torque) {
            assert!((t - u).norm() <= 1e-8 * weight, "{t:?} against {u:?}");
        }
        // Friction holds the push: the cube takes 0.3 of its weight sideways.
        assert!((merged.force[1].x + 0.3 * weight).abs() <= 1e-9 * weight);
        for k in 0..4 {
            assert_eq!(merged.contact_force[2 * k], by_hand.contact_force[k]);
            assert_eq!(merged.contact_force[2 * k + 1], 0.0);
        }
    }

    /// A 1 m rod at 50° to a fixed floor, its lower end touching, moving at
    /// (2, 0, −2) m/s: one contact, e = 0.9, μ = 1. Newton's restitution
    /// with sticking friction adds 0.095 J here (Kane and Levinson's
    /// paradox); the guard must apply Poisson's restitution instead, not
    /// the frictionless inelastic answer: the compression impulse of the
    /// inelastic solve with friction, then 0.9 times its normal part.
    #[test]
    fn newton_restitution_that_adds_energy_gives_way_to_poisson() {
        let rod = |restitution: f64| {
            let theta = 50f64.to_radians();
            let (l, m) = (1.0, 1.0);
            let dir = Vector3::new(theta.cos(), 0.0, theta.sin());
            let rot = nalgebra::Rotation3::from_axis_angle(&Vector3::y_axis(), -theta);
            let (axial, across) = (m * 0.01 / 6.0, m * l * l / 12.0);
            let local =
                Matrix3::from_diagonal(&Vector3::new(1.0 / axial, 1.0 / across, 1.0 / across));
            let inv_inertia = rot.matrix() * local * rot.matrix().transpose();
            let floor = fixed_body(Vector3::new(0.0, 0.0, -0.1));
            let body = IslandBody {
                id: BodyId(1),
                inv_mass: 1.0 / m,
                inv_inertia,
                position: dir * (l / 2.0),
                velocity: Vector3::new(2.0, 0.0, -2.0),
                ..floor.clone()
            };
            IslandTask {
                bodies: vec![floor, body],
                contacts: vec![IslandContact {
                    a: 1,
                    b: 0,
                    point: Vector3::zeros(),
                    normal: Vector3::z(),
                    restitution,
                    friction: 1.0,
                    separation: 0.0,
                    warm_force: 0.0,
                    warm_friction: Vector3::zeros(),
                    turns: NormalTurn::WithB,
                    approach: 0.0,
                    near: false,
                }],
                dt: 0.01,
                restitution_threshold: 0.05,
                iterative_min_rows: 300,
                island_blocks: 1,
            }
        };
        let energy = |t: &IslandTask, r: &IslandResult| {
            let b = &t.bodies[1];
            let v = b.velocity + r.impulse[1] * b.inv_mass;
            let w = b.angular_velocity + b.inv_inertia * r.angular_impulse[1];
            let inertia = b.inv_inertia.try_inverse().unwrap();
            0.5 * v.norm_squared() / b.inv_mass + 0.5 * w.dot(&(inertia * w))
        };
        let (elastic, inelastic) = (rod(0.9), rod(0.0));
        let before = 0.5 * elastic.bodies[1].velocity.norm_squared();
        let r = solve_island(&elastic);
        assert_eq!(r.stats.failed, 1, "{:?}", r.stats.failures);
        assert!(
            r.stats.failures[0]
                .1
                .contains("Poisson's restitution applied"),
            "{:?}",
            r.stats.failures
        );
        let after = energy(&elastic, &r);
        assert!(
            after <= before,
            "{after} J after the impact against {before} J"
        );
        // The inelastic solve with friction adds nothing and is used as is.
        let c = solve_island(&inelastic);
        assert_eq!(c.stats.failed, 0, "{:?}", c.stats.failures);
        assert!(energy(&inelastic, &c) < after);
        // Poisson: the same friction impulse, 1.9 times the normal one.
        let (pe, pc) = (r.impulse[1], c.impulse[1]);
        assert!(
            (pe.z - 1.9 * pc.z).abs() <= 1e-12 * pc.z,
            "{pe:?} against {pc:?}"
        );
        assert!((pe.x - pc.x).abs() <= 1e-12 * pc.z, "{pe:?} against {pc:?}");
        // It bounces: the contact point leaves the floor.
        let b = &elastic.bodies[1];
        let w = b.inv_inertia * r.angular_impulse[1];
        let vn = (b.velocity + pe * b.inv_mass + w.cross(&-b.position)).z;
        assert!(vn > 0.5, "the end leaves at {vn} m/s");
    }

    /// A 1 kg point-like body above a fixed floor, one frictionless contact
    /// `separation` below it, moving down at `speed` under gravity (1 s
    /// steps of 0.01 s): the island of a speculative or touching contact.
    fn falling_on_floor(separation: f64, speed: f64, near: bool, approach: f64) -> IslandTask {
        let g = 9.81;
        let h = 0.01;
        let floor = fixed_body(Vector3::new(0.0, 0.0, -1.0));
        let body = IslandBody {
            id: BodyId(1),
            inv_mass: 1.0,
            inv_inertia: Matrix3::identity(),
            position: Vector3::new(0.0, 0.0, 0.1 + separation),
            velocity: Vector3::new(0.0, 0.0, -speed),
            external_dv: Vector3::new(0.0, 0.0, -g * h),
            ..floor.clone()
        };
        IslandTask {
            bodies: vec![floor, body],
            contacts: vec![IslandContact {
                a: 1,
                b: 0,
                point: Vector3::new(0.0, 0.0, separation / 2.0),
                normal: Vector3::z(),
                restitution: 0.5,
                friction: 0.0,
                separation,
                warm_force: 0.0,
                warm_friction: Vector3::zeros(),
                turns: NormalTurn::WithB,
                approach,
                near,
            }],
            dt: h,
            restitution_threshold: 0.5 * g * h,
            iterative_min_rows: 300,
            island_blocks: 1,
        }
    }

    /// The body's velocity after the impact phase (u) and at the step's end
    /// (v'), and the gap at the end: separation + h (u + v')/2.
    fn after_step(t: &IslandTask, r: &IslandResult) -> (f64, f64, f64) {
        let b = &t.bodies[1];
        let u = b.velocity.z + r.impulse[1].z * b.inv_mass;
        let end = u + b.external_dv.z + r.force[1].z * t.dt * b.inv_mass;
        let gap = t.contacts[0].separation + t.dt * (u + end) / 2.0;
        (u, end, gap)
    }

    /// A speculative contact 50 µm below a body approaching at 3 cm/s
    /// (it would close 0.79 mm in the step): the gap closes exactly to
    /// `SPECULATIVE_GAP`, with no bounce, and nothing is carried (it would
    /// meet the floor at 4.2 cm/s, below the restitution threshold).
    #[test]
    fn speculative_contact_closes_the_gap_to_its_target_without_a_bounce() {
        let t = falling_on_floor(5e-5, 0.03, true, 0.0);
        let r = solve_island(&t);
        let (u, end, gap) = after_step(&t, &r);
        assert!((gap - SPECULATIVE_GAP).abs() < 1e-15, "gap {gap:e}");
        assert!(u <= 0.0 && end <= 0.0, "bounced: {u} then {end} m/s");
        assert_eq!(r.carried, vec![0.0]);
        // Far enough that the step cannot close it: no force at all.
        let far = falling_on_floor(2e-3, 0.03, true, 0.0);
        let r = solve_island(&far);
        assert_eq!((r.impulse[1].z, r.force[1].z), (0.0, 0.0));
    }

    /// An approach at 1 m/s stopped 0.5 mm short by a speculative contact
    /// is carried (at the speed it would have met the floor with); the next
    /// step's touching contact bounces at e times it, exactly as Newton's
    /// law from the original approach, and
    /// the energy guard lets that rebound through (it gives back no more
    /// than the stop took).
    #[test]
    fn a_deferred_approach_bounces_at_the_step_where_the_bodies_meet() {
        let stop = falling_on_floor(5e-4, 1.0, true, 0.0);
        let r = solve_island(&stop);
        let (u, _, gap) = after_step(&stop, &r);
        assert!((gap - SPECULATIVE_GAP).abs() < 1e-15, "gap {gap:e}");
        // 1 m/s at the start, gravity's 9.81 m/s² over the 0.495 mm closed.
        let meeting = -(1.0f64 + 2.0 * 9.81 * (5e-4 - SPECULATIVE_GAP)).sqrt();
        assert_eq!(r.carried, vec![meeting]);
        // Next step: touching, closing at what the stop left (u plus
        // gravity's step), the carried approach deciding the bounce.
        let meet = falling_on_floor(SPECULATIVE_GAP, -(u - 9.81 * 0.01), false, r.carried[0]);
        let r = solve_island(&meet);
        assert_eq!(r.stats.failed, 0, "{:?}", r.stats.failures);
        let (u, _, _) = after_step(&meet, &r);
        assert!((u + 0.5 * meeting).abs() < 1e-12, "rebound {u} m/s");
        assert_eq!(r.carried, vec![0.0]);
    }
}
