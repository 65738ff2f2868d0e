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

use super::pile_sweeps::{self, PileSweepSettings};
pub use super::system::IslandBody;
use super::system::{IterativeSystem, Row, RowFactorsOf, Step};
use super::{lcp, subspace};
use crate::collision::manifold::NormalTurn;
use crate::collision::narrowphase::CONTACT_TOLERANCE;
use crate::collision::patch::same_normal;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Contacts approaching slower than this (m/s) need no impact solve.
const APPROACH_EPS: f64 = 1e-9;

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct IslandContact {
    /// Indices into `IslandTask::bodies`.
    pub a: u32,
    pub b: u32,
    pub point: Vector3<f64>,
    /// Unit normal out of B towards A.
    pub normal: Vector3<f64>,
    pub restitution: f64,
    pub friction: f64,
    /// Signed gap (negative = overlap) when the contact was found.
    pub separation: f64,
    /// The resting force this contact held in the last solve of its pair
    /// (normal, newtons, and friction, world frame), zero if none: the start
    /// of the iterative solve and of Dantzig's method (warm start).
    pub warm_force: f64,
    pub warm_friction: Vector3<f64>,
    /// How the normal turns with the bodies (for `gap_curvature`).
    pub turns: NormalTurn,
    /// The normal speed (negative: closing) this contact approached at
    /// when a speculative contact of its pair stopped it short in the
    /// pair's last solve (`IslandResult::carried`), zero if none: a touching
    /// contact's impact restitutes from it, so the bounce a speculative
    /// contact deferred is the one the approach had.
    pub approach: f64,
    /// A speculative contact: a near point, apart by more than the contact
    /// tolerance, whose gap may close to `SPECULATIVE_GAP` within the step.
    pub near: bool,
}

/// Separating speeds below this (m/s) count as resting in the resting
/// solve: a stack at rest has contact speeds of rounding size, and letting
/// them in perturbs its redundant systems enough to send some through the
/// compliant retry. A lifting nut rocks at about 1e-3 m/s, far above it.
const SEPARATING_EPS: f64 = 1e-6;

/// Overlap left alone (metres): rounding, and the band time of impact allows.
const OVERLAP_SLOP: f64 = 1e-6;
/// Share of an overlap beyond the slop removed per step by the resting solve
/// (Baumgarte-style stabilisation). Time of impact keeps bodies apart; this
/// only mends what a failed solve or an accepted overlap left behind, at a
/// separating speed of 0.2·depth/dt (2e-4 m/s for 10 µm at dt = 0.01 s).
const OVERLAP_RECOVERY: f64 = 0.2;

/// Overlap (metres) past which the resting solve asks the excess to be gone
/// by the end of its interval (target 2·excess/h: from rest, a constant
/// force opens the gap by h·v'/2). Each impact lets a pair 0.1 µm deeper
/// than it was last solved (`TOI_GAP`), faster than the recovery above
/// mends near the 10 µm tolerance. Just below it, not lower: a lower
/// threshold lifts, and so feeds, a body wobbling on its rim.
const OVERLAP_FIRM: f64 = 0.99 * CONTACT_TOLERANCE;

/// The gap a speculative contact (one apart by more than the contact
/// tolerance) may close to within the step: the middle of the touching band,
/// so that what the linear prediction misses either way still ends touching.
pub const SPECULATIVE_GAP: f64 = 0.5 * CONTACT_TOLERANCE;

/// The speed (m/s) at which a speculative contact (`IslandContact::near`)
/// may close over an interval `dt` and still end apart by
/// `SPECULATIVE_GAP`; zero for a touching contact.
fn closing_allowed(c: &IslandContact, dt: f64) -> f64 {
    if c.near {
        (c.separation - SPECULATIVE_GAP) / dt
    } else {
        0.0
    }
}

/// Contact request for one system (SPEC 3.4).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct IslandTask {
    pub bodies: Vec<IslandBody>,
    pub contacts: Vec<IslandContact>,
    pub dt: f64,
    /// Collisions slower than this converge to contact (ε = 0): g·dt/2.
    pub restitution_threshold: f64,
    /// Rows from which the island is solved by sequential impulses
    /// (`ITERATIVE_MIN_ROWS` unless a test lowers it). `u32::MAX`: by
    /// Dantzig's method alone, without the interior point either (tests
    /// compare the methods so).
    pub iterative_min_rows: u32,
}

/// Contact reply: per body (same order as the task), the impulse applied at
/// the start of the step and the constant contact force over the step.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct IslandResult {
    pub impulse: Vec<Vector3<f64>>,
    pub angular_impulse: Vec<Vector3<f64>>,
    pub force: Vec<Vector3<f64>>,
    pub torque: Vec<Vector3<f64>>,
    /// Total normal impulse of the impact solve and of the resting solve (×h).
    pub normal_impulse_sum: f64,
    pub normal_force_sum: f64,
    /// Resting normal force at each contact, in task order (newtons).
    pub contact_force: Vec<f64>,
    /// Resting friction force at each contact, world frame, in task order.
    pub contact_friction: Vec<Vector3<f64>>,
    /// Per contact in task order: where a speculative contact pushed and
    /// its approach at the start was faster than the restitution threshold,
    /// that approach speed (negative), for the pair's next solve to bounce
    /// from (`IslandContact::approach`); else zero.
    pub carried: Vec<f64>,
    /// Per contact in task order: whether it pushed, in the impact or the
    /// resting solve.
    pub pushed: Vec<bool>,
    pub stats: SolveStats,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct SolveStats {
    pub lcp_solves: u32,
    pub closed_form_solves: u32,
    pub skipped_solves: u32,
    pub rows: u32,
    pub friction_rows: u32,
    pub pivots: u64,
    /// Solves whose exact answer was not used: the LCP failed (and the
    /// compliant retry, where tried) and projected Gauss–Seidel answered, or
    /// the energy guard rejected the answer.
    pub failed: u64,
    /// The first `FAILURES_KEPT` of them, with system size and reason. Only
    /// examples: a long crowd run fails thousands of times, and this list
    /// travels in every reply, summary and checkpoint.
    pub failures: Vec<(u32, String)>,
    /// Solves that failed on the exact system and were solved exactly with
    /// the contacts made slightly compliant (`COMPLIANCE`).
    pub compliant_solves: u32,
    /// Islands of `ITERATIVE_MIN_ROWS` rows or more, solved by sequential
    /// impulses (not counted in `lcp_solves`).
    pub iterative_solves: u32,
    /// Of those, the ones whose answer still missed the LCP's conditions
    /// (`ITERATIVE_RESIDUAL`, `ITERATIVE_FLOOR`) after `ITERATIVE_SWEEPS`
    /// sweeps: solved again by Dantzig's method below `DANTZIG_MAX_ROWS`,
    /// kept above it.
    pub iterative_unconverged: u32,
    /// Solves below `ITERATIVE_MIN_ROWS` that Dantzig's method failed on
    /// (exact and compliant) and the sequential impulses, or after them the
    /// interior point, then solved to the LCP's conditions (not counted in
    /// `failed`).
    pub iterative_rescues: u32,
    /// Sweeps of the iterative solves and rescues, all together (their
    /// cost: a sweep is one pass over the rows; the energy guard's safe
    /// answer is not counted).
    pub iterative_sweeps: u64,
    /// Rows of the largest system solved.
    pub largest_rows: u32,
    /// Systems of `LARGE_SYSTEM_ROWS` rows or more.
    pub large_systems: u32,
    /// The most any answer missed its system's LCP conditions by (m/s,
    /// `violation`): an exact answer's rounding, what an iterative one left
    /// (`iterative_unconverged`), or a failed solve's fallback. Measured
    /// before the energy guard: an answer it replaces is counted in
    /// `failed`, and the safe answer it applies instead (no restitution, or
    /// no friction) meets another system's conditions on purpose.
    pub worst_violation: f64,
    /// Solves answered by the interior-point method (`interior`), its
    /// Newton steps (all its solves), and its solves that missed the
    /// conditions and went on to the other methods.
    pub interior_solves: u32,
    pub interior_steps: u64,
    pub interior_missed: u32,
}

/// Rows from which a system counts in `SolveStats::large_systems`: where
/// Dantzig's method stops being cheap (a system of 300 rows takes it about
/// 0.1 s, docs/architecture.md).
pub const LARGE_SYSTEM_ROWS: usize = 300;

/// Failure examples kept in `SolveStats::failures`.
pub const FAILURES_KEPT: usize = 32;

impl SolveStats {
    fn record_failure(&mut self, rows: usize, why: String) {
        self.failed += 1;
        if self.failures.len() < FAILURES_KEPT {
            self.failures.push((rows as u32, why));
        }
    }

    pub fn add(&mut self, o: &SolveStats) {
        self.lcp_solves += o.lcp_solves;
        self.closed_form_solves += o.closed_form_solves;
        self.skipped_solves += o.skipped_solves;
        self.rows += o.rows;
        self.friction_rows += o.friction_rows;
        self.pivots += o.pivots;
        self.failed += o.failed;
        let room = FAILURES_KEPT.saturating_sub(self.failures.len());
        self.failures.extend(o.failures.iter().take(room).cloned());
        self.compliant_solves += o.compliant_solves;
        self.iterative_solves += o.iterative_solves;
        self.iterative_unconverged += o.iterative_unconverged;
        self.iterative_rescues += o.iterative_rescues;
        self.iterative_sweeps += o.iterative_sweeps;
        self.largest_rows = self.largest_rows.max(o.largest_rows);
        self.large_systems += o.large_systems;
        self.worst_violation = self.worst_violation.max(o.worst_violation);
        self.interior_solves += o.interior_solves;
        self.interior_steps += o.interior_steps;
        self.interior_missed += o.interior_missed;
    }
}

/// Which velocities a solve targets.
#[derive(Clone, Copy)]
enum Phase<'a> {
    Impact,
    /// `start`: the velocities at the start of the step (after any impact),
    /// before the external forces act.
    /// `curvature`: each contact's `gap_curvature`.
    Resting {
        start: (&'a [Vector3<f64>], &'a [Vector3<f64>]),
        curvature: &'a [f64],
    },
}

/// Solves one island: impact impulses, then resting forces.
pub fn solve_island(task: &IslandTask) -> IslandResult {
    let Some(merged) = merge_coincident_contacts(task) else {
        return solve_distinct(task);
    };
    let mut r = solve_distinct(&merged.task);
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
fn solve_distinct(task: &IslandTask) -> IslandResult {
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
        let (rows, p, sum) = solve_phase(task, &v, &w, Phase::Impact, &mut out.stats);
        out.normal_impulse_sum = sum;
        for (row, &pi) in rows.iter().zip(&p) {
            apply(row, pi, &mut out.impulse, &mut out.angular_impulse);
            row.change_velocities(pi, &mut v, &mut w);
        }
        for (k, r) in normal_rows(task).into_iter().enumerate() {
            pushed[k] |= p[r] > 0.0;
        }
    }

    // 2. Resting forces on the end-of-step velocities.
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
    // Below SEPARATING_EPS over the step it is rounding (a resting stack's
    // spins are 1e-9 rad/s): left out, so that near-degenerate resting
    // systems (1 kg under 10 000 kg) see exactly the targets they did.
    let spin_rate: Vec<Vector3<f64>> = task
        .bodies
        .iter()
        .zip(&w)
        .map(|(b, w)| gyroscopic(b, w))
        .collect();
    let curvature: Vec<f64> = task
        .contacts
        .iter()
        // A speculative contact's points are apart: the gap's curvature
        // there is no prediction of a touch (a spinning body's far corner
        // turns away within the step), so its row asks only what the
        // velocities give.
        .map(|c| {
            if c.near {
                0.0
            } else {
                gap_curvature(task, c, &v, &w, &spin_rate)
            }
        })
        .map(|k| {
            if k.abs() * task.dt < SEPARATING_EPS {
                0.0
            } else {
                k
            }
        })
        .collect();
    let needed = task.contacts.iter().zip(&curvature).any(|(c, k)| {
        let row = Row::new(&task.bodies, c.a as usize, c.b as usize, &c.point, c.normal);
        let gap = closing_allowed(c, task.dt);
        let allowed = if gap > 0.0 {
            row.velocity(&v, &w) + 2.0 * gap
        } else {
            0.0
        };
        row.velocity(&vf, &wf) + allowed + k * task.dt < 0.0
    });
    if needed {
        let (rows, p, sum) = solve_phase(
            task,
            &vf,
            &wf,
            Phase::Resting {
                start: (&v, &w),
                curvature: &curvature,
            },
            &mut out.stats,
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
            apply(row, pi / task.dt, &mut out.force, &mut out.torque);
        }
        for (k, r) in normal_rows(task).into_iter().enumerate() {
            pushed[k] |= p[r] > 0.0;
        }
    } else {
        out.stats.skipped_solves += 1;
        out.contact_force = vec![0.0; task.contacts.len()];
        out.contact_friction = vec![Vector3::zeros(); task.contacts.len()];
    }
    let external_dv: Vec<Vector3<f64>> = task.bodies.iter().map(|b| b.external_dv).collect();
    let external_dw: Vec<Vector3<f64>> = task.bodies.iter().map(|b| b.external_dw).collect();
    out.carried = task
        .contacts
        .iter()
        .zip(&start_speed)
        .zip(&pushed)
        .map(|((c, &vn), &pushed)| {
            if pushed && closing_allowed(c, task.dt) > 0.0 {
                meeting_speed(task, c, vn, (&external_dv, &external_dw))
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
        .collect();
    out.pushed = pushed;
    out
}

/// The normal speed at which a speculative contact's gap, closing at `vn`
/// under the external forces' acceleration alone, would have closed to
/// `SPECULATIVE_GAP`: the approach its deferred bounce restitutes from.
/// `external` is each body's velocity change from the external forces.
fn meeting_speed(
    task: &IslandTask,
    c: &IslandContact,
    vn: f64,
    (dv, dw): (&[Vector3<f64>], &[Vector3<f64>]),
) -> f64 {
    let row = Row::new(&task.bodies, c.a as usize, c.b as usize, &c.point, c.normal);
    let closing_accel = (-row.velocity(dv, dw) / task.dt).max(0.0);
    let gap = (c.separation - SPECULATIVE_GAP).max(0.0);
    -(vn * vn + 2.0 * closing_accel * gap).sqrt()
}

/// The normal speed a touching contact's impact restitutes from: its own
/// `vn`, or the approach a speculative contact deferred (`approach`) where
/// that was faster. Speculative contacts do not bounce.
fn bounce_basis(c: &IslandContact, vn: f64, task: &IslandTask) -> f64 {
    if closing_allowed(c, task.dt) > 0.0 {
        0.0
    } else if c.approach < 0.0 && c.approach < vn {
        c.approach
    } else {
        vn
    }
}

/// Per contact, whether Newton's law applies at its impact: where any
/// touching point of its contact patch approaches faster than the
/// restitution threshold, every touching point of the patch restitutes from
/// its own approach. A patch is one contact: one rule over it keeps its rows
/// affine in the point, so the hull of its points (`collision::patch`)
/// answers as all of them do. A patch: consecutive contacts of one pair
/// whose normals agree (`patch::same_normal`), as the narrowphase gives
/// them. `speeds` are the contacts' normal speeds.
fn patches_that_bounce(task: &IslandTask, speeds: &[f64]) -> Vec<bool> {
    let fast: Vec<bool> = task
        .contacts
        .iter()
        .zip(speeds)
        .map(|(c, &vn)| {
            closing_allowed(c, task.dt) == 0.0
                && bounce_basis(c, vn, task) < -task.restitution_threshold
        })
        .collect();
    let mut bounces = vec![false; fast.len()];
    let mut start = 0;
    while start < fast.len() {
        let first = &task.contacts[start];
        let end = (start + 1..fast.len())
            .find(|&k| {
                let c = &task.contacts[k];
                (c.a, c.b) != (first.a, first.b) || !same_normal(&c.normal, &first.normal)
            })
            .unwrap_or(fast.len());
        let any = fast[start..end].iter().any(|&f| f);
        for (bounce, c) in bounces[start..end]
            .iter_mut()
            .zip(&task.contacts[start..end])
        {
            *bounce = any && closing_allowed(c, task.dt) == 0.0;
        }
        start = end;
    }
    bounces
}

/// Index of each contact's normal row in the row list `solve_phase` builds.
fn normal_rows(task: &IslandTask) -> Vec<usize> {
    let mut at = 0;
    task.contacts
        .iter()
        .map(|c| {
            let here = at;
            at += if c.friction > 0.0 { 3 } else { 1 };
            here
        })
        .collect()
}

fn apply(row: &Row, p: f64, lin: &mut [Vector3<f64>], ang: &mut [Vector3<f64>]) {
    lin[row.a] += row.lin * p;
    ang[row.a] += row.ang_a * p;
    lin[row.b] -= row.lin * p;
    ang[row.b] += row.ang_b * p;
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

/// Builds and solves the LCP of one phase. Returns the rows, their impulses
/// and the sum of the normal impulses.
fn solve_phase(
    task: &IslandTask,
    v: &[Vector3<f64>],
    w: &[Vector3<f64>],
    phase: Phase,
    stats: &mut SolveStats,
) -> (Vec<Row>, Vec<f64>, f64) {
    // At most three rows a contact (its normal and two friction rows),
    // reserved at once: grown a row at a time they were 2 % of the
    // pyramid's instructions.
    let most = 3 * task.contacts.len();
    let mut rows = Vec::with_capacity(most);
    let mut rhs = Vec::with_capacity(most);
    let mut lo = Vec::with_capacity(most);
    let mut hi = Vec::with_capacity(most);
    let mut findex = Vec::with_capacity(most);
    // Warm start of the iterative solve: last solve's impulses over this
    // phase's interval (resting phase only; an impact has no history).
    let mut warm = Vec::with_capacity(most);
    // Each row's velocity-product term over the interval (`gap_curvature`):
    // the energy guard counts it as velocity the row already has.
    let mut bias = Vec::with_capacity(most);
    // Each row's coefficient of restitution where the impact applies one.
    let mut restitution = Vec::with_capacity(most);
    let resting = matches!(phase, Phase::Resting { .. });
    let normals: Vec<Row> = task
        .contacts
        .iter()
        .map(|c| Row::new(&task.bodies, c.a as usize, c.b as usize, &c.point, c.normal))
        .collect();
    let speeds: Vec<f64> = normals.iter().map(|row| row.velocity(v, w)).collect();
    let bounces = match phase {
        Phase::Impact => patches_that_bounce(task, &speeds),
        Phase::Resting { .. } => vec![false; task.contacts.len()],
    };
    let mut deferred = 0.0;
    for ((ci, c), normal) in task.contacts.iter().enumerate().zip(normals) {
        let (a, b) = (c.a as usize, c.b as usize);
        let vn = speeds[ci];
        let speculative = closing_allowed(c, task.dt);
        let basis = bounce_basis(c, vn, task);
        let b_n = match phase {
            // A speculative contact: the gap may close to `SPECULATIVE_GAP`
            // at the speed it starts with (no restitution: its approach is
            // slower than the speculative speed, `step::contact`).
            Phase::Impact if speculative > 0.0 => vn + speculative,
            // Newton's law from the approach, its own or the deferred one.
            Phase::Impact if basis < vn && bounces[ci] => vn + c.restitution * basis,
            Phase::Impact if bounces[ci] => (1.0 + c.restitution) * vn,
            Phase::Impact => vn,
            // Over the step its gap changes by h (u + v')/2, u its speed
            // after the impact phase: it may end closed to the same gap.
            Phase::Resting { start, curvature } if speculative > 0.0 => {
                let u = normal.velocity(start.0, start.1);
                vn + u + 2.0 * speculative + curvature[ci] * task.dt
            }
            // w = v' − u ≥ 0 asks for a separating speed u that mends overlap.
            // A contact already separating at the step's start (speed u > 0)
            // may end it closing at up to u: over the step its gap changes
            // by h (u + v')/2 ≥ 0, so it never ends closer than it began.
            // Asking v' ≥ 0 instead makes the solve stop a body that is
            // lifting off and rocking, while the constant force of the step
            // still carries it up by h·u/2: a rocking nut gained 1.2e-5 J
            // each time, and never came to rest.
            Phase::Resting { start, curvature } => {
                let u = normal.velocity(start.0, start.1);
                let separating = if u > SEPARATING_EPS { u } else { 0.0 };
                vn + separating + curvature[ci] * task.dt
                    - OVERLAP_RECOVERY * (-c.separation - OVERLAP_SLOP).max(0.0) / task.dt
                    - 2.0 * (-c.separation - OVERLAP_FIRM).max(0.0) / task.dt
            }
        };
        bias.push(match phase {
            Phase::Resting { curvature, .. } => curvature[ci] * task.dt,
            Phase::Impact => 0.0,
        });
        // The energy a deferred approach lost at its speculative contact,
        // which its bounce may give back (`energy_guard`): the most of any
        // one row's, as a patch's points carry the same approach of one
        // body and their sum would count it once a point.
        if matches!(phase, Phase::Impact) && basis < vn.min(0.0) {
            let a_nn = normal.coupling(&normal);
            if a_nn > 0.0 {
                deferred = f64::max(deferred, 0.5 * (basis * basis - vn.min(0.0).powi(2)) / a_nn);
            }
        }
        restitution.push(match phase {
            Phase::Impact if speculative > 0.0 => 0.0,
            Phase::Impact if bounces[ci] => c.restitution,
            _ => 0.0,
        });
        let ni = rows.len();
        rows.push(normal);
        rhs.push(b_n);
        lo.push(0.0);
        hi.push(f64::INFINITY);
        findex.push(None);
        warm.push(if resting { c.warm_force * task.dt } else { 0.0 });
        if c.friction > 0.0 {
            let t1 = friction_direction(task, c, v, w);
            let t2 = c.normal.cross(&t1);
            for t in [t1, t2] {
                let row = Row::new(&task.bodies, a, b, &c.point, t);
                warm.push(if resting {
                    c.warm_friction.dot(&t) * task.dt
                } else {
                    0.0
                });
                rhs.push(row.velocity(v, w));
                bias.push(0.0);
                restitution.push(0.0);
                rows.push(row);
                // Friction bounds are coefficients of the normal impulse: |p_t| ≤ μ p_N.
                lo.push(-c.friction);
                hi.push(c.friction);
                findex.push(Some(ni));
                stats.friction_rows += 1;
            }
        }
    }
    let m = rows.len();
    stats.rows += m as u32;
    stats.largest_rows = stats.largest_rows.max(m as u32);
    if m >= LARGE_SYSTEM_ROWS {
        stats.large_systems += 1;
    }
    let normal_sum = |p: &[f64]| {
        p.iter()
            .zip(&findex)
            .filter(|(_, f)| f.is_none())
            .map(|(x, _)| x)
            .sum()
    };

    // Single frictionless contact: closed form (SPEC eq. 3.17), no solver.
    if m == 1 {
        stats.closed_form_solves += 1;
        let a00 = rows[0].coupling(&rows[0]);
        let p = if a00 > 0.0 {
            (-rhs[0] / a00).max(0.0)
        } else {
            0.0
        };
        return (rows, vec![p], p);
    }

    // A_ii, for the iterative solve and the energy guard.
    let diag: Vec<f64> = rows.iter().map(|r| r.coupling(r)).collect();
    // Large islands (stacks of 50, piles): sequential impulses with the
    // subspace step on the rows, no dense matrix (see `ITERATIVE_MIN_ROWS`).
    // An answer that misses the conditions is handed to Dantzig's method
    // below `DANTZIG_MAX_ROWS`, and kept if that fails too.
    let sweeps_from = |start: &[f64], max_sweeps| {
        sequential_impulses(
            &rows,
            &diag,
            &rhs,
            &lo,
            &hi,
            &findex,
            start,
            v.len(),
            max_sweeps,
        )
    };
    let sweeps_of = |max_sweeps| sweeps_from(&warm, max_sweeps);
    let system = IterativeSystem::new(&rows, &diag, &rhs, &lo, &hi, &findex);
    let iterative = m >= task.iterative_min_rows as usize;
    // Asked only below `ITERATIVE_MIN_ROWS` (where the start sweeps and the
    // interior point wait for it); from there the sweeps' warm subspace
    // step tells the same.
    let warm_is_close = !iterative
        && m >= FACTORED_MIN_ROWS
        && system.worst_miss(&system.warm_state(&warm, v.len())) <= WARM_CLOSE;
    // An answer of the iterative system (the sweeps' or the interior
    // point's): its violation noted, the energy guard's iterative check.
    let keep = |p: Vec<f64>, stats: &mut SolveStats| {
        note_violation(&rows, &rhs, &lo, &hi, &findex, &p, v.len(), stats);
        let p = guard_iterative(&diag, &rows, &findex, (v, w, &bias, deferred), p, stats);
        let sum = normal_sum(&p);
        (p, sum)
    };
    // Large islands of many moving bodies (piles): the large-island
    // method alone (`pile_sweeps`).
    if m >= task.iterative_min_rows as usize
        && super::interior::is_large(super::interior::moving_count(&rows, v.len()))
    {
        let answer = pile_sweeps::solve(&system, &warm, v.len(), &PileSweepSettings::default());
        stats.iterative_solves += 1;
        stats.iterative_sweeps += answer.sweeps as u64;
        if !answer.met {
            stats.iterative_unconverged += 1;
        }
        let (p, sum) = keep(answer.p, stats);
        return (rows, p, sum);
    }
    // Whether the interior point is tried first: from `INTERIOR_MIN_ROWS`
    // rows, on an island of few enough moving bodies for its Newton
    // systems (the large ones took the large-island method above).
    let interior_first = m >= INTERIOR_MIN_ROWS
        && task.iterative_min_rows != u32::MAX
        && (iterative || !warm_is_close);
    // The interior point's answer where it missed the conditions: where
    // the sweeps follow, they start from it (`SWEEPS_AFTER_INTERIOR`).
    let mut missed = None;
    if interior_first {
        // A system at rest (a stack) meets the conditions in the warm
        // start's subspace step, a stack's impact in a few sweeps.
        if iterative {
            let (p, met, sweeps) = sweeps_of(ITERATIVE_CHECK_EVERY);
            stats.iterative_sweeps += sweeps as u64;
            if met {
                stats.iterative_solves += 1;
                let (p, sum) = keep(p, stats);
                return (rows, p, sum);
            }
        }
        // Below `ITERATIVE_MIN_ROWS`, where Dantzig's answers are, on the
        // exact system: no compliance.
        let strict = IterativeSystem {
            compliance: if iterative { system.compliance } else { 0.0 },
            ..system
        };
        if let Some(answer) = super::interior::solve(&strict, &warm, v.len()) {
            stats.interior_steps += answer.steps as u64;
            if answer.met {
                stats.interior_solves += 1;
                let (p, sum) = keep(answer.p, stats);
                return (rows, p, sum);
            }
            stats.interior_missed += 1;
            missed = Some(answer.p);
        }
    }
    let mut unconverged = None;
    if m >= task.iterative_min_rows as usize {
        stats.iterative_solves += 1;
        let (p, met, sweeps) = match &missed {
            Some(start) => sweeps_from(start, SWEEPS_AFTER_INTERIOR),
            None => sweeps_of(ITERATIVE_SWEEPS),
        };
        stats.iterative_sweeps += sweeps as u64;
        if !met {
            stats.iterative_unconverged += 1;
        }
        if met || m >= DANTZIG_MAX_ROWS {
            let (p, sum) = keep(p, stats);
            return (rows, p, sum);
        }
        unconverged = Some(p);
    }
    // Below that, from `FACTORED_MIN_ROWS` rows: a few sweeps first, whose
    // answer is where Dantzig's method starts (`START_SWEEPS`), unless the
    // last step's impulses are that close already (`WARM_CLOSE`).
    let swept = (unconverged.is_none()
        && m >= FACTORED_MIN_ROWS
        && m < task.iterative_min_rows as usize
        && !warm_is_close)
        .then(|| {
            let (p, met, sweeps) = sweeps_of(START_SWEEPS);
            stats.iterative_sweeps += sweeps as u64;
            (p, met)
        });

    let mut a = vec![0.0; m * m];
    for i in 0..m {
        for j in 0..m {
            a[i * m + j] = rows[i].coupling(&rows[j]);
        }
    }
    stats.lcp_solves += 1;
    // A's factors, so that Dantzig's drive updates w in O(rows) a pivot,
    // from `FACTORED_MIN_ROWS` rows.
    let factors = (m >= FACTORED_MIN_ROWS).then(|| RowFactorsOf::new(&rows));
    // Dantzig's method starts from the iterative answer that missed the
    // conditions, or from the start sweeps' answer, else from the last
    // step's impulses where there are any: the sets they imply are most of
    // the answer's (`lcp::LcpProblem::start`).
    // From `FACTORED_MIN_ROWS` rows, like the factors: below, the small
    // exact cases keep the rounding of a fresh start.
    let warm_started = m >= FACTORED_MIN_ROWS;
    let start = unconverged
        .clone()
        .or_else(|| swept.as_ref().map(|(p, _)| p.clone()))
        .or_else(|| warm.iter().any(|&x| x != 0.0).then(|| warm.clone()))
        .filter(|_| warm_started);
    let options = lcp::LcpOptions {
        resume_passes: warm_started,
        ..Default::default()
    };
    let problem = lcp::LcpProblem {
        a: &a,
        b: &rhs,
        lo: &lo,
        hi: &hi,
        findex: &findex,
        factors: factors.as_ref().map(|f| f.view(v.len())),
        start: start.as_deref(),
    };
    // One workspace per thread: no allocation per solve once warmed up.
    thread_local! {
        static WORKSPACE: std::cell::RefCell<lcp::LcpWorkspace> = std::cell::RefCell::new(lcp::LcpWorkspace::new());
    }
    let solve = |a: &[f64], options: &lcp::LcpOptions| {
        let problem = lcp::LcpProblem { a, ..problem };
        WORKSPACE.with(|ws| ws.borrow_mut().solve(&problem, options))
    };
    let p = match solve(&a, &options) {
        Ok(sol) => {
            stats.pivots += sol.pivots as u64;
            sol.x
        }
        // Retried once on the slightly compliant system: it removes the
        // broken factors of redundant contacts, and its friction bounds
        // settle where the singular system's cycled (the pyramid's do). Up
        // to COMPLIANT_RETRY_ROWS only: compliance clamps every redundant
        // row too, and on the 800 rows of a stack of 50 one retry took
        // seconds, where Gauss-Seidel takes milliseconds.
        Err(e) => {
            let retried = (m <= COMPLIANT_RETRY_ROWS).then(|| solve(&compliant(&a, m), &options));
            match retried {
                Some(Ok(sol)) => {
                    stats.pivots += sol.pivots as u64;
                    stats.compliant_solves += 1;
                    sol.x
                }
                // Where Dantzig's friction passes cycle on both systems (the
                // bounds follow normal impulses that move with them), the
                // sequential impulses with the subspace step may still meet
                // the conditions (to `ITERATIVE_RESIDUAL` on the
                // `ITERATIVE_COMPLIANCE` system): their answer if they do.
                // Else the interior point on the exact system, where it was
                // not tried first (below `INTERIOR_MIN_ROWS`, or where the
                // last impulses were close enough for Dantzig's method): on
                // the 1000-body pile's 1.0-1.1 s it met all four small
                // islands that ended here, whose fallback answers had
                // missed the conditions by 1e-2 to 3e-2 m/s.
                _ => match unconverged
                    .is_none()
                    .then(|| match swept.clone() {
                        // The start sweeps' answer, where it met the conditions.
                        Some((p, met)) => (p, met, 0),
                        None => sweeps_of(ITERATIVE_SWEEPS),
                    })
                    .inspect(|&(_, _, sweeps)| stats.iterative_sweeps += sweeps as u64)
                    .filter(|&(_, met, _)| met)
                    .map(|(p, _, _)| p)
                    .or_else(|| {
                        let untried = !interior_first && task.iterative_min_rows != u32::MAX;
                        untried
                            .then(|| interior_rescue(&system, &warm, v.len(), stats))
                            .flatten()
                    }) {
                    Some(p) => {
                        stats.iterative_rescues += 1;
                        p
                    }
                    None => {
                        stats.record_failure(m, e.to_string());
                        unconverged
                            .or(swept.map(|(p, _)| p))
                            .unwrap_or_else(|| fallback(&a, m, &rhs, &lo, &hi, &findex))
                    }
                },
            }
        }
    };
    note_violation(&rows, &rhs, &lo, &hi, &findex, &p, v.len(), stats);
    let p = energy_guard(&diag, &rows, (v, w, &bias, deferred), p, stats, |vel| {
        safe_answers(&a, m, vel, &lo, &hi, &findex, &restitution)
    });
    let sum = normal_sum(&p);
    (rows, p, sum)
}

/// Records in `stats.worst_violation` how far `p` misses the LCP
/// conditions of its system (`violation`).
#[allow(clippy::too_many_arguments)]
fn note_violation(
    rows: &[Row],
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    findex: &[Option<usize>],
    p: &[f64],
    bodies: usize,
    stats: &mut SolveStats,
) {
    let v = violation(rows, b, lo, hi, findex, p, bodies);
    stats.worst_violation = stats.worst_violation.max(v);
}

/// How far impulses `p` miss the conditions of the system w = A p + b
/// (friction bounds ±μ times the normal row's impulse), in m/s: per row,
/// the velocity on the side its bound does not allow (w < 0 at a lower
/// bound, w > 0 at an upper one), and between its bounds the smaller of
/// |w| and the velocity change A_ii·(p − bound) that would take it to the
/// bound where its w is allowed (a friction row whose normal impulse is
/// 1e-13 has bounds that close: it may slip); a bound overstepped counts
/// times A_ii. Computed through the bodies' velocity change, independent of
/// the method that found p. Zero for an exact answer up to rounding.
pub(super) fn violation(
    rows: &[Row],
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    findex: &[Option<usize>],
    p: &[f64],
    bodies: usize,
) -> f64 {
    let (mut dv, mut dw) = (
        vec![Vector3::zeros(); bodies],
        vec![Vector3::zeros(); bodies],
    );
    for (row, &pi) in rows.iter().zip(p) {
        row.change_velocities(pi, &mut dv, &mut dw);
    }
    let mut worst = 0.0f64;
    for (i, row) in rows.iter().enumerate() {
        let (l, h) = match findex[i] {
            None => (lo[i], hi[i]),
            Some(j) => (lo[i] * p[j].abs(), hi[i] * p[j].abs()),
        };
        let w = b[i] + row.velocity(&dv, &dw);
        let a_ii = row.coupling(row);
        let side = match (p[i] <= l, p[i] >= h) {
            (true, true) => 0.0,
            (true, false) => (-w).max(0.0),
            (false, true) => w.max(0.0),
            (false, false) if w > 0.0 => w.min(a_ii * (p[i] - l)),
            (false, false) => (-w).min(a_ii * (h - p[i])),
        };
        let outside = (l - p[i]).max(p[i] - h).max(0.0) * a_ii;
        worst = worst.max(side).max(outside);
    }
    worst
}

/// Answers to a contact system that add no energy, for the energy guard,
/// best first; `vel` is each row's own velocity (its target with no
/// restitution, overlap mending or separation allowance).
///
/// With e = 0 the LCP w = A p + vel, friction bounds included, cannot add
/// energy: ΔKE = pᵀvel + ½pᵀAp = pᵀw − ½pᵀAp, where pᵀw is zero on normal
/// rows and ≤ 0 on friction rows at their bounds. Newton's restitution
/// (target −e·v_N) with friction can (Kane and Levinson's paradox): in the
/// 200-body pours every guard rejection was a nut's single contact with
/// friction at impact. So, in turn:
/// 1. Poisson's restitution: that inelastic answer (the compression),
///    then each contact's normal impulse again times its e (a rebound with
///    no friction);
/// 2. the inelastic answer itself;
/// 3. the frictionless, inelastic LCP on the normal rows.
fn safe_answers(
    a: &[f64],
    m: usize,
    vel: &[f64],
    lo: &[f64],
    hi: &[f64],
    findex: &[Option<usize>],
    restitution: &[f64],
) -> Vec<(&'static str, Vec<f64>)> {
    let mut out = Vec::new();
    let inelastic = lcp::LcpProblem {
        a,
        b: vel,
        lo,
        hi,
        findex,
        factors: None,
        start: None,
    };
    if let Ok(sol) = lcp::solve(&inelastic) {
        if restitution.iter().any(|&e| e > 0.0) {
            // `restitution` is zero on friction rows.
            let rebound: Vec<f64> = sol
                .x
                .iter()
                .zip(restitution)
                .map(|(p, e)| p * (1.0 + e))
                .collect();
            out.push(("Poisson's restitution", rebound));
        }
        out.push(("the inelastic answer with friction", sol.x));
    }
    if let Some(p) = solve_normal_rows(a, m, vel, findex) {
        out.push(("the frictionless inelastic answer", p));
    }
    out
}

/// The energy guard of an iterative solve; its safe answer is the
/// frictionless, inelastic solve by the same method: coordinate descent on
/// the energy from p = 0, so it cannot add any.
fn guard_iterative(
    diag: &[f64],
    rows: &[Row],
    findex: &[Option<usize>],
    velocities: Velocities,
    p: Vec<f64>,
    stats: &mut SolveStats,
) -> Vec<f64> {
    let m = rows.len();
    let bodies = velocities.0.len();
    energy_guard(diag, rows, velocities, p, stats, |vel| {
        let normal_hi: Vec<f64> = findex
            .iter()
            .map(|f| if f.is_none() { f64::INFINITY } else { 0.0 })
            .collect();
        let zero = vec![0.0; m];
        let (p, _, _) = sequential_impulses(
            rows,
            diag,
            vel,
            &zero,
            &normal_hi,
            findex,
            &zero,
            bodies,
            ITERATIVE_SWEEPS,
        );
        vec![("the frictionless inelastic answer", p)]
    })
}

/// The body velocities a solve acts on, each row's bias, and the kinetic
/// energy (J) deferred bounces may give back (see `energy_guard`).
type Velocities<'a> = (&'a [Vector3<f64>], &'a [Vector3<f64>], &'a [f64], f64);

/// Compliance added to the diagonal of a contact system the exact solve
/// failed on, relative to its largest diagonal entry. Redundant contacts (a
/// pyramid, a box on four corners) make A singular; Dantzig's method keeps
/// dependent rows out of the clamped set, but rounding can still let one in,
/// and its near-zero pivot then ruins the factor ("negative pivot"). With
/// A + εI every clamped block is positive definite with condition ≤ 1/ε.
/// The answer solves w = (A + εI) p + b exactly: a contact holding impulse p
/// closes at ε·A_max·p, e.g. 1e-8 · 0.3 /kg · 0.8 N s = 2.4e-9 m/s for the
/// 8 kg boxes of a resting stack (24 pm per step, which the overlap recovery
/// of the next step removes) — the constraint-force mixing of ODE and
/// Bullet, used here only where the exact solve failed.
const COMPLIANCE: f64 = 1e-8;

/// Largest system retried with compliance (see `solve_phase`).
const COMPLIANT_RETRY_ROWS: usize = 400;

fn compliant(a: &[f64], m: usize) -> Vec<f64> {
    let scale = (0..m).map(|i| a[i * m + i]).fold(0.0, f64::max);
    let mut reg = a.to_vec();
    for i in 0..m {
        reg[i * m + i] += COMPLIANCE * scale;
    }
    reg
}

/// Share of the contacts' kinetic energy a solve may add before it is
/// rejected. Simultaneous restitution can add a little (Stronge's examples);
/// a solve that adds more is numerically wrong (a near-singular system), and
/// once applied it can fling a body at hundreds of m/s.
const ENERGY_GAIN_ALLOWED: f64 = 0.01;

/// Rejects a solution that adds kinetic energy. The change is
/// ΔKE = pᵀJv + ½ pᵀAp, summed here body by body (P·v + ½ P·ΔV with P the
/// impulse a body receives and ΔV = M⁻¹P): on a near-singular system a
/// wrong answer can hold impulses of 1e14 whose effects almost cancel in
/// the rows, and the quadratic form in A loses that to rounding while the
/// bodies still fly off. The frictionless, inelastic LCP on the same rows
/// (w = A_N p + J_N v ≥ 0, p ≥ 0) is the minimiser of that quadratic over
/// p ≥ 0, and p = 0 is feasible, so it can never add energy: it replaces a
/// rejected solution (reported as a failure with the system size).
///
/// A row's `bias` (the gap's curvature over the interval, `gap_curvature`)
/// counts as velocity it already has: an impulse that holds a curving gap
/// open does no work on the real motion, though the linear prediction of
/// the velocities says it does. A bounce a speculative contact deferred
/// (`IslandContact::approach`) gives back at most the energy its approach
/// lost then, `deferred`, which is allowed on top.
fn energy_guard(
    diag: &[f64],
    rows: &[Row],
    (v, w, bias, deferred): Velocities,
    p: Vec<f64>,
    stats: &mut SolveStats,
    safe_solves: impl FnOnce(&[f64]) -> Vec<(&'static str, Vec<f64>)>,
) -> Vec<f64> {
    let m = rows.len();
    let gain = |x: &[f64]| {
        let n = v.len();
        let (mut lin, mut ang) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
        let (mut dv, mut dw) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
        for (row, &pi) in rows.iter().zip(x) {
            apply(row, pi, &mut lin, &mut ang);
            row.change_velocities(pi, &mut dv, &mut dw);
        }
        let e: f64 = (0..n)
            .map(|i| lin[i].dot(&(v[i] + 0.5 * dv[i])) + ang[i].dot(&(w[i] + 0.5 * dw[i])))
            .sum::<f64>()
            + x.iter().zip(bias).map(|(pi, b)| pi * b).sum::<f64>();
        if e.is_finite() { e } else { f64::INFINITY }
    };
    // The kinetic energy the rows see: Σ ½ v_i² / A_ii.
    let vel: Vec<f64> = rows
        .iter()
        .zip(bias)
        .map(|(r, b)| r.velocity(v, w) + b)
        .collect();
    let scale: f64 = (0..m)
        .filter(|&i| diag[i] > 0.0)
        .map(|i| 0.5 * vel[i] * vel[i] / diag[i])
        .sum();
    let allowed = |x: &[f64]| gain(x) <= ENERGY_GAIN_ALLOWED * scale + deferred + 1e-12;
    if allowed(&p) {
        return p;
    }
    let added = gain(&p);
    // The first safe answer that passes; if none does (rounding), nothing
    // is applied this step.
    let (name, safe) = safe_solves(&vel)
        .into_iter()
        .find(|(_, x)| allowed(x))
        .unwrap_or(("nothing", vec![0.0; m]));
    stats.record_failure(
        m,
        format!("solution added {added:.3e} J of kinetic energy; {name} applied instead"),
    );
    safe
}

/// Slip direction at the contact, or where external forces push when at rest.
fn friction_direction(
    task: &IslandTask,
    c: &IslandContact,
    v: &[Vector3<f64>],
    w: &[Vector3<f64>],
) -> Vector3<f64> {
    let n = c.normal;
    let (a, b) = (c.a as usize, c.b as usize);
    let (ba, bb) = (&task.bodies[a], &task.bodies[b]);
    let rel = |va: &Vector3<f64>, wa: &Vector3<f64>, vb: &Vector3<f64>, wb: &Vector3<f64>| {
        (va + wa.cross(&(c.point - ba.position))) - (vb + wb.cross(&(c.point - bb.position)))
    };
    let vel = rel(&v[a], &w[a], &v[b], &w[b]);
    let slip = vel - n * n.dot(&vel);
    if slip.norm() > 1e-9 {
        return slip.normalize();
    }
    let push = rel(
        &ba.external_dv,
        &ba.external_dw,
        &bb.external_dv,
        &bb.external_dw,
    );
    let push = push - n * n.dot(&push);
    if push.norm() > 1e-12 {
        return push.normalize();
    }
    // Any tangent, chosen deterministically from the normal.
    let helper = if n.x.abs() < 0.6 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    (helper - n * n.dot(&helper)).normalize()
}

/// When the coupled friction problem fails (the friction bounds depend on the
/// normal impulses, which is not an LCP and may not converge): solve the
/// normal rows alone exactly, then the whole system with the friction bounds
/// frozen at μ times those normal impulses (a boxed LCP with constant
/// bounds). Projected Gauss–Seidel is the last resort.
fn fallback(
    a: &[f64],
    m: usize,
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    findex: &[Option<usize>],
) -> Vec<f64> {
    let Some(pn) = solve_normal_rows(a, m, b, findex) else {
        return projected_gauss_seidel(a, m, b, lo, hi, findex);
    };
    let (mut flo, mut fhi) = (lo.to_vec(), hi.to_vec());
    for i in 0..m {
        if let Some(j) = findex[i] {
            flo[i] = lo[i] * pn[j];
            fhi[i] = hi[i] * pn[j];
        }
    }
    match lcp::solve(&lcp::LcpProblem::boxed(a, b, &flo, &fhi)) {
        Ok(full) => full.x,
        Err(_) => pn,
    }
}

/// The standard LCP on the normal rows alone (friction rows left at zero),
/// as a full-length impulse vector; `None` when the solver fails.
fn solve_normal_rows(a: &[f64], m: usize, b: &[f64], findex: &[Option<usize>]) -> Option<Vec<f64>> {
    let normal: Vec<usize> = (0..m).filter(|&i| findex[i].is_none()).collect();
    let k = normal.len();
    let mut an = vec![0.0; k * k];
    for (r, &i) in normal.iter().enumerate() {
        for (c, &j) in normal.iter().enumerate() {
            an[r * k + c] = a[i * m + j];
        }
    }
    let bn: Vec<f64> = normal.iter().map(|&i| b[i]).collect();
    let sol = lcp::solve_standard(&an, &bn).ok()?;
    let mut p = vec![0.0; m];
    for (r, &i) in normal.iter().enumerate() {
        p[i] = sol.x[r];
    }
    Some(p)
}

/// Rows from which Dantzig's method takes the system's factors
/// (`lcp::RowFactors`): its drive's Δw then costs O(rows) a pivot instead
/// of O(rows · clamped). Below, the dense product is cheap, and the small
/// exact cases (a light cube under a heavy one) keep its finer rounding.
const FACTORED_MIN_ROWS: usize = 64;

/// Rows from which a system not at rest is solved by the interior-point
/// method (`interior`) first.
const INTERIOR_MIN_ROWS: usize = FACTORED_MIN_ROWS;

/// Rows from which an island is solved by sequential impulses with the
/// subspace step instead of Dantzig's method. Dantzig's cost grows with the
/// cube of the rows, and on redundant systems this large its friction
/// passes often cycle and fail. Below this the exact method stays: it has
/// no compliance and no tolerance, and small systems are cheap for it.
pub const ITERATIVE_MIN_ROWS: usize = 300;
/// Rows up to which an iterative answer that missed the LCP's conditions is
/// solved again by Dantzig's method: a missed answer, kept, adds energy and
/// moves a resting stack, but a settling pile's larger islands miss often,
/// and solving them exactly would take most of the run. The compliant
/// retry stops at the same size.
const DANTZIG_MAX_ROWS: usize = COMPLIANT_RETRY_ROWS;
/// Sweeps of the sequential-impulse solve at most; it stops as soon as its
/// answer meets the LCP's conditions to `ITERATIVE_RESIDUAL`, checked every
/// `ITERATIVE_CHECK_EVERY` sweeps (a check costs about one sweep).
const ITERATIVE_SWEEPS: usize = 1000;
/// Sweeps (with the subspace step, warm-started like the iterative solve)
/// that give Dantzig's method its start on systems of `FACTORED_MIN_ROWS`
/// to `ITERATIVE_MIN_ROWS` rows. The answer stays Dantzig's; the sweeps
/// keep each friction row within its normal row's bound as they go, so
/// their sets need fewer friction passes and compliant retries than the
/// last step's impulses, and a few sweeps get most of that gain.
const START_SWEEPS: usize = 128;
/// Sweeps of the sequential-impulse solve at most where it starts from the
/// answer of an interior-point solve that missed the conditions (from
/// `ITERATIVE_MIN_ROWS` rows; below `DANTZIG_MAX_ROWS` Dantzig's method
/// then starts from theirs). That answer is close where the last step's
/// impulses are not, so a fraction of `ITERATIVE_SWEEPS` from it ends
/// nearer the conditions than all of them from those impulses would.
const SWEEPS_AFTER_INTERIOR: usize = 200;
/// How far (m/s) the last step's impulses may miss the conditions and
/// still be Dantzig's start without the start sweeps. A system at rest
/// needs nearly the same impulses every step, and its sweeps would cost a
/// subspace factorisation each step for nothing; a standing stack's
/// impulses miss by less than this, a settling pile's mostly by far more.
const WARM_CLOSE: f64 = 1e-4;
const ITERATIVE_CHECK_EVERY: usize = 8;
/// Subspace steps per solve at most, and rejected steps in a row after
/// which the solve goes on with sweeps alone. Where the pushing set keeps
/// changing (friction in a settling pile) the steps are rejected and each
/// costs a factorisation, so the solve stops trying them.
const SUBSPACE_STEPS: usize = 32;
const SUBSPACE_REJECTIONS: usize = 3;

/// Projected Gauss–Seidel on w = (A + c·diag) p + b without forming A
/// (Erleben's "sequential impulses", Box2D's and Bullet's solver): each row
/// in turn takes the impulse that zeroes its w, clamped to its bounds (a
/// friction row's to ± its coefficient times its normal row's impulse), and
/// the bodies' velocity changes carry it to the other rows. O(rows) a sweep.
/// After every `ITERATIVE_CHECK_EVERY` sweeps that did not meet the
/// conditions, the subspace step (`subspace`) solves the rows strictly
/// inside their bounds together; the sweeps find which rows push, the step
/// carries the load through them at once.
///
/// It starts from `warm` (clamped to the bounds): the impulses the same
/// contacts took in their last solve. A pile or a stack at rest needs
/// nearly the same impulses every step, so the sweeps start with the right
/// rows pushing. Returns the impulses and whether they meet the LCP's
/// conditions to the tolerance (`ITERATIVE_RESIDUAL`, `ITERATIVE_FLOOR`),
/// and the sweeps it took.
#[allow(clippy::too_many_arguments)]
fn sequential_impulses(
    rows: &[Row],
    diag: &[f64],
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    findex: &[Option<usize>],
    warm: &[f64],
    bodies: usize,
    max_sweeps: usize,
) -> (Vec<f64>, bool, u32) {
    let system = IterativeSystem::new(rows, diag, b, lo, hi, findex);
    let mut state = system.warm_state(warm, bodies);
    let by_body = subspace::rows_by_body(rows, bodies);
    // A warm start already frees the rows that pushed in the last solve:
    // the subspace step comes first, before any sweep. A stack at rest then
    // meets the conditions at once, where eight sweeps first only re-found
    // the free rows it had (the stack of 50: half the sweeps, half the
    // solve time). Without one (an impact), the sweeps find them first.
    let warm_started = state.p.iter().any(|&x| x != 0.0);
    let (mut steps_left, mut rejected_in_a_row) = (SUBSPACE_STEPS, 0);
    for sweep in 0..max_sweeps {
        if sweep % ITERATIVE_CHECK_EVERY == 0 {
            if system.met(&state) {
                return (state.p, true, sweep as u32);
            }
            let may_step = sweep > 0 || warm_started;
            if may_step && steps_left > 0 && rejected_in_a_row < SUBSPACE_REJECTIONS {
                steps_left -= 1;
                match subspace::step(&system, &by_body, &mut state) {
                    Step::Kept if system.met(&state) => return (state.p, true, sweep as u32),
                    Step::Kept => rejected_in_a_row = 0,
                    Step::Rejected => rejected_in_a_row += 1,
                    Step::NotTaken => {}
                }
            }
        }
        system.sweep(&mut state);
    }
    let met = system.met(&state);
    (state.p, met, max_sweeps as u32)
}

/// The interior point on `system` made exact (no compliance), for a
/// system it was not tried on first: its answer where it meets the
/// conditions. It refuses systems that move too many bodies itself
/// (`interior::takes`).
fn interior_rescue(
    system: &IterativeSystem,
    warm: &[f64],
    bodies: usize,
    stats: &mut SolveStats,
) -> Option<Vec<f64>> {
    let exact = IterativeSystem {
        compliance: 0.0,
        ..*system
    };
    let answer = super::interior::solve(&exact, warm, bodies)?;
    stats.interior_steps += answer.steps as u64;
    answer.met.then(|| {
        stats.interior_solves += 1;
        answer.p
    })
}

/// Last-resort fallback: projected Gauss–Seidel on the boxed LCP.
/// Converges for positive semidefinite A; used only after a reported failure.
pub fn projected_gauss_seidel(
    a: &[f64],
    m: usize,
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    findex: &[Option<usize>],
) -> Vec<f64> {
    let mut x = vec![0.0; m];
    for _ in 0..200 {
        for i in 0..m {
            let aii = a[i * m + i];
            if aii <= 1e-300 {
                continue;
            }
            let r: f64 = b[i] + (0..m).map(|j| a[i * m + j] * x[j]).sum::<f64>();
            let mut xi = x[i] - r / aii;
            xi = match findex[i] {
                None => xi.clamp(lo[i], hi[i]),
                Some(k) => xi.clamp(lo[i] * x[k].abs(), hi[i] * x[k].abs()),
            };
            x[i] = if xi.is_finite() { xi } else { 0.0 };
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyId;
    use crate::contact::system::ITERATIVE_COMPLIANCE;
    use nalgebra::Matrix3;

    /// A fixed body (no inverse mass or inertia) at rest at `position`.
    fn fixed_body(position: Vector3<f64>) -> IslandBody {
        IslandBody {
            id: BodyId(0),
            inv_mass: 0.0,
            inv_inertia: Matrix3::zeros(),
            position,
            velocity: Vector3::zeros(),
            angular_velocity: Vector3::zeros(),
            external_dv: Vector3::zeros(),
            external_dw: Vector3::zeros(),
        }
    }

    /// A frictionless stack of `n` 1 kg bodies on a fixed floor in the
    /// resting phase (every body about to fall g·h), solved by sequential
    /// impulses from `warm` (a share of the exact answer). Returns the
    /// impulses, whether they met the conditions, and the exact answer: the
    /// impulse under the k-th body from the top is k·m·g·h.
    fn stack(n: usize, warm: f64) -> (Vec<f64>, bool, Vec<f64>, Vec<f64>) {
        let (g, h) = (9.81, 0.01);
        let mut bodies = vec![fixed_body(Vector3::zeros())];
        for k in 1..=n {
            bodies.push(IslandBody {
                id: BodyId(k as u32),
                inv_mass: 1.0,
                inv_inertia: Matrix3::identity() * 6.0,
                position: Vector3::new(0.0, 0.0, k as f64 - 0.5),
                velocity: Vector3::new(0.0, 0.0, -g * h),
                ..bodies[0].clone()
            });
        }
        // Contact k joins body k + 1 (above, A) to body k (below, B).
        let rows: Vec<Row> = (0..n)
            .map(|k| {
                let point = Vector3::new(0.0, 0.0, k as f64);
                Row::new(&bodies, k + 1, k, &point, Vector3::z())
            })
            .collect();
        let v: Vec<Vector3<f64>> = bodies.iter().map(|b| b.velocity).collect();
        let w = vec![Vector3::zeros(); bodies.len()];
        let b: Vec<f64> = rows.iter().map(|r| r.velocity(&v, &w)).collect();
        let diag: Vec<f64> = rows.iter().map(|r| r.coupling(r)).collect();
        let exact: Vec<f64> = (0..n).map(|k| (n - k) as f64 * g * h).collect();
        let start: Vec<f64> = exact.iter().map(|x| x * warm).collect();
        // The answer of the compliant system the solve meets, with every
        // contact pushing: (A + c·diag) p = −b.
        let compliant = nalgebra::DMatrix::from_fn(n, n, |i, j| {
            rows[i].coupling(&rows[j])
                + if i == j {
                    ITERATIVE_COMPLIANCE * diag[i]
                } else {
                    0.0
                }
        });
        let compliant: Vec<f64> = compliant
            .lu()
            .solve(&-nalgebra::DVector::from_column_slice(&b))
            .expect("a compliant stack is regular")
            .iter()
            .copied()
            .collect();
        let (p, met, _) = sequential_impulses(
            &rows,
            &diag,
            &b,
            &vec![0.0; n],
            &vec![f64::INFINITY; n],
            &vec![None; n],
            &start,
            bodies.len(),
            ITERATIVE_SWEEPS,
        );
        (p, met, exact, compliant)
    }

    /// From zero, five bodies: the answer meets the conditions (it stops
    /// there) and every impulse is right to 1e-5.
    #[test]
    fn sequential_impulses_hold_a_stack_exactly() {
        let (p, met, exact, _) = stack(5, 0.0);
        for (k, (pk, ek)) in p.iter().zip(&exact).enumerate() {
            assert!((pk - ek).abs() <= 1e-5 * ek, "contact {k}: {pk} vs {ek}");
        }
        assert!(met);
    }

    /// A stack of 100, from zero, from the exact answer and from 0.1 % short
    /// of it. Sweeps alone pass a load one contact per sweep (the bottom
    /// impulse was still far from 100·m·g·h after 1000 sweeps from zero);
    /// with the subspace step the rows that push are solved together: every
    /// start meets the conditions within 1e-5 of k·m·g·h, and the start
    /// from zero ends at the compliant system's answer to 1e-9 (the exact
    /// start already meets the conditions and is kept). The compliance
    /// costs the answer up to 1e-5 of k·m·g·h: a
    /// 100-body chain's smallest eigenvalue is about 2.5e-4 of its diagonal,
    /// so c = 1e-9 moves the load by c / 2.5e-4 ≈ 4e-6.
    #[test]
    fn subspace_step_carries_a_tall_stack_from_any_start() {
        for warm in [0.0, 1.0, 0.999] {
            let (p, met, exact, compliant) = stack(100, warm);
            assert!(met, "start {warm}: bottom {} of {}", p[0], exact[0]);
            for k in 0..100 {
                let (pk, ck, ek) = (p[k], compliant[k], exact[k]);
                assert!(
                    (pk - ek).abs() <= 1e-5 * ek,
                    "start {warm}, contact {k}: {pk} vs {ek}"
                );
                if warm == 0.0 {
                    assert!((pk - ck).abs() <= 1e-9 * ck, "contact {k}: {pk} vs {ck}");
                }
            }
        }
    }

    /// A fixed floor and `n` 1 kg unit bodies stacked on it under gravity
    /// over a 0.01 s step, the top one moving along x at `slide` m/s.
    fn stacked_bodies(n: usize, slide: f64) -> Vec<IslandBody> {
        let floor = fixed_body(Vector3::zeros());
        let mut bodies = vec![floor.clone()];
        for k in 1..=n {
            bodies.push(IslandBody {
                id: BodyId(k as u32),
                inv_mass: 1.0,
                inv_inertia: Matrix3::identity() * 6.0,
                position: Vector3::new(0.0, 0.0, k as f64 - 0.5),
                velocity: Vector3::new(if k == n { slide } else { 0.0 }, 0.0, 0.0),
                external_dv: Vector3::new(0.0, 0.0, -9.81 * 0.01),
                ..floor.clone()
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
                contacts.push(IslandContact {
                    a: k as u32 + 1,
                    b: k as u32,
                    point: Vector3::new(x, y, k as f64),
                    normal: Vector3::z(),
                    restitution: 0.0,
                    friction,
                    separation: 0.0,
                    warm_force: 0.0,
                    warm_friction: Vector3::zeros(),
                    turns: NormalTurn::WithB,
                    approach: 0.0,
                    near: false,
                });
            }
        }
        IslandTask {
            bodies: stacked_bodies(n, slide),
            contacts,
            dt: 0.01,
            restitution_threshold: 0.05,
            iterative_min_rows,
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
        assert!(s.iterative_sweeps > 0 && s.iterative_sweeps < ITERATIVE_SWEEPS as u64);
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
        let unmerged = solve_distinct(&twice);
        let by_hand = solve_distinct(&once);
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

    /// A 1 kg body falling at 1 m/s onto the ground through two identical
    /// contacts (a redundant pair, so A is singular). The answer
    /// p = (X, 3 − X) with X = 1e14 pushes the body up at 2 m/s: +1.5 J.
    /// Its quadratic form pᵀJv + ½ pᵀAp sums terms of 1e28 whose rounding
    /// hides that; the guard must still reject it.
    #[test]
    fn energy_guard_rejects_huge_cancelling_impulses() {
        let body = |inv_mass: f64, velocity: Vector3<f64>| IslandBody {
            id: BodyId(0),
            inv_mass,
            inv_inertia: Matrix3::identity() * inv_mass,
            position: Vector3::zeros(),
            velocity,
            angular_velocity: Vector3::zeros(),
            external_dv: Vector3::zeros(),
            external_dw: Vector3::zeros(),
        };
        let bodies = [body(1.0, -Vector3::z()), body(0.0, Vector3::zeros())];
        let point = Vector3::new(0.0, 0.0, -0.5);
        let rows: Vec<Row> = (0..2)
            .map(|_| Row::new(&bodies, 0, 1, &point, Vector3::z()))
            .collect();
        let m = rows.len();
        let mut a = vec![0.0; m * m];
        for i in 0..m {
            for j in 0..m {
                a[i * m + j] = rows[i].coupling(&rows[j]);
            }
        }
        let v = [bodies[0].velocity, bodies[1].velocity];
        let w = [Vector3::zeros(); 2];
        let x = 1e14;
        let mut stats = SolveStats::default();
        let diag: Vec<f64> = (0..m).map(|i| a[i * m + i]).collect();
        let unbiased = [0.0; 2];
        let velocities = (&v[..], &w[..], &unbiased[..], 0.0);
        let p = energy_guard(
            &diag,
            &rows,
            velocities,
            vec![x, 3.0 - x],
            &mut stats,
            |vel| {
                solve_normal_rows(&a, m, vel, &[None, None])
                    .map(|p| vec![("the frictionless inelastic answer", p)])
                    .unwrap_or_default()
            },
        );
        assert_eq!(stats.failed, 1, "the guard let {p:?} through");
        // The safe answer stops the body (inelastic): net impulse 1 N s.
        assert!((p[0] + p[1] - 1.0).abs() < 1e-9, "{p:?}");
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
