//! The passes of Dantzig's method: one from nothing, one resumed from the
//! last pass's sets, one started from a guess; and the settling of the
//! sets a resumed or started pass begins with.

use super::problem::LcpProblem;
use super::solution::LcpError;
use super::workspace::{Ctx, LcpWorkspace, RowState};
use super::{RESUME_ROUNDS, ZERO_FRACTION};

impl LcpWorkspace {
    /// One Dantzig pass over all rows. `lazy_friction`: set each friction row's
    /// bounds from the current normal impulse when it is taken (ODE); otherwise
    /// they are frozen from the previous pass.
    pub(super) fn run_pass(
        &mut self,
        p: &LcpProblem,
        ctx: Ctx,
        lazy_friction: bool,
    ) -> Result<(), LcpError> {
        let n = self.n;
        self.x[..n].fill(0.0);
        self.w[..n].fill(0.0);
        self.state[..n].fill(RowState::Unprocessed);
        self.clamped.clear();
        self.factor.clear();
        for k in 0..n {
            let d = self.order[k];
            if let (true, Some(Some(j))) = (lazy_friction, p.findex.get(d)) {
                let normal = self.x[*j].abs();
                self.lo[d] = p.lo[d] * normal;
                self.hi[d] = p.hi[d] * normal;
            }
            self.drive(ctx, d)?;
        }
        Ok(())
    }

    /// A pass after the first, with the friction bounds frozen: it starts
    /// from the last pass's sets instead of from nothing. Most rows keep
    /// their set when the bounds move a little (on 617 islands of a settling
    /// pile the later passes took 91 % of all pivots, restarting each time),
    /// so x_C is solved again for the new bounds; the rows that then miss
    /// their condition (a clamped row past a bound, a row at a bound whose w
    /// turned) go back to unprocessed at x = 0, x_C is solved again
    /// (`RESUME_ROUNDS` times at most), and the drive takes the unprocessed
    /// rows as in a fresh pass. Every processed row meets its condition
    /// before the drive starts, as the method needs, so the answer is one
    /// of Dantzig's; where the rounds do not get there, a fresh pass.
    pub(super) fn resume_pass(&mut self, p: &LcpProblem, ctx: Ctx) -> Result<(), LcpError> {
        let n = self.n;
        // Rows whose bounds closed (a normal impulse gone to zero) are fixed.
        for i in 0..n {
            if self.lo[i] == self.hi[i] {
                self.state[i] = RowState::Fixed;
                self.x[i] = self.lo[i];
            } else {
                match self.state[i] {
                    RowState::AtLo => self.x[i] = self.lo[i],
                    RowState::AtHi => self.x[i] = self.hi[i],
                    RowState::Free => self.x[i] = self.x[i].clamp(self.lo[i], self.hi[i]),
                    RowState::Fixed | RowState::Unprocessed => {
                        self.state[i] = RowState::Unprocessed;
                        self.x[i] = 0.0;
                    }
                    RowState::Clamped => {}
                }
            }
        }
        let state = &self.state;
        self.clamped.retain(|&k| state[k] == RowState::Clamped);
        if !self.settle(p, ctx) {
            return self.run_pass(p, ctx, false);
        }
        self.drive_unprocessed(ctx)
    }

    /// The first pass from a guess x⁰ of the answer: the friction bounds
    /// frozen at μ|x⁰_N|, each row at the bound the guess puts it on, and
    /// the rows inside their bounds clamped in row order where independent
    /// of the rows clamped before (a dependent one waits, unprocessed);
    /// then as `resume_pass`. A settling pile's islands keep most of their
    /// contacts and loads from one step to the next, so the last step's
    /// impulses give most rows their set at once. Where the guess's sets
    /// do not settle, a fresh pass from nothing.
    pub(super) fn start_pass(
        &mut self,
        p: &LcpProblem,
        ctx: Ctx,
        start: &[f64],
    ) -> Result<(), LcpError> {
        let n = self.n;
        if start.len() != n || start.iter().any(|v| !v.is_finite()) {
            return self.run_pass(p, ctx, true);
        }
        self.clamped.clear();
        self.factor.clear();
        for i in 0..n {
            if let Some(Some(j)) = p.findex.get(i) {
                let normal = start[*j].max(0.0);
                self.lo[i] = p.lo[i] * normal;
                self.hi[i] = p.hi[i] * normal;
            }
            let (lo, hi, x) = (self.lo[i], self.hi[i], start[i]);
            (self.state[i], self.x[i]) = if lo == hi {
                (RowState::Fixed, lo)
            } else if x <= lo {
                (RowState::AtLo, lo)
            } else if x >= hi {
                (RowState::AtHi, hi)
            } else {
                (RowState::Unprocessed, 0.0)
            };
        }
        // (A fresh pass sets its friction bounds from the coefficients in
        // `p` as it goes, so nothing needs undoing before one.)
        if self.clamp_independent(ctx).is_err() || !self.settle(p, ctx) {
            return self.run_pass(p, ctx, true);
        }
        self.drive_unprocessed(ctx)
    }

    /// Clamps the unprocessed rows, in the pass's order, that are
    /// independent of the rows clamped before them (Schur complement above
    /// `pivot_tolerance` of the diagonal); the others stay unprocessed.
    fn clamp_independent(&mut self, ctx: Ctx) -> Result<(), LcpError> {
        for k in 0..self.n {
            let d = self.order[k];
            if self.state[d] != RowState::Unprocessed {
                continue;
            }
            let schur = self.direction(ctx, d, 1.0)?;
            if schur > ctx.opts.pivot_tolerance * ctx.mat.at(d, d).abs() && schur > 0.0 {
                self.clamp_driven(ctx, d, schur)?;
            }
        }
        Ok(())
    }

    /// Drives the unprocessed rows, in the pass's order.
    fn drive_unprocessed(&mut self, ctx: Ctx) -> Result<(), LcpError> {
        for k in 0..self.n {
            let d = self.order[k];
            if self.state[d] == RowState::Unprocessed {
                self.drive(ctx, d)?;
            }
        }
        Ok(())
    }

    /// Solves x_C for the rows at their bounds, and sends the processed rows
    /// that then miss their condition back to unprocessed (x = 0), until
    /// none does (`RESUME_ROUNDS` times at most). Whether it got there: then
    /// every processed row meets its condition and the factor holds A_CC,
    /// the state the drive needs.
    fn settle(&mut self, p: &LcpProblem, ctx: Ctx) -> bool {
        let n = self.n;
        let mut settled = false;
        for _ in 0..RESUME_ROUNDS {
            if self.polish(p, ctx).is_err() {
                break;
            }
            let mut missed = 0;
            for i in 0..n {
                let (w, s) = self.fresh_w(ctx, i);
                self.w[i] = w;
                let zero = ZERO_FRACTION * ctx.opts.tolerance * s;
                let miss = match self.state[i] {
                    RowState::Clamped => self.x[i] < self.lo[i] || self.x[i] > self.hi[i],
                    RowState::AtLo => w < -zero,
                    RowState::AtHi => w > zero,
                    RowState::Free => w.abs() > zero,
                    RowState::Fixed | RowState::Unprocessed => false,
                };
                if miss {
                    self.state[i] = RowState::Unprocessed;
                    self.x[i] = 0.0;
                    missed += 1;
                }
            }
            if missed == 0 {
                settled = true;
                break;
            }
            let state = &self.state;
            self.clamped.retain(|&k| state[k] == RowState::Clamped);
        }
        settled
    }
}
