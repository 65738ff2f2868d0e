//! Rows joining and leaving the clamped set C, the factor of A_CC
//! following each change.

use super::NOISE;
use super::factor::dot;
use super::solution::LcpError;
use super::workspace::{Ctx, LcpWorkspace, RowState};

impl LcpWorkspace {
    pub(super) fn ensure_factor(&mut self, ctx: Ctx) -> Result<(), LcpError> {
        if self.factor.dirty || self.factor.m != self.clamped.len() {
            self.factor
                .refactor(
                    ctx.mat,
                    &self.clamped,
                    self.symmetric,
                    ctx.opts.faer_min_clamped,
                    self.floor,
                )
                .map_err(|detail| LcpError::Numerical {
                    size: self.n,
                    detail: if self.symmetric {
                        detail
                    } else {
                        format!("{detail} in a non-symmetric A: not a P-matrix")
                    },
                })?;
        }
        Ok(())
    }

    /// d joins C at the end of its drive; its factor row is the z of its last
    /// direction and its pivot is Δa_d.
    pub(super) fn clamp_driven(&mut self, ctx: Ctx, d: usize, schur: f64) -> Result<(), LcpError> {
        self.state[d] = RowState::Clamped;
        if ctx.refactor {
            self.clamped.push(d);
            self.factor.dirty = true;
            return Ok(());
        }
        self.append_clamped(schur, d)
    }

    /// A not-clamped row k joins C: append its factor row, pivot Δa_k.
    pub(super) fn clamp_row(&mut self, ctx: Ctx, k: usize) -> Result<(), LcpError> {
        self.state[k] = RowState::Clamped;
        let m = self.clamped.len();
        if !self.symmetric {
            // Δa_k through the current LU, to refuse a singular block before
            // refactoring with it.
            self.ensure_factor(ctx)?;
            for r in 0..m {
                self.y[r] = ctx.mat.at(self.clamped[self.factor.perm[r]], k);
            }
            self.factor.forward(&mut self.y);
            self.factor.backward_upper(&mut self.y);
            let row = ctx.mat.row(k);
            let schur = row[k]
                - self
                    .clamped
                    .iter()
                    .zip(&self.y[..m])
                    .map(|(&c, u)| row[c] * u)
                    .sum::<f64>();
            if schur.is_nan() || schur.abs() <= NOISE * self.row_scale[k] {
                return Err(LcpError::Numerical {
                    size: self.n,
                    detail: format!(
                        "row {k} is dependent on the clamped rows of a non-symmetric A \
                         (Schur complement {schur:e}): not a P-matrix"
                    ),
                });
            }
        }
        if ctx.refactor {
            self.clamped.push(k);
            self.factor.dirty = true;
            return Ok(());
        }
        self.ensure_factor(ctx)?;
        let row = ctx.mat.row(k);
        for (yr, &c) in self.y.iter_mut().zip(&self.clamped) {
            *yr = row[c];
        }
        self.factor.forward(&mut self.y);
        for r in 0..m {
            self.z[r] = self.y[r] / self.factor.d(r);
        }
        let schur = row[k] - dot(&self.y[..m], &self.z[..m]);
        self.append_clamped(schur, k)
    }

    /// Row `row` joins C at the factor's end: its pivot (the Schur
    /// complement `schur`, checked against the floor) and the factor row
    /// in `z`.
    fn append_clamped(&mut self, schur: f64, row: usize) -> Result<(), LcpError> {
        let pivot = self
            .factor
            .checked_pivot(schur, self.floor)
            .map_err(|detail| LcpError::Numerical {
                size: self.n,
                detail,
            })?;
        self.factor.append(&self.z, pivot);
        self.clamped.push(row);
        Ok(())
    }

    /// The clamped row at factor position r leaves C.
    pub(super) fn unclamp(&mut self, ctx: Ctx, r: usize) -> Result<(), LcpError> {
        self.clamped.remove(r);
        if ctx.refactor {
            self.factor.dirty = true;
            return Ok(());
        }
        if !self.factor.remove(r, self.floor) {
            self.factor.dirty = true;
            self.ensure_factor(ctx)?;
        }
        Ok(())
    }
}
