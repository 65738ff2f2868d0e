//! Dantzig's principal pivoting method for the (boxed) linear complementarity
//! problem of SPEC §2.4 (eq. 3.15), extended to friction rows as in ODE.
//!
//! # The problem
//!
//! Given a dense n×n matrix A (row-major, see [`LcpProblem::a`]), a vector b and
//! bounds lo ≤ 0 ≤ hi (lo may be −∞, hi may be +∞), find x and w = A x + b with
//! lo ≤ x ≤ hi and, row by row,
//!
//! ```text
//!     x_i = lo_i        ⇒  w_i ≥ 0
//!     x_i = hi_i        ⇒  w_i ≤ 0
//!     lo_i < x_i < hi_i ⇒  w_i = 0
//! ```
//!
//! With lo = 0 and hi = ∞ this is the standard LCP w = A x + b ≥ 0, x ≥ 0,
//! xᵀw = 0: Baraff's V' = A p + V with impulses p and post-impulse relative
//! normal velocities V' (SPEC eq. 3.15). A friction row i has `findex[i] =
//! Some(j)`: its bounds follow the normal impulse x_j of its contact,
//! lo_i = −mu_i |x_j| and hi_i = mu_i |x_j| (ODE's convention), so the friction
//! impulse may not exceed mu times the normal impulse.
//!
//! # The method (Baraff 1994, "drive to zero"; boxed as in ODE's `dxSolveLCP`)
//!
//! Rows are taken one at a time. Every row already taken ("processed") keeps its
//! condition at all times: it is either *clamped* (in C: lo < x < hi and w = 0)
//! or *not clamped* (in N: x at a bound with w of the right sign, or a free row
//! with w = 0, see below). Unprocessed rows sit at x = 0. To take row d, compute
//! w_d; if it already satisfies its condition at x_d = 0 it joins N at once.
//! Otherwise x_d moves in the direction `dir` = sign(−w_d) while x_C moves so that
//! every clamped row keeps w = 0:
//!
//! ```text
//!     Δx_d = dir,   A_CC Δx_C + A_Cd Δx_d = 0   ⇒   Δx_C = −dir · A_CC⁻¹ A_Cd
//!     Δw   = A Δx   (Δw_C = 0 by construction)
//!     Δw_d = dir · (A_dd − A_dC A_CC⁻¹ A_Cd) = dir · Δa_d
//! ```
//!
//! Δa_d is the Schur complement of A_CC in A_{C+d, C+d}; for positive
//! semidefinite A it is ≥ 0, and it is 0 exactly when row d depends on the
//! clamped rows. The step is the largest s ≥ 0 that keeps every condition:
//!
//! ```text
//!     w_d reaches 0:            s = −w_d / Δw_d            (only if Δa_d > 0)
//!     x_d reaches its bound:    s = (hi_d − x_d) or (x_d − lo_d)
//!     clamped k hits a bound:   s = (lo_k − x_k)/Δx_k  or (hi_k − x_k)/Δx_k
//!     not-clamped k gets w = 0: s = −w_k / Δw_k         (only if w_k moves the wrong way)
//! ```
//!
//! The row that limits the step changes set (C → N or N → C) and the direction is
//! recomputed; the drive of d ends when d itself reaches w_d = 0 (d joins C) or
//! its bound (d joins N). With no limit at all the direction is an unbounded ray
//! along which w_d never reaches its target: for positive semidefinite A that
//! proves the problem infeasible ([`LcpError::Infeasible`]), unless |w_d| is
//! already within a tenth of the tolerance (see below). For indefinite A the
//! method can also stop this way on a problem that has a solution.
//!
//! # Degeneracy (redundant contacts)
//!
//! A box face on a floor gives four coplanar contacts but only three independent
//! normal rows, so A is singular. The rules that keep the method finite and
//! NaN-free, with no regularisation of the answer:
//!
//! * **A dependent row is never clamped.** d joins C through "w_d reaches 0"
//!   only if Δa_d > `pivot_tolerance` · A_dd. Otherwise d is dependent: Δw = 0
//!   everywhere (for PSD A, A Δx = 0 exactly), so the step only shifts load along
//!   the null direction until a clamped row leaves C (after which d may be
//!   independent) or x_d reaches its bound. A not-clamped row k joins C only when
//!   Δw_k ≠ 0, and for PSD A, |Δw_k|² ≤ Δa_k · Δa_d, so such a row is independent
//!   of C too. If nothing limits the shift, d stays where it is when
//!   |w_d| ≤ 0.1 · tolerance · σ_d (a 1e12-conditioned block leaves Δa_d and
//!   w_d at ~1e-12 of their scale), else the problem is infeasible. There is
//!   deliberately no fallback that divides by a sub-threshold Δa_d: on
//!   rank-deficient matrices that Δa_d is rounding (seen at 1e-12 · A_dd), and
//!   the impulses of 1e13 it gives only look like a solution.
//! * **w already zero.** A row whose w_d is zero up to rounding when it is taken
//!   joins N at its bound (or, inside its bounds, joins C if independent and
//!   otherwise stays *free* at x = 0 with w = 0, watched like any N row). For
//!   contact data b = J v lies in the range of A, and the fourth coplanar contact
//!   arrives with w_d ≈ 1e-16 relative: it takes no impulse and needs no pivot.
//! * **Rounding noise is not a direction.** Δx and Δw entries below
//!   1e-13 × their scale are treated as zero in the ratio test, so no zero-length
//!   step is taken on noise (the "s <= 0" failure DART users meet on stacks).
//!   Zero-length steps on genuine ties are legal pivots; ties go to d's own
//!   events, then to rows leaving C, then to the lowest index; the total number of
//!   pivots is capped.
//! * **Pivot floor.** A pivot of the clamped factor below 1e-13 · max_i A_ii
//!   (only reachable through rounding) is raised to that floor and counted in
//!   [`LcpSolution::regularized_pivots`]: a diagonal change of at most
//!   1e-13 · max A_ii on that row, i.e. a relative residual of the same size.
//!
//! # Factorisation
//!
//! For symmetric A the solver keeps an LDLᵀ factor of A_CC (column-major, L
//! below and D on the diagonal). Adding a row k appends one row of L by forward
//! substitution: with y = L⁻¹ A_Ck, the new row is lᵀ = (D⁻¹ y)ᵀ and the new pivot
//! is A_kk − yᵀ D⁻¹ y = Δa_k, the very Schur complement above (when d joins, y is
//! a by-product of its direction, so the append is O(|C|)). Removing the row at
//! position p leaves the leading block as it is and turns the trailing block into
//! L₃₃ D₃ L₃₃ᵀ + d_p l₃ l₃ᵀ, a rank-one update (Gill, Golub, Murray & Saunders
//! 1974, method C1). Both are O(|C|²) instead of the O(|C|³) of refactoring.
//!
//! Where faer is used: full LDLᵀ factorisations (refactor-each-pivot, the
//! final refinement, and the rare rebuild after a failed update) of blocks from
//! [`LcpOptions::faer_min_clamped`] rows on (64 by default, where NOTES.md
//! measured faer ahead), with `Par::Seq`. The per-pivot work is O(|C|²) (one
//! triangular solve with a single right-hand side, one append or rank-one
//! update), and there hand-rolled column-major loops were measured faster than
//! faer's triangular solves up to |C| = 128 (bench: 636 µs against 776 µs a
//! solve at n = 128), so those stay hand-rolled and allocation-free.
//!
//! Non-symmetric A (e.g. Murty's P-matrix) cannot use LDLᵀ: A_CC is then
//! refactored by LU with partial pivoting whenever C changes. The pivot rule itself
//! does not rely on symmetry: it is correct for any P-matrix.
//!
//! # Verification
//!
//! After solving, w = A x + b is recomputed and every condition checked. With
//! σ_i = |b_i| + Σ_j |A_ij x_j| (the size of what row i sums, so its rounding
//! error is ≲ n ε σ_i) and X = max_j |x_j|, row i's violation is
//!
//! ```text
//!     bounds:             max(lo_i − x_i, x_i − hi_i, 0) / X
//!     w_i > 0 (needs lo): min(w_i / σ_i, (x_i − lo_i) / X)
//!     w_i < 0 (needs hi): min(−w_i / σ_i, (hi_i − x_i) / X)
//! ```
//!
//! and the largest must not exceed [`LcpOptions::tolerance`] (1e-9 by default).
//! Before the check, x is projected onto its bounds (it can sit 1e-17 outside
//! after many steps). If the check fails, x_C is recomputed once from a fresh
//! factor of the final clamped set (for friction problems, the exact step
//! below) and checked again; failing that, the solve returns
//! [`LcpError::Numerical`]. NaN never leaves this module: input is checked for
//! non-finite values and every direction and step is checked before use.
//!
//! # Friction rows
//!
//! Friction rows are taken after all other rows, their bounds set from the
//! current normal impulse when they are taken (ODE). Normal impulses can still
//! change afterwards (friction torques shift load between corners), so the
//! bounds are recomputed from the final x and checked. If they moved:
//!
//! 1. **Exact step.** With the active sets of the pass fixed, a friction row at
//!    a bound has x_i = c_i |x_j|, linear in its normal impulse, so one LU solve
//!    of the clamped rows with those rows substituted gives the consistent
//!    solution (see `friction_newton`). It is kept only if it verifies.
//! 2. **Another pass.** Otherwise the whole problem is solved again with the
//!    bounds frozen at the values of the last x (averaged with the previous
//!    pass's from the third pass on, which breaks the two-cycles that coplanar
//!    contacts cause), then step 1 again, up to
//!    [`LcpOptions::max_friction_passes`]. With
//!    [`LcpOptions::resume_passes`] (the default) such a pass starts from the
//!    last pass's sets rather than from nothing (`resume_pass`): x_C is
//!    solved anew for the new bounds, the rows that then miss their
//!    condition go back to unprocessed, and only those are driven.
//!
//! # Starting from a guess
//!
//! [`LcpProblem::start`] (e.g. the last step's impulses of the same
//! contacts) makes the first pass start from the sets the guess implies:
//! friction bounds frozen at μ times the guess's normal impulses, each row
//! at the bound the guess puts it on, the rows inside their bounds clamped
//! where independent of those clamped before (`start_pass`), then as a
//! resumed pass. Every processed row meets its condition before the drive
//! starts, as the method needs, so the answer is one of Dantzig's and is
//! verified the same way; where the guess's sets do not settle in
//! `RESUME_ROUNDS` rounds, the pass starts from nothing after all.
//!
//! On 3000 random stacks of 1–4 boxes with 4 corner contacts each (12–48 rows,
//! mu 0.1–1), 21 % finish in one pass, the mean is 3 passes, and 3 (0.1 %) find no
//! consistent bounds in 50 passes and return [`LcpError::Numerical`] (the
//! coupled problem is not an LCP, and neither Dantzig's method nor this
//! iteration is guaranteed to converge on it): the caller should fall back to
//! an iterative method for those.
//!
//! # Where things are
//!
//! The problem and its input check (`problem`), the options (`options`),
//! the solution and the errors (`solution`); the workspace and its loop
//! over passes (`workspace`), the passes (`passes`), the drive of one row
//! (`drive`), the clamped set's changes (`clamp`), the factor of A_CC
//! (`factor`), and the refinement and final check after a pass
//! (`refine`).

mod clamp;
mod drive;
mod factor;
mod options;
mod passes;
mod problem;
mod refine;
mod solution;
#[cfg(test)]
mod tests;
mod workspace;

pub use options::{FAER_MIN_CLAMPED, Factorization, LcpOptions};
pub use problem::{LcpProblem, RowFactors};
pub use solution::{LcpError, LcpSolution};
pub use workspace::LcpWorkspace;

/// Solves with default options and a fresh workspace. For many solves, keep a
/// [`LcpWorkspace`] to avoid allocating each time.
pub fn solve(problem: &LcpProblem) -> Result<LcpSolution, LcpError> {
    LcpWorkspace::new().solve(problem, &LcpOptions::default())
}

/// Solves the standard LCP w = A x + b ≥ 0, x ≥ 0, xᵀw = 0 (A row-major n×n).
pub fn solve_standard(a: &[f64], b: &[f64]) -> Result<LcpSolution, LcpError> {
    solve(&LcpProblem::standard(a, b))
}

/// Entries below `NOISE` × their scale are rounding, not directions.
const NOISE: f64 = 1e-13;
/// Pivots below `PIVOT_FLOOR` · max A_ii are raised to it (see the module docs).
const PIVOT_FLOOR: f64 = 1e-13;
/// A pivot below −`NEGATIVE_PIVOT` · max A_ii is no rounding: A is not PSD.
const NEGATIVE_PIVOT: f64 = 1e-8;
/// |A_ij − A_ji| ≤ `SYMMETRY` · (row scale) counts as symmetric: contact
/// matrices built as J M⁻¹ Jᵀ differ from their transpose by rounding only.
const SYMMETRY: f64 = 1e-10;
/// w_d counts as zero when |w_d| ≤ `ZERO_FRACTION` · tolerance · σ_d.
const ZERO_FRACTION: f64 = 1e-3;
/// A dependent row whose drive finds no limit is accepted as it stands when
/// |w_d| ≤ `RAY_FRACTION` · tolerance · σ_d; otherwise the problem is infeasible.
const RAY_FRACTION: f64 = 0.1;
/// Rounds of `LcpWorkspace::settle` (each a fresh factor of the clamped
/// rows) before a start or resumed pass gives up and restarts from nothing.
/// In a pile a row sent back to unprocessed shifts its neighbours' x_C,
/// which can send them back in the next round, so settling may take many
/// rounds, and each restart costs a whole fresh pass.
const RESUME_ROUNDS: usize = 16;
