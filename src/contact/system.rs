//! The contact system of an island as the solves see it: its LCP rows
//! (`Row`: J and M⁻¹Jᵀ of one contact direction) built from the island's
//! bodies (`IslandBody`), and the boxed LCP w = (A + c·diag) p + b that the
//! iterative solves work on, held as its rows (`IterativeSystem`), with
//! the impulses of a solve (`IterativeState`). The island's solve
//! (`solver`), the subspace step (`subspace`) and the interior point
//! (`interior`) all work on it; it depends on none of them.

use super::lcp;
use crate::body::BodyId;
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

/// One LCP row: direction d at contact `contact`, with M⁻¹Jᵀ precomputed.
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
    pub(super) fn velocity(&self, v: &[Vector3<f64>], w: &[Vector3<f64>]) -> f64 {
        self.lin.dot(&v[self.a]) + self.ang_a.dot(&w[self.a]) - self.lin.dot(&v[self.b])
            + self.ang_b.dot(&w[self.b])
    }

    /// Adds the velocity change of an impulse `p` on this row to both bodies.
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

/// The storage behind `lcp::RowFactors` for a list of rows.
pub(super) struct RowFactorsOf {
    body: Vec<[u32; 2]>,
    jacobian: Vec<[[f64; 6]; 2]>,
    response: Vec<[[f64; 6]; 2]>,
}

impl RowFactorsOf {
    pub(super) fn new(rows: &[Row]) -> Self {
        RowFactorsOf {
            body: rows.iter().map(|r| [r.a as u32, r.b as u32]).collect(),
            jacobian: rows.iter().map(Row::jacobian).collect(),
            response: rows.iter().map(Row::response).collect(),
        }
    }

    pub(super) fn view(&self, bodies: usize) -> lcp::RowFactors<'_> {
        lcp::RowFactors {
            bodies,
            body: &self.body,
            jacobian: &self.jacobian,
            response: &self.response,
        }
    }
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
#[derive(Clone)]
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
            if self.diag[i] > 1e-300 && start.is_finite() && start != 0.0 {
                state.p[i] = start;
                row.change_velocities(start, &mut state.dv, &mut state.dw);
            }
        }
        state
    }

    /// Row i's bounds; a friction row's are its coefficients times its
    /// normal row's impulse.
    pub(super) fn bounds(&self, i: usize, p: &[f64]) -> (f64, f64) {
        match self.findex[i] {
            None => (self.lo[i], self.hi[i]),
            Some(k) => (self.lo[i] * p[k].abs(), self.hi[i] * p[k].abs()),
        }
    }

    /// w_i = (A p + b)_i + c·A_ii·p_i.
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
        if self.diag[i] <= 1e-300 {
            return 0.0;
        }
        let wi = self.velocity(i, s);
        let (l, h) = self.bounds(i, &s.p);
        match (s.p[i] <= l, s.p[i] >= h) {
            (true, true) => 0.0,
            (true, false) if wi >= 0.0 => 0.0,
            (true, false) => -wi,
            (false, true) if wi <= 0.0 => 0.0,
            (false, true) => wi,
            (false, false) => wi.abs(),
        }
    }

    /// How far p is from meeting them, in velocity: the squared length of
    /// diag·(p − clamp(p − w/diag)), zero exactly at an answer.
    pub(super) fn natural_residual(&self, s: &IterativeState) -> f64 {
        (0..self.rows.len())
            .filter(|&i| self.diag[i] > 1e-300)
            .map(|i| {
                let wi = self.velocity(i, s);
                let (l, h) = self.bounds(i, &s.p);
                let r = self.diag[i] * (s.p[i] - (s.p[i] - wi / self.diag[i]).clamp(l, h));
                r * r
            })
            .sum::<f64>()
    }

    /// One projected Gauss–Seidel sweep over the rows in order.
    pub(super) fn sweep(&self, s: &mut IterativeState) {
        for (i, row) in self.rows.iter().enumerate() {
            if self.diag[i] <= 1e-300 {
                continue;
            }
            let wi = self.velocity(i, s);
            let (l, h) = self.bounds(i, &s.p);
            let new = (s.p[i] - wi / (self.diag[i] * (1.0 + self.compliance))).clamp(l, h);
            let delta = if new.is_finite() {
                new - s.p[i]
            } else {
                -s.p[i]
            };
            s.p[i] += delta;
            row.change_velocities(delta, &mut s.dv, &mut s.dw);
        }
    }
}
