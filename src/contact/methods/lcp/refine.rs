//! After a pass: the exact friction step, x_C anew from a fresh factor,
//! and the final check of every condition.

use super::problem::LcpProblem;
use super::solution::LcpError;
use super::workspace::{Ctx, LcpWorkspace, RowState};

impl LcpWorkspace {
    /// Makes friction bounds consistent for the active sets of the last pass.
    ///
    /// A friction row i at a bound has x_i = c_i |x_j| (c_i = lo or hi
    /// coefficient), which is linear in its normal impulse x_j. If the active
    /// sets are right, the consistent solution solves, for the clamped rows k,
    ///
    /// ```text
    ///     Σ_{c∈C} (A_kc + Σ_{i at a bound, j(i) = c} A_ki c_i sign(x_c)) x_c
    ///         = −b_k − Σ_{other j ∉ C} A_kj x_j
    /// ```
    ///
    /// a non-symmetric system (solved by LU): one exact step instead of a
    /// fixed-point iteration whose rate is the normal–friction coupling times mu.
    /// Returns false if the system is singular (x is then left unchanged).
    pub(super) fn friction_newton(&mut self, p: &LcpProblem, ctx: Ctx) -> bool {
        let (n, m, cap) = (self.n, self.clamped.len(), self.factor.cap);
        if m == 0 {
            return false;
        }
        self.cpos.clear();
        self.cpos.resize(n, usize::MAX);
        for (r, &k) in self.clamped.iter().enumerate() {
            self.cpos[k] = r;
        }
        // A friction row at a bound whose normal is clamped: x_i = coef · x_j.
        let coupled = |state: &[RowState], x: &[f64], cpos: &[usize], i: usize| {
            let j = p.findex.get(i).copied().flatten()?;
            let c = match state[i] {
                RowState::AtLo => p.lo[i],
                RowState::AtHi => p.hi[i],
                _ => return None,
            };
            (cpos[j] != usize::MAX).then_some((j, if x[j] < 0.0 { -c } else { c }))
        };
        for (rk, &k) in self.clamped.iter().enumerate() {
            let row = ctx.mat.row(k);
            for (rc, &c) in self.clamped.iter().enumerate() {
                self.factor.ld[rc * cap + rk] = row[c];
            }
            let mut rhs = -p.b[k];
            for (i, (&a, &st)) in row.iter().zip(&self.state[..n]).enumerate() {
                if st == RowState::Clamped {
                    continue;
                }
                match coupled(&self.state, &self.x, &self.cpos, i) {
                    Some((j, coef)) => self.factor.ld[self.cpos[j] * cap + rk] += a * coef,
                    None => rhs -= a * self.x[i],
                }
            }
            self.y[rk] = rhs;
        }
        // Whatever happens next, the factor no longer holds A_CC.
        self.factor.dirty = true;
        if self.factor.lu_in_place(m).is_err() {
            return false;
        }
        for r in 0..m {
            self.z[r] = self.y[self.factor.perm[r]];
        }
        self.factor.forward(&mut self.z);
        self.factor.backward_upper(&mut self.z);
        if self.z[..m].iter().any(|v| !v.is_finite()) {
            return false;
        }
        for (r, &k) in self.clamped.iter().enumerate() {
            self.x[k] = self.z[r];
        }
        for i in 0..n {
            if let Some((j, coef)) = coupled(&self.state, &self.x, &self.cpos, i) {
                self.x[i] = coef * self.x[j];
            }
        }
        true
    }

    /// x_C ← −A_CC⁻¹ (b_C + A_CN x_N) from a fresh factor.
    pub(super) fn polish(&mut self, p: &LcpProblem, ctx: Ctx) -> Result<(), LcpError> {
        let m = self.clamped.len();
        if m == 0 {
            // The factor of no rows: `settle` may have sent every clamped
            // row back, and the drive's `direction` takes an empty C as it
            // stands (a stale factor would be appended to past its end).
            self.factor.clear();
            return Ok(());
        }
        self.factor.dirty = true;
        self.ensure_factor(ctx)?;
        let (mat, n) = (ctx.mat, self.n);
        for r in 0..m {
            let k = self.clamped[r];
            let row = mat.row(k);
            let mut s = p.b[k];
            for ((a, x), st) in row.iter().zip(&self.x[..n]).zip(&self.state[..n]) {
                if *st != RowState::Clamped {
                    s += a * x;
                }
            }
            self.y[r] = -s;
        }
        if self.symmetric {
            self.factor.forward(&mut self.y);
            for r in 0..m {
                self.y[r] /= self.factor.d(r);
            }
            self.factor.backward(&mut self.y);
            for r in 0..m {
                self.x[self.clamped[r]] = self.y[r];
            }
        } else {
            for r in 0..m {
                self.z[r] = self.y[self.factor.perm[r]];
            }
            self.factor.forward(&mut self.z);
            self.factor.backward_upper(&mut self.z);
            for r in 0..m {
                self.x[self.clamped[r]] = self.z[r];
            }
        }
        Ok(())
    }

    /// Projects x onto its bounds (friction bounds recomputed from the final
    /// normal impulses), recomputes w = A x + b and returns the largest scaled
    /// violation of the conditions.
    pub(super) fn finish(&mut self, p: &LcpProblem, ctx: Ctx) -> Result<f64, LcpError> {
        let n = self.n;
        if let Some(i) = self.x[..n].iter().position(|v| !v.is_finite()) {
            return Err(LcpError::Numerical {
                size: n,
                detail: format!("non-finite impulse x[{i}]"),
            });
        }
        for &i in &self.order {
            if let Some(Some(j)) = p.findex.get(i) {
                let normal = self.x[*j].abs();
                self.lo[i] = p.lo[i] * normal;
                self.hi[i] = p.hi[i] * normal;
            }
            self.x[i] = self.x[i].clamp(self.lo[i], self.hi[i]);
        }
        for i in 0..n {
            let (w, s) = self.fresh_w(ctx, i);
            self.w[i] = w;
            self.sigma[i] = s;
        }
        let xs = self.x[..n]
            .iter()
            .fold(f64::MIN_POSITIVE, |m, v| m.max(v.abs()));
        let mut worst = 0.0f64;
        for i in 0..n {
            let (x, w, s, lo, hi) = (self.x[i], self.w[i], self.sigma[i], self.lo[i], self.hi[i]);
            let mut v = ((lo - x).max(x - hi)).max(0.0) / xs;
            if lo < hi && w != 0.0 {
                let c = if w > 0.0 {
                    (w / s).min((x - lo) / xs)
                } else {
                    (-w / s).min((hi - x) / xs)
                };
                v = v.max(c);
            }
            worst = worst.max(v);
        }
        if !worst.is_finite() || self.w[..n].iter().any(|v| !v.is_finite()) {
            return Err(LcpError::Numerical {
                size: n,
                detail: "non-finite w = A x + b".to_string(),
            });
        }
        Ok(worst)
    }
}
