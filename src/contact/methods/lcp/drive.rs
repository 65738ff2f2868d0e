//! The drive of one row d to its condition (see the module documentation,
//! *The method*): the direction Δx_C, Δw, the ratio test and the step.

use super::factor::dot;
use super::solution::LcpError;
use super::workspace::{Ctx, LcpWorkspace, RowState};
use super::{NOISE, RAY_FRACTION, ZERO_FRACTION};

/// Which bound of a row.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Side {
    Lo,
    Hi,
}

/// What limits a step of the drive of row d.
#[derive(Clone, Copy, Debug)]
enum Event {
    None,
    DriveZero,
    DriveBound(Side),
    Leave(usize, Side),
    Join(usize),
}

impl LcpWorkspace {
    /// w_d = A_d x + b_d and σ_d = |b_d| + Σ|A_dj x_j|.
    pub(super) fn fresh_w(&self, ctx: Ctx, d: usize) -> (f64, f64) {
        let row = ctx.mat.row(d);
        let (mut w, mut s) = (ctx.b[d], ctx.b[d].abs());
        for (a, x) in row.iter().zip(&self.x[..self.n]) {
            if *x != 0.0 {
                let t = a * x;
                w += t;
                s += t.abs();
            }
        }
        (w, s)
    }

    /// Takes row d: moves x_d (and x_C with it) until d meets its condition.
    pub(super) fn drive(&mut self, ctx: Ctx, d: usize) -> Result<(), LcpError> {
        let n = self.n;
        let (wd, sd) = self.fresh_w(ctx, d);
        self.w[d] = wd;
        let (lo, hi) = (self.lo[d], self.hi[d]);
        if lo == hi {
            self.x[d] = lo;
            self.state[d] = RowState::Fixed;
            return Ok(());
        }
        let zero = ZERO_FRACTION * ctx.opts.tolerance * sd;
        if lo == 0.0 && wd >= -zero {
            self.state[d] = RowState::AtLo;
            return Ok(());
        }
        if hi == 0.0 && wd <= zero {
            self.state[d] = RowState::AtHi;
            return Ok(());
        }
        let add = ctx.mat.at(d, d);
        let dependent_below = ctx.opts.pivot_tolerance * add.abs();
        if wd.abs() <= zero {
            // Inside its bounds with w_d = 0 already: clamp it if it is
            // independent of C, else leave it free at x_d = 0.
            self.w[d] = 0.0;
            let schur = self.direction(ctx, d, 1.0)?;
            if schur > dependent_below && schur > 0.0 {
                self.clamp_driven(ctx, d, schur)?;
            } else {
                self.state[d] = RowState::Free;
            }
            return Ok(());
        }
        let dir = if wd < 0.0 { 1.0 } else { -1.0 };
        loop {
            self.pivots += 1;
            if self.pivots > self.pivot_limit {
                return Err(LcpError::IterationLimit {
                    size: n,
                    pivots: self.pivots,
                });
            }
            let schur = self.direction(ctx, d, dir)?;
            let independent = schur > dependent_below && schur > 0.0;
            self.delta_w(ctx, d, dir);
            let (s, event) = self.ratio_test(d, dir, schur, independent);

            if let Event::None = event {
                return self.end_on_ray(ctx, d);
            }
            if !s.is_finite() {
                return Err(LcpError::Numerical {
                    size: n,
                    detail: format!("non-finite step length while driving row {d}"),
                });
            }

            if s > 0.0 {
                self.step(d, dir, s, schur);
            }

            match event {
                Event::None => unreachable!("handled above"),
                Event::DriveZero => {
                    self.w[d] = 0.0;
                    self.clamp_driven(ctx, d, schur)?;
                    return Ok(());
                }
                Event::DriveBound(side) => {
                    let (x, st) = match side {
                        Side::Lo => (self.lo[d], RowState::AtLo),
                        Side::Hi => (self.hi[d], RowState::AtHi),
                    };
                    self.x[d] = x;
                    self.state[d] = st;
                    return Ok(());
                }
                Event::Leave(r, side) => {
                    let k = self.clamped[r];
                    let (x, st) = match side {
                        Side::Lo => (self.lo[k], RowState::AtLo),
                        Side::Hi => (self.hi[k], RowState::AtHi),
                    };
                    self.x[k] = x;
                    self.w[k] = 0.0;
                    self.state[k] = st;
                    self.unclamp(ctx, r)?;
                }
                Event::Join(k) => {
                    self.w[k] = 0.0;
                    self.clamp_row(ctx, k)?;
                }
            }
        }
    }

    /// Driving row d along an unbounded ray: w_d never reaches 0 along it.
    /// A dependent row left with |w_d| within a tenth of the tolerance
    /// stays where it is (1e12-conditioned blocks leave Δa_d ≈ 1e-12 A_dd
    /// and w_d ≈ 1e-12 σ_d there); the final check counts it like any
    /// other row.
    fn end_on_ray(&mut self, ctx: Ctx, d: usize) -> Result<(), LcpError> {
        let (wd, sd) = self.fresh_w(ctx, d);
        self.w[d] = wd;
        if wd.abs() <= RAY_FRACTION * ctx.opts.tolerance * sd {
            self.state[d] = if self.x[d] == self.lo[d] {
                RowState::AtLo
            } else if self.x[d] == self.hi[d] {
                RowState::AtHi
            } else {
                RowState::Free
            };
            return Ok(());
        }
        // No fallback to driving a dependent row with its tiny Δa_d:
        // Δa_d below the threshold is rounding (seen at 1e-12 · A_dd on
        // rank-deficient Gram matrices), and dividing by it gives
        // impulses of 1e13 that only look like a solution.
        Err(LcpError::Infeasible {
            size: self.n,
            row: d,
        })
    }

    /// A step of length `s` in direction `dir` of driven row d: x_d and
    /// x_C move, and the w of the rows not clamped (Δw_C = 0).
    fn step(&mut self, d: usize, dir: f64, s: f64, schur: f64) {
        for (r, &k) in self.clamped.iter().enumerate() {
            self.x[k] += s * self.dxc[r];
        }
        self.x[d] += s * dir;
        for k in 0..self.n {
            if matches!(
                self.state[k],
                RowState::AtLo | RowState::AtHi | RowState::Free
            ) {
                self.w[k] += s * self.dw[k];
            }
        }
        self.w[d] += s * dir * schur;
    }

    /// The largest step keeping every condition, and the row that limits it.
    /// Ties go to d's own events, then to rows leaving C, then to the lowest
    /// index; entries below the rounding scale never limit (no steps on noise).
    fn ratio_test(&self, d: usize, dir: f64, schur: f64, independent: bool) -> (f64, Event) {
        let mut best = f64::INFINITY;
        let mut event = Event::None;
        let (bound, side) = if dir > 0.0 {
            (self.hi[d], Side::Hi)
        } else {
            (self.lo[d], Side::Lo)
        };
        if bound.is_finite() {
            best = ((bound - self.x[d]) * dir).max(0.0);
            event = Event::DriveBound(side);
        }
        if independent {
            let s = (-self.w[d] / (dir * schur)).max(0.0);
            if s < best {
                best = s;
                event = Event::DriveZero;
            }
        }
        let dx_tol = NOISE
            * self.dxc[..self.clamped.len()]
                .iter()
                .fold(1.0f64, |m, v| m.max(v.abs()));
        for (r, &k) in self.clamped.iter().enumerate() {
            let dx = self.dxc[r];
            let (s, side) = if dx < -dx_tol && self.lo[k].is_finite() {
                ((self.lo[k] - self.x[k]) / dx, Side::Lo)
            } else if dx > dx_tol && self.hi[k].is_finite() {
                ((self.hi[k] - self.x[k]) / dx, Side::Hi)
            } else {
                continue;
            };
            let s = s.max(0.0);
            if s < best {
                best = s;
                event = Event::Leave(r, side);
            }
        }
        let norm1 = 1.0
            + self.dxc[..self.clamped.len()]
                .iter()
                .map(|v| v.abs())
                .sum::<f64>();
        for k in 0..self.n {
            let dw = self.dw[k];
            let tol = NOISE * self.row_scale[k] * norm1;
            let limits = match self.state[k] {
                RowState::AtLo => dw < -tol,
                RowState::AtHi => dw > tol,
                RowState::Free => dw.abs() > tol,
                _ => false,
            };
            if limits {
                let s = (-self.w[k] / dw).max(0.0);
                if s < best {
                    best = s;
                    event = Event::Join(k);
                }
            }
        }
        (best, event)
    }

    /// Computes Δx_C for Δx_d = dir (into `dxc`) and returns Δa_d =
    /// A_dd − A_dC A_CC⁻¹ A_Cd. Leaves y = L⁻¹ A_Cd and z = D⁻¹ y for
    /// [`Self::clamp_driven`].
    pub(super) fn direction(&mut self, ctx: Ctx, d: usize, dir: f64) -> Result<f64, LcpError> {
        let m = self.clamped.len();
        let add = ctx.mat.at(d, d);
        if m == 0 {
            return Ok(add);
        }
        self.ensure_factor(ctx)?;
        let schur;
        if self.symmetric {
            let row = ctx.mat.row(d);
            for (yr, &k) in self.y.iter_mut().zip(&self.clamped) {
                *yr = row[k];
            }
            self.factor.forward(&mut self.y);
            for r in 0..m {
                self.z[r] = self.y[r] / self.factor.d(r);
            }
            schur = add - dot(&self.y[..m], &self.z[..m]);
            self.dxc[..m].copy_from_slice(&self.z[..m]);
            self.factor.backward(&mut self.dxc);
        } else {
            // A_CC u = A_Cd through the LU factor (rows permuted by `perm`).
            for r in 0..m {
                self.dxc[r] = ctx.mat.at(self.clamped[self.factor.perm[r]], d);
            }
            self.factor.forward(&mut self.dxc);
            self.factor.backward_upper(&mut self.dxc);
            let row = ctx.mat.row(d);
            schur = add
                - self
                    .clamped
                    .iter()
                    .zip(&self.dxc[..m])
                    .map(|(&k, u)| row[k] * u)
                    .sum::<f64>();
        }
        for v in &mut self.dxc[..m] {
            *v *= -dir;
        }
        if !schur.is_finite() || self.dxc[..m].iter().any(|v| !v.is_finite()) {
            return Err(LcpError::Numerical {
                size: self.n,
                detail: format!("non-finite direction while driving row {d}"),
            });
        }
        Ok(schur)
    }

    /// Δw_k = dir · A_kd + A_kC Δx_C for every not-clamped processed row.
    fn delta_w(&mut self, ctx: Ctx, d: usize, dir: f64) {
        let m = self.clamped.len();
        if let Some(f) = ctx.factors {
            self.du.clear();
            self.du.resize(6 * f.bodies, 0.0);
            let du = &mut self.du;
            let mut push = |row: usize, x: f64| {
                for side in 0..2 {
                    let at = 6 * f.body[row][side] as usize;
                    for (u, r) in du[at..at + 6].iter_mut().zip(&f.response[row][side]) {
                        *u += r * x;
                    }
                }
            };
            push(d, dir);
            for (&c, &dx) in self.clamped.iter().zip(&self.dxc[..m]) {
                push(c, dx);
            }
            for k in 0..self.n {
                if matches!(
                    self.state[k],
                    RowState::AtLo | RowState::AtHi | RowState::Free
                ) {
                    let mut s = 0.0;
                    for side in 0..2 {
                        let at = 6 * f.body[k][side] as usize;
                        s += dot(&f.jacobian[k][side], &self.du[at..at + 6]);
                    }
                    self.dw[k] = s;
                }
            }
            return;
        }
        for k in 0..self.n {
            if matches!(
                self.state[k],
                RowState::AtLo | RowState::AtHi | RowState::Free
            ) {
                let row = ctx.mat.row(k);
                let mut s = dir * row[d];
                for (&c, dx) in self.clamped.iter().zip(&self.dxc[..m]) {
                    s += row[c] * dx;
                }
                self.dw[k] = s;
            }
        }
    }
}
