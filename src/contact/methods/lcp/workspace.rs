//! The workspace: the buffers a solve reuses, and the solve itself, its
//! passes until the friction bounds agree with the normal impulses.

use super::factor::{Factor, Mat};
use super::options::{Factorization, LcpOptions};
use super::problem::{LcpProblem, RowFactors, check_input};
use super::solution::{LcpError, LcpSolution, unmet};
use super::{PIVOT_FLOOR, SYMMETRY};

/// Where a row stands in the pass (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum RowState {
    Unprocessed,
    Clamped,
    AtLo,
    AtHi,
    /// Not clamped, inside its bounds with w = 0 (a dependent row).
    Free,
    /// lo = hi: x is fixed and w is unconstrained.
    Fixed,
}

/// Reusable buffers: one workspace solves any number of problems of any size
/// without allocating once it has seen the largest.
pub struct LcpWorkspace {
    pub(super) n: usize,
    pub(super) x: Vec<f64>,
    pub(super) w: Vec<f64>,
    pub(super) sigma: Vec<f64>,
    /// x of the last pass, kept while an exact friction step is tried.
    pub(super) x_pass: Vec<f64>,
    /// Position of each row in C (usize::MAX if not clamped), for friction steps.
    pub(super) cpos: Vec<usize>,
    pub(super) prev_lo: Vec<f64>,
    pub(super) prev_hi: Vec<f64>,
    pub(super) lo: Vec<f64>,
    pub(super) hi: Vec<f64>,
    pub(super) state: Vec<RowState>,
    pub(super) order: Vec<usize>,
    pub(super) row_scale: Vec<f64>,
    /// C, in factor order.
    pub(super) clamped: Vec<usize>,
    /// Δx over C (factor order) for the current direction.
    pub(super) dxc: Vec<f64>,
    /// Δw of not-clamped rows for the current direction.
    pub(super) dw: Vec<f64>,
    /// The bodies' velocity change of the current direction (with `RowFactors`).
    pub(super) du: Vec<f64>,
    /// L⁻¹ A_Cd and D⁻¹ L⁻¹ A_Cd of the current direction (factor order).
    pub(super) y: Vec<f64>,
    pub(super) z: Vec<f64>,
    pub(super) factor: Factor,
    pub(super) symmetric: bool,
    pub(super) floor: f64,
    pub(super) pivots: usize,
    pub(super) pivot_limit: usize,
}

impl Default for LcpWorkspace {
    fn default() -> Self {
        Self::new()
    }
}

/// Per-solve settings the drive needs.
#[derive(Clone, Copy)]
pub(super) struct Ctx<'a> {
    pub(super) mat: Mat<'a>,
    pub(super) b: &'a [f64],
    pub(super) opts: &'a LcpOptions,
    pub(super) refactor: bool,
    pub(super) factors: Option<RowFactors<'a>>,
}

impl LcpWorkspace {
    pub fn new() -> Self {
        Self {
            n: 0,
            x: Vec::new(),
            w: Vec::new(),
            sigma: Vec::new(),
            x_pass: Vec::new(),
            cpos: Vec::new(),
            prev_lo: Vec::new(),
            prev_hi: Vec::new(),
            lo: Vec::new(),
            hi: Vec::new(),
            state: Vec::new(),
            order: Vec::new(),
            row_scale: Vec::new(),
            clamped: Vec::new(),
            dxc: Vec::new(),
            dw: Vec::new(),
            du: Vec::new(),
            y: Vec::new(),
            z: Vec::new(),
            factor: Factor::new(),
            symmetric: true,
            floor: 0.0,
            pivots: 0,
            pivot_limit: 0,
        }
    }

    /// Solves `problem`, returning a verified solution.
    pub fn solve(
        &mut self,
        problem: &LcpProblem,
        options: &LcpOptions,
    ) -> Result<LcpSolution, LcpError> {
        let mut solution = LcpSolution::default();
        self.solve_into(problem, options, &mut solution)?;
        Ok(solution)
    }

    /// Like [`LcpWorkspace::solve`], writing into `solution` to reuse its buffers.
    /// On error `solution` is left unspecified (but finite).
    pub fn solve_into(
        &mut self,
        problem: &LcpProblem,
        options: &LcpOptions,
        solution: &mut LcpSolution,
    ) -> Result<(), LcpError> {
        let n = self.prepare(problem, options)?;
        let mat = Mat { a: problem.a, n };
        let ctx = Ctx {
            mat,
            b: problem.b,
            opts: options,
            refactor: options.factorization == Factorization::Refactor || !self.symmetric,
            factors: problem.factors,
        };
        let has_friction = problem.findex.iter().any(Option::is_some);
        let passes = if has_friction {
            options.max_friction_passes.max(1)
        } else {
            1
        };
        let mut total_pivots = 0;
        let mut violation = f64::INFINITY;
        for pass in 0..passes {
            self.pivots = 0;
            let run = if pass == 0 {
                match problem.start {
                    Some(start) => self.start_pass(problem, ctx, start),
                    None => self.run_pass(problem, ctx, true),
                }
            } else if options.resume_passes {
                self.resume_pass(problem, ctx)
            } else {
                self.run_pass(problem, ctx, false)
            };
            total_pivots += self.pivots;
            run?;
            violation = self.finish(problem, ctx)?;
            if violation > options.tolerance {
                if has_friction {
                    // Solve for the fixed point of this pass's active sets; keep
                    // it only if it verifies (with a wrong active set it can give
                    // negative normal impulses), else go on from this pass's x.
                    self.x_pass.clear();
                    self.x_pass.extend_from_slice(&self.x[..n]);
                    if self.friction_newton(problem, ctx) {
                        violation = self.finish(problem, ctx)?;
                        if violation > options.tolerance {
                            self.x[..n].copy_from_slice(&self.x_pass);
                            violation = self.finish(problem, ctx)?;
                        }
                    }
                } else {
                    // Recompute x_C from a fresh factor of the final clamped
                    // set: removes drift accumulated by the incremental steps.
                    self.polish(problem, ctx)?;
                    violation = self.finish(problem, ctx)?;
                }
            }
            if violation <= options.tolerance {
                solution.x.clear();
                solution.x.extend_from_slice(&self.x[..n]);
                solution.w.clear();
                solution.w.extend_from_slice(&self.w[..n]);
                solution.pivots = total_pivots;
                solution.max_violation = violation;
                solution.friction_passes = pass + 1;
                solution.regularized_pivots = self.factor.regularized;
                return Ok(());
            }
            if !has_friction {
                break;
            }
            // `finish` left the friction bounds computed from this pass's x:
            // the next pass solves with them frozen. From the third pass on they
            // are averaged with the previous pass's: on coplanar contacts the load
            // can jump between equivalent distributions from pass to pass, and
            // the average stops that two-cycle (on 3000 random box stacks with
            // friction, failures fell from 3 % to 0.1 %).
            self.next_bounds(problem, pass);
        }
        Err(unmet(n, has_friction, passes, violation, options.tolerance))
    }

    /// The friction bounds of the pass after `pass`, from those `finish`
    /// left (averaged with the previous pass's from the third pass on).
    fn next_bounds(&mut self, problem: &LcpProblem, pass: usize) {
        let n = self.n;
        if pass >= 1 {
            for i in 0..n {
                if problem.findex.get(i).is_some_and(Option::is_some) {
                    self.lo[i] = 0.5 * (self.lo[i] + self.prev_lo[i]);
                    self.hi[i] = 0.5 * (self.hi[i] + self.prev_hi[i]);
                }
            }
        }
        self.prev_lo.clear();
        self.prev_lo.extend_from_slice(&self.lo[..n]);
        self.prev_hi.clear();
        self.prev_hi.extend_from_slice(&self.hi[..n]);
    }

    /// Checks the input and sizes the buffers. Returns n.
    fn prepare(&mut self, p: &LcpProblem, opts: &LcpOptions) -> Result<usize, LcpError> {
        let n = check_input(p)?;
        self.reset(p, opts, n);
        Ok(n)
    }

    /// Sizes the buffers for problem `p` of `n` rows and sets its scales.
    fn reset(&mut self, p: &LcpProblem, opts: &LcpOptions, n: usize) {
        self.n = n;
        self.x.clear();
        self.x.resize(n, 0.0);
        self.w.clear();
        self.w.resize(n, 0.0);
        self.sigma.clear();
        self.sigma.resize(n, 0.0);
        self.lo.clear();
        self.hi.clear();
        if p.lo.is_empty() {
            self.lo.resize(n, 0.0);
        } else {
            self.lo.extend_from_slice(p.lo);
        }
        if p.hi.is_empty() {
            self.hi.resize(n, f64::INFINITY);
        } else {
            self.hi.extend_from_slice(p.hi);
        }
        self.state.clear();
        self.state.resize(n, RowState::Unprocessed);
        self.dw.clear();
        self.dw.resize(n, 0.0);
        for v in [&mut self.dxc, &mut self.y, &mut self.z] {
            v.clear();
            v.resize(n, 0.0);
        }
        self.clamped.clear();
        self.factor.reserve(n, opts.faer_min_clamped);
        self.factor.regularized = 0;

        // Friction rows last, so the normal impulses exist when they are taken.
        self.order.clear();
        let is_friction = |i: usize| p.findex.get(i).is_some_and(Option::is_some);
        self.order.extend((0..n).filter(|&i| !is_friction(i)));
        self.order.extend((0..n).filter(|&i| is_friction(i)));

        let mat = Mat { a: p.a, n };
        self.row_scale.clear();
        self.row_scale
            .extend((0..n).map(|i| mat.row(i).iter().fold(0.0f64, |m, v| m.max(v.abs()))));
        self.symmetric = (0..n).all(|i| {
            (0..i).all(|j| {
                (mat.at(i, j) - mat.at(j, i)).abs()
                    <= SYMMETRY * self.row_scale[i].max(self.row_scale[j])
            })
        });
        let max_diag = (0..n).fold(0.0f64, |m, i| m.max(mat.at(i, i).abs()));
        let amax = self.row_scale.iter().fold(0.0f64, |m, v| m.max(*v));
        self.floor = PIVOT_FLOOR
            * if max_diag > 0.0 {
                max_diag
            } else {
                amax.max(1.0)
            };
        self.pivot_limit = opts.max_pivots.unwrap_or(50 * n + 100);
    }
}
