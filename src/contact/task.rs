//! The contact request of one island and its reply (SPEC 3.4): plain data
//! that any rank can solve and that travels between ranks, with the
//! counters of its solve (`SolveStats`).

use crate::body::BodyId;
use crate::collision::manifold::NormalTurn;
use crate::collision::narrowphase::CONTACT_TOLERANCE;
use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct IslandBody {
    pub id: BodyId,
    pub inv_mass: f64,
    /// World inverse inertia (zero for fixed and driven bodies).
    pub inv_inertia: Matrix3<f64>,
    pub position: Vector3<f64>,
    pub velocity: Vector3<f64>,
    pub angular_velocity: Vector3<f64>,
    /// Velocity change the external forces give over the step (a·h, α·h).
    pub external_dv: Vector3<f64>,
    pub external_dw: Vector3<f64>,
}

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

/// The gap a speculative contact (one apart by more than the contact
/// tolerance) may close to within the step: the middle of the touching band,
/// so that what the linear prediction misses either way still ends touching.
pub const SPECULATIVE_GAP: f64 = 0.5 * CONTACT_TOLERANCE;

/// The speed (m/s) at which a speculative contact (`IslandContact::near`)
/// may close over an interval `dt` and still end apart by
/// `SPECULATIVE_GAP`; zero for a touching contact.
pub(super) fn closing_allowed(c: &IslandContact, dt: f64) -> f64 {
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
    /// Blocks the large-island method cuts the island into, so that ranks
    /// can share it (`block_sweeps`); 1: swept whole.
    pub island_blocks: u32,
}

impl IslandTask {
    /// The rows its solve builds: one per contact, two more per contact
    /// with friction.
    pub fn rows(&self) -> usize {
        self.contacts
            .iter()
            .map(|c| if c.friction > 0.0 { 3 } else { 1 })
            .sum()
    }

    /// What the scheduler estimates its solve by (`cluster::schedule`'s
    /// cost model): Dantzig's cost, cubic in its rows, plus the linear
    /// building work.
    pub fn cost_units(&self) -> f64 {
        let r = self.rows() as f64;
        r * r * r + 20.0 * r
    }
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
    /// the contacts made slightly compliant (`dantzig::COMPLIANCE`).
    pub compliant_solves: u32,
    /// Islands of `ITERATIVE_MIN_ROWS` rows or more, solved by sequential
    /// impulses (not counted in `lcp_solves`).
    pub iterative_solves: u32,
    /// Of those, the ones whose answer still missed the LCP's conditions
    /// (`IterativeSystem::tolerance`) after their sweeps: solved again by
    /// Dantzig's method below `SolverSettings::dantzig_max_rows`, kept
    /// from there and by the large-island method.
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
    pub(super) fn record_failure(&mut self, rows: usize, why: String) {
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

/// A touching contact of bodies `a` on `b` at `point`, normal `normal`
/// (out of B), no restitution, friction coefficient `friction`, no warm
/// start.
#[cfg(test)]
pub(super) fn resting_contact(
    a: usize,
    b: usize,
    point: Vector3<f64>,
    normal: Vector3<f64>,
    friction: f64,
) -> IslandContact {
    IslandContact {
        a: a as u32,
        b: b as u32,
        point,
        normal,
        restitution: 0.0,
        friction,
        separation: 0.0,
        warm_force: 0.0,
        warm_friction: Vector3::zeros(),
        turns: crate::collision::manifold::NormalTurn::WithB,
        approach: 0.0,
        near: false,
    }
}

/// A fixed body (no inverse mass or inertia) at rest at `position`.
#[cfg(test)]
pub(super) fn fixed_body(position: Vector3<f64>) -> IslandBody {
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

/// Body `k` (from 1) of a stack of 1 kg unit cubes on a fixed floor at the
/// origin (`fixed_body`): centred at z = k − ½, moving at `velocity`.
#[cfg(test)]
pub(super) fn stacked_cube(k: usize, velocity: Vector3<f64>) -> IslandBody {
    IslandBody {
        id: BodyId(k as u32),
        inv_mass: 1.0,
        inv_inertia: Matrix3::identity() * 6.0,
        position: Vector3::new(0.0, 0.0, k as f64 - 0.5),
        velocity,
        ..fixed_body(Vector3::zeros())
    }
}
