//! The contact system of an island as the solves see it: its LCP rows
//! (`Row`: J and M⁻¹Jᵀ of one contact direction) built from the island's
//! bodies (`IslandBody`), the rows of one phase of its solve with their
//! targets and bounds (`PhaseSystem`), and the boxed LCP
//! w = (A + c·diag) p + b that the iterative solves work on, held as its
//! rows (`IterativeSystem`), with the impulses of a solve
//! (`IterativeState`). The island's solve (`solver`) and every method
//! (`methods`) work on it; it depends on none of them.

use super::restitution::{bounce_basis, patches_that_bounce};
use super::task::{
    IslandBody, IslandContact, IslandTask, LARGE_SYSTEM_ROWS, SolveStats, closing_allowed,
};
use crate::collision::narrowphase::CONTACT_TOLERANCE;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// A row whose diagonal A_ii is at most this moves nothing: no body behind
/// it can be pushed (both static, or a friction row of no lever), so every
/// method leaves it out rather than divide by it.
pub(crate) const NO_RESPONSE: f64 = 1e-300;

/// Separating speeds below this (m/s) count as resting in the resting
/// solve: a stack at rest has contact speeds of rounding size, and letting
/// them in perturbs its redundant systems enough to send some through the
/// compliant retry. A lifting nut rocks at about 1e-3 m/s, far above it.
pub(super) const SEPARATING_EPS: f64 = 1e-6;

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

/// One LCP row: direction d at contact `contact`, with M⁻¹Jᵀ precomputed.
#[derive(Clone, Serialize, Deserialize)]
pub(super) struct Row {
    pub(super) a: usize,
    pub(super) b: usize,
    pub(super) lin: Vector3<f64>,
    pub(super) ang_a: Vector3<f64>,
    pub(super) ang_b: Vector3<f64>,
    /// M⁻¹Jᵀ: velocity change of A and B per unit impulse on this row.
    dva: Vector3<f64>,
    dwa: Vector3<f64>,
    dvb: Vector3<f64>,
    dwb: Vector3<f64>,
}

impl Row {
    pub(super) fn new(
        bodies: &[IslandBody],
        a: usize,
        b: usize,
        point: &Vector3<f64>,
        d: Vector3<f64>,
    ) -> Row {
        let (ba, bb) = (&bodies[a], &bodies[b]);
        let ang_a = (point - ba.position).cross(&d);
        let ang_b = -(point - bb.position).cross(&d);
        Row {
            a,
            b,
            lin: d,
            ang_a,
            ang_b,
            dva: d * ba.inv_mass,
            dwa: ba.inv_inertia * ang_a,
            dvb: -d * bb.inv_mass,
            dwb: bb.inv_inertia * ang_b,
        }
    }

    /// The same row between bodies numbered `a` and `b` elsewhere (a
    /// block's own numbering, `block_sweeps`).
    pub(super) fn renumbered(&self, a: usize, b: usize) -> Row {
        Row {
            a,
            b,
            ..self.clone()
        }
    }

    /// J on A and on B, linear then angular (for `lcp::RowFactors`).
    pub(super) fn jacobian(&self) -> [[f64; 6]; 2] {
        let side =
            |lin: Vector3<f64>, ang: Vector3<f64>| [lin.x, lin.y, lin.z, ang.x, ang.y, ang.z];
        [side(self.lin, self.ang_a), side(-self.lin, self.ang_b)]
    }

    /// M⁻¹Jᵀ on A and on B, linear then angular (for `lcp::RowFactors`).
    pub(super) fn response(&self) -> [[f64; 6]; 2] {
        let side = |dv: Vector3<f64>, dw: Vector3<f64>| [dv.x, dv.y, dv.z, dw.x, dw.y, dw.z];
        [side(self.dva, self.dwa), side(self.dvb, self.dwb)]
    }

    /// Relative velocity along the row: J·v.
    #[inline(always)]
    pub(super) fn velocity(&self, v: &[Vector3<f64>], w: &[Vector3<f64>]) -> f64 {
        self.lin.dot(&v[self.a]) + self.ang_a.dot(&w[self.a]) - self.lin.dot(&v[self.b])
            + self.ang_b.dot(&w[self.b])
    }

    /// Adds the velocity change of an impulse `p` on this row to both bodies.
    #[inline(always)]
    pub(super) fn change_velocities(&self, p: f64, v: &mut [Vector3<f64>], w: &mut [Vector3<f64>]) {
        v[self.a] += self.dva * p;
        w[self.a] += self.dwa * p;
        v[self.b] += self.dvb * p;
        w[self.b] += self.dwb * p;
    }

    /// Whether an impulse on this row moves A, and B (a fixed body takes
    /// none).
    pub(super) fn moves(&self) -> (bool, bool) {
        let moves = |dv: &Vector3<f64>, dw: &Vector3<f64>| {
            *dv != Vector3::zeros() || *dw != Vector3::zeros()
        };
        (moves(&self.dva, &self.dwa), moves(&self.dvb, &self.dwb))
    }

    /// This row's side on body `body` (A or B): J's linear and angular
    /// parts there and the velocity change M⁻¹Jᵀ a unit impulse gives it,
    /// the terms of `coupling` through that body.
    pub(super) fn side(&self, body: usize) -> RowSide {
        if body == self.a {
            RowSide {
                lin: self.lin,
                ang: self.ang_a,
                dv: self.dva,
                dw: self.dwa,
            }
        } else {
            RowSide {
                lin: -self.lin,
                ang: self.ang_b,
                dv: self.dvb,
                dw: self.dwb,
            }
        }
    }

    /// J_self · (M⁻¹ J_other ᵀ). The terms are `RowSide::coupling`'s,
    /// written out: built from `side` they cost the 1000-body pile 2.5 %
    /// more instructions (its dense systems ask this for every pair).
    pub(super) fn coupling(&self, other: &Row) -> f64 {
        let mut s = 0.0;
        for (body, lin, ang) in [
            (self.a, self.lin, self.ang_a),
            (self.b, -self.lin, self.ang_b),
        ] {
            if body == other.a {
                s += lin.dot(&other.dva) + ang.dot(&other.dwa);
            }
            if body == other.b {
                s += lin.dot(&other.dvb) + ang.dot(&other.dwb);
            }
        }
        s
    }

    /// Adds an impulse `p` on this row to both bodies' linear and angular
    /// impulses (`lin`, `ang`; or, with p a force, their forces and
    /// torques).
    pub(super) fn apply(&self, p: f64, lin: &mut [Vector3<f64>], ang: &mut [Vector3<f64>]) {
        lin[self.a] += self.lin * p;
        ang[self.a] += self.ang_a * p;
        lin[self.b] -= self.lin * p;
        ang[self.b] += self.ang_b * p;
    }
}

/// A row on one of its bodies (`Row::side`).
#[derive(Clone, Copy)]
pub(super) struct RowSide {
    pub(super) lin: Vector3<f64>,
    pub(super) ang: Vector3<f64>,
    pub(super) dv: Vector3<f64>,
    pub(super) dw: Vector3<f64>,
}

impl RowSide {
    /// The coupling of this side's row with `other`'s row through the
    /// body they share: `Row::coupling`'s term for that body, to the bit.
    pub(super) fn coupling(&self, other: &RowSide) -> f64 {
        self.lin.dot(&other.dv) + self.ang.dot(&other.dw)
    }
}

/// Which velocities a solve targets.
#[derive(Clone, Copy)]
pub(super) enum Phase<'a> {
    Impact,
    /// `start`: the velocities at the start of the step (after any impact),
    /// before the external forces act.
    /// `curvature`: each contact's `gap_curvature`.
    Resting {
        start: (&'a [Vector3<f64>], &'a [Vector3<f64>]),
        curvature: &'a [f64],
    },
}

/// The boxed LCP of one phase of an island's solve, w = A p + b: per
/// contact its normal row and, where μ > 0, two friction rows after it
/// (`normal_rows`), with what the methods and the energy guard need
/// beside.
pub(super) struct PhaseSystem {
    pub(super) rows: Vec<Row>,
    /// A_ii, for the iterative solves and the energy guard.
    pub(super) diag: Vec<f64>,
    /// b: each row's velocity, with a normal row's target folded in.
    pub(super) rhs: Vec<f64>,
    /// Bounds; a friction row's are coefficients of its normal row's
    /// impulse (`findex`): |p_t| ≤ μ p_N.
    pub(super) lo: Vec<f64>,
    pub(super) hi: Vec<f64>,
    pub(super) findex: Vec<Option<usize>>,
    /// Warm start of the iterative solve: last solve's impulses over this
    /// phase's interval (resting phase only; an impact has no history).
    pub(super) warm: Vec<f64>,
    /// Each row's velocity-product term over the interval (`gap_curvature`):
    /// the energy guard counts it as velocity the row already has.
    pub(super) bias: Vec<f64>,
    /// Each row's coefficient of restitution where the impact applies one.
    pub(super) restitution: Vec<f64>,
    /// The energy a deferred approach lost at its speculative contact,
    /// which its bounce may give back (`energy_guard`): the most of any
    /// one row's, as a patch's points carry the same approach of one
    /// body and their sum would count it once a point.
    pub(super) deferred: f64,
}

impl PhaseSystem {
    /// The rows of `phase` on the velocities `v`, `w`, their targets and
    /// bounds.
    pub(super) fn build(
        task: &IslandTask,
        v: &[Vector3<f64>],
        w: &[Vector3<f64>],
        phase: Phase,
    ) -> PhaseSystem {
        // At most three rows a contact (its normal and two friction rows),
        // reserved at once: grown a row at a time they were 2 % of the
        // pyramid's instructions.
        let most = 3 * task.contacts.len();
        let mut s = PhaseSystem {
            rows: Vec::with_capacity(most),
            diag: Vec::new(),
            rhs: Vec::with_capacity(most),
            lo: Vec::with_capacity(most),
            hi: Vec::with_capacity(most),
            findex: Vec::with_capacity(most),
            warm: Vec::with_capacity(most),
            bias: Vec::with_capacity(most),
            restitution: Vec::with_capacity(most),
            deferred: 0.0,
        };
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
        for ((ci, c), normal) in task.contacts.iter().enumerate().zip(normals) {
            let vn = speeds[ci];
            let speculative = closing_allowed(c, task.dt);
            let basis = bounce_basis(c, vn, task);
            let b_n = normal_target(task, ci, &normal, vn, basis, bounces[ci], phase);
            s.bias.push(match phase {
                Phase::Resting { curvature, .. } => curvature[ci] * task.dt,
                Phase::Impact => 0.0,
            });
            if matches!(phase, Phase::Impact) && basis < vn.min(0.0) {
                let a_nn = normal.coupling(&normal);
                if a_nn > 0.0 {
                    s.deferred = f64::max(
                        s.deferred,
                        0.5 * (basis * basis - vn.min(0.0).powi(2)) / a_nn,
                    );
                }
            }
            s.restitution.push(match phase {
                Phase::Impact if speculative > 0.0 => 0.0,
                Phase::Impact if bounces[ci] => c.restitution,
                _ => 0.0,
            });
            let ni = s.rows.len();
            s.rows.push(normal);
            s.rhs.push(b_n);
            s.lo.push(0.0);
            s.hi.push(f64::INFINITY);
            s.findex.push(None);
            s.warm
                .push(if resting { c.warm_force * task.dt } else { 0.0 });
            if c.friction > 0.0 {
                s.push_friction_rows(task, c, ni, (v, w), resting);
            }
        }
        s.diag = s.rows.iter().map(|r| r.coupling(r)).collect();
        s
    }

    /// Contact `c`'s two friction rows, after its normal row `ni`: the slip
    /// direction first (`friction_direction`), then the one across it.
    fn push_friction_rows(
        &mut self,
        task: &IslandTask,
        c: &IslandContact,
        ni: usize,
        (v, w): (&[Vector3<f64>], &[Vector3<f64>]),
        resting: bool,
    ) {
        let t1 = friction_direction(task, c, v, w);
        let t2 = c.normal.cross(&t1);
        for t in [t1, t2] {
            let row = Row::new(&task.bodies, c.a as usize, c.b as usize, &c.point, t);
            self.warm.push(if resting {
                c.warm_friction.dot(&t) * task.dt
            } else {
                0.0
            });
            self.rhs.push(row.velocity(v, w));
            self.bias.push(0.0);
            self.restitution.push(0.0);
            self.rows.push(row);
            // Friction bounds are coefficients of the normal impulse: |p_t| ≤ μ p_N.
            self.lo.push(-c.friction);
            self.hi.push(c.friction);
            self.findex.push(Some(ni));
        }
    }

    /// Counts the system in `stats`: its rows, friction rows, and size.
    pub(super) fn count(&self, stats: &mut SolveStats) {
        let m = self.rows.len();
        stats.friction_rows += self.findex.iter().filter(|f| f.is_some()).count() as u32;
        stats.rows += m as u32;
        stats.largest_rows = stats.largest_rows.max(m as u32);
        if m >= LARGE_SYSTEM_ROWS {
            stats.large_systems += 1;
        }
    }

    /// The system as the iterative solves see it (`IterativeSystem`).
    pub(super) fn iterative(&self) -> IterativeSystem<'_> {
        IterativeSystem::new(
            &self.rows,
            &self.diag,
            &self.rhs,
            &self.lo,
            &self.hi,
            &self.findex,
        )
    }

    /// The sum of the normal rows' impulses in `p`.
    pub(super) fn normal_sum(&self, p: &[f64]) -> f64 {
        p.iter()
            .zip(&self.findex)
            .filter(|(_, f)| f.is_none())
            .map(|(x, _)| x)
            .sum()
    }
}

/// Contact `ci`'s normal row's b in `phase`: its normal speed `vn` with
/// what the row asks of it folded in (w = A p + b ≥ 0): restitution from
/// the approach `basis` where the contact `bounces`, the gap a speculative
/// contact may close, the separation a resting contact may keep, and the
/// overlap it mends.
fn normal_target(
    task: &IslandTask,
    ci: usize,
    normal: &Row,
    vn: f64,
    basis: f64,
    bounces: bool,
    phase: Phase,
) -> f64 {
    let c = &task.contacts[ci];
    let speculative = closing_allowed(c, task.dt);
    match phase {
        // A speculative contact: the gap may close to `SPECULATIVE_GAP`
        // at the speed it starts with (no restitution: its approach is
        // slower than the speculative speed, `step::contact`).
        Phase::Impact if speculative > 0.0 => vn + speculative,
        // Newton's law from the approach, its own or the deferred one.
        Phase::Impact if basis < vn && bounces => vn + c.restitution * basis,
        Phase::Impact if bounces => (1.0 + c.restitution) * vn,
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
    }
}

/// Index of each contact's normal row in the row list `PhaseSystem::build`
/// builds.
pub(super) fn normal_rows(task: &IslandTask) -> Vec<usize> {
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

/// How far an iterative answer may miss the LCP's conditions: each row's
/// velocity w = (A + c·diag) p + b within the larger of this share of the
/// largest |b| of the system and `ITERATIVE_FLOOR`, on the side its bound
/// does not allow (w ≥ 0 at a lower bound, w ≤ 0 at an upper one, w = 0
/// between). Once the pushing set is right the subspace step is exact, so
/// the tolerance can be tight, and must be: a looser one lets a resting
/// pyramid gain energy, its cubes drifting up a little every step.
const ITERATIVE_RESIDUAL: f64 = 1e-9;
/// The least tolerance (m/s): 0.1 nm of approach over a 10 ms step. It
/// decides for every system slower than 10 m/s. An impact solve of
/// rounding-size approaches would otherwise ask for far less; there most
/// contacts neither push nor move apart, the pushing set flips between
/// checks, and the solve would spend all its sweeps on rounding.
const ITERATIVE_FLOOR: f64 = 1e-8;
/// Compliance of the iteratively solved system, relative to each row's
/// diagonal (constraint-force mixing, as in ODE and Bullet): the solve
/// meets w = (A + c·diag) p + b. Redundant contacts (four corners of each
/// face of a stack) make A singular, and their targets differ a little (each
/// corner mends its own overlap), so the exact system has no answer with
/// all of them pushing. With c = 1e-9 every block is positive definite and
/// the answer unique; the price is that a contact holding p closes at
/// c·diag·p: 1e-9 · 0.3 /kg · 20 N·s = 6e-9 m/s under a stack of 100.
pub(super) const ITERATIVE_COMPLIANCE: f64 = 1e-9;

/// The boxed LCP the iterative solve works on, w = (A + c·diag) p + b with
/// c = `compliance`, held as its rows (A is never formed).
pub(super) struct IterativeSystem<'a> {
    pub(super) rows: &'a [Row],
    pub(super) diag: &'a [f64],
    pub(super) b: &'a [f64],
    pub(super) lo: &'a [f64],
    pub(super) hi: &'a [f64],
    pub(super) findex: &'a [Option<usize>],
    pub(super) compliance: f64,
    /// How far w may miss the conditions (m/s).
    pub(super) tolerance: f64,
}

/// The impulses of an iterative solve and the velocity changes they give
/// the bodies (M⁻¹Jᵀp), kept in step.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub(super) struct IterativeState {
    pub(super) p: Vec<f64>,
    pub(super) dv: Vec<Vector3<f64>>,
    pub(super) dw: Vec<Vector3<f64>>,
}

/// What became of a subspace step.
pub(super) enum Step {
    Kept,
    Rejected,
    /// No row was free, or the factorisation failed.
    NotTaken,
}

impl<'a> IterativeSystem<'a> {
    pub(super) fn new(
        rows: &'a [Row],
        diag: &'a [f64],
        b: &'a [f64],
        lo: &'a [f64],
        hi: &'a [f64],
        findex: &'a [Option<usize>],
    ) -> Self {
        let scale = b.iter().fold(0.0f64, |s, x| s.max(x.abs()));
        IterativeSystem {
            rows,
            diag,
            b,
            lo,
            hi,
            findex,
            compliance: ITERATIVE_COMPLIANCE,
            tolerance: (ITERATIVE_RESIDUAL * scale).max(ITERATIVE_FLOOR),
        }
    }

    /// The warm start, clamped to the bounds. A friction row comes after
    /// its normal row, so its bounds use the normal impulse already started.
    pub(super) fn warm_state(&self, warm: &[f64], bodies: usize) -> IterativeState {
        let mut state = IterativeState {
            p: vec![0.0f64; self.rows.len()],
            dv: vec![Vector3::zeros(); bodies],
            dw: vec![Vector3::zeros(); bodies],
        };
        for (i, row) in self.rows.iter().enumerate() {
            let (l, h) = self.bounds(i, &state.p);
            let start = warm[i].clamp(l, h);
            if self.diag[i] > NO_RESPONSE && start.is_finite() && start != 0.0 {
                state.p[i] = start;
                row.change_velocities(start, &mut state.dv, &mut state.dw);
            }
        }
        state
    }

    /// Row i's bounds; a friction row's are its coefficients times its
    /// normal row's impulse.
    #[inline(always)]
    pub(super) fn bounds(&self, i: usize, p: &[f64]) -> (f64, f64) {
        match self.findex[i] {
            None => (self.lo[i], self.hi[i]),
            Some(k) => (self.lo[i] * p[k].abs(), self.hi[i] * p[k].abs()),
        }
    }

    /// Whether row i is strictly inside its bounds (it pushes, or holds
    /// friction short of its bound): the rows the subspace step solves
    /// together.
    pub(super) fn is_free(&self, i: usize, s: &IterativeState) -> bool {
        let (l, h) = self.bounds(i, &s.p);
        self.diag[i] > NO_RESPONSE && s.p[i] > l && s.p[i] < h
    }

    /// w_i = (A p + b)_i + c·A_ii·p_i.
    #[inline(always)]
    pub(super) fn velocity(&self, i: usize, s: &IterativeState) -> f64 {
        self.b[i] + self.rows[i].velocity(&s.dv, &s.dw) + self.compliance * self.diag[i] * s.p[i]
    }

    /// Whether the rows that can take an impulse meet the LCP's conditions
    /// to `tolerance`: w ≥ 0 at a lower bound, w ≤ 0 at an upper one, w = 0
    /// between.
    pub(super) fn met(&self, s: &IterativeState) -> bool {
        (0..self.rows.len()).all(|i| self.miss(i, s) <= self.tolerance)
    }

    /// The largest amount by which a row misses its condition (m/s).
    pub(super) fn worst_miss(&self, s: &IterativeState) -> f64 {
        (0..self.rows.len())
            .map(|i| self.miss(i, s))
            .fold(0.0, f64::max)
    }

    /// How far (m/s) row i misses its condition: w_i below 0 at its lower
    /// bound, above 0 at its upper one, off 0 between; zero for a row no
    /// impulse moves. NaN where w_i is (so that `met` fails on it).
    pub(super) fn miss(&self, i: usize, s: &IterativeState) -> f64 {
        if self.diag[i] <= NO_RESPONSE {
            return 0.0;
        }
        let (l, h) = self.bounds(i, &s.p);
        let (at_lower, at_upper) = (s.p[i] <= l, s.p[i] >= h);
        if at_lower && at_upper {
            // Pinned (both bounds 0): any velocity meets the conditions.
            return 0.0;
        }
        let wi = self.velocity(i, s);
        match (at_lower, at_upper) {
            (true, _) if wi >= 0.0 => 0.0,
            (true, _) => -wi,
            (_, true) if wi <= 0.0 => 0.0,
            (_, true) => wi,
            _ => wi.abs(),
        }
    }

    /// How far p is from meeting them, in velocity: the squared length of
    /// diag·(p − clamp(p − w/diag)), zero exactly at an answer.
    pub(super) fn natural_residual(&self, s: &IterativeState) -> f64 {
        (0..self.rows.len())
            .filter(|&i| self.diag[i] > NO_RESPONSE)
            .map(|i| {
                let wi = self.velocity(i, s);
                let (l, h) = self.bounds(i, &s.p);
                let r = self.diag[i] * (s.p[i] - (s.p[i] - wi / self.diag[i]).clamp(l, h));
                r * r
            })
            .sum::<f64>()
    }

    /// One projected Gauss–Seidel sweep over the rows in order. A row
    /// pinned at zero (a friction row whose normal row pushes nothing: its
    /// bounds are both 0) stays there whatever its velocity, and a row
    /// whose impulse does not change moves no body, so neither is worked
    /// out: the impulses and velocity changes are the plain sweep's (a
    /// zero's sign aside).
    pub(super) fn sweep(&self, s: &mut IterativeState) {
        for i in 0..self.rows.len() {
            self.sweep_row(i, s);
        }
    }

    /// The same sweep over these rows only, in the order given.
    pub(super) fn sweep_rows(&self, rows: &[usize], s: &mut IterativeState) {
        for &i in rows {
            self.sweep_row(i, s);
        }
    }

    /// Row i's step of a sweep (`sweep`).
    #[inline(always)]
    fn sweep_row(&self, i: usize, s: &mut IterativeState) {
        if self.diag[i] <= NO_RESPONSE {
            return;
        }
        let (l, h) = self.bounds(i, &s.p);
        if l == 0.0 && h == 0.0 && s.p[i] == 0.0 {
            return;
        }
        let wi = self.velocity(i, s);
        let new = (s.p[i] - wi / (self.diag[i] * (1.0 + self.compliance))).clamp(l, h);
        let delta = if new.is_finite() {
            new - s.p[i]
        } else {
            -s.p[i]
        };
        if delta != 0.0 {
            s.p[i] += delta;
            self.rows[i].change_velocities(delta, &mut s.dv, &mut s.dw);
        }
    }
}
