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

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt;
use faer::{MatMut, Par};
use serde::{Deserialize, Serialize};

/// One (boxed) LCP. `n` is `b.len()`.
#[derive(Clone, Copy, Debug)]
pub struct LcpProblem<'a> {
    /// A, n×n, dense, **row-major**: `a[i * n + j]` = A_ij. For a symmetric
    /// nalgebra `DMatrix<f64>`, `m.as_slice()` is already this layout (column-major
    /// of Aᵀ = A); a non-symmetric `DMatrix` must be transposed first.
    pub a: &'a [f64],
    /// b, length n.
    pub b: &'a [f64],
    /// Lower bounds, each ≤ 0 (−∞ allowed); empty means all 0. For a friction
    /// row, the coefficient c with lo_i = c · |x_j| (pass −mu_i).
    pub lo: &'a [f64],
    /// Upper bounds, each ≥ 0 (+∞ allowed); empty means all +∞. For a friction
    /// row, the coefficient c with hi_i = c · |x_j| (pass mu_i).
    pub hi: &'a [f64],
    /// `findex[i] = Some(j)`: row i is a friction row bounded by row j's impulse;
    /// j must not itself be a friction row. Empty means no friction rows.
    pub findex: &'a [Option<usize>],
    /// A's factors where A = J M⁻¹ Jᵀ, or None (see [`RowFactors`]).
    pub factors: Option<RowFactors<'a>>,
    /// A guess of x (length n), e.g. the last step's impulses of the same
    /// contacts, or None. The first pass then starts from the sets the
    /// guess implies instead of from nothing (see `start_pass`); the
    /// answer meets the same conditions either way.
    pub start: Option<&'a [f64]>,
}

/// A = J M⁻¹ Jᵀ off its diagonal as its factors, for systems whose rows
/// each act on two bodies (contacts): row i's Jacobian on its two bodies
/// and the velocity change M⁻¹Jᵀ a unit impulse on it gives them. With
/// them the drive's Δw over the not-clamped rows costs O(rows + |C|) (the
/// bodies' velocity change from Δx_C, then each row's share of it) instead
/// of O(rows · |C|) through A's entries. A's diagonal may differ from the
/// factors' (compliance): Δw is only taken for rows that do not move.
#[derive(Clone, Copy, Debug)]
pub struct RowFactors<'a> {
    pub bodies: usize,
    /// Per row, the two bodies it acts on (indices below `bodies`).
    pub body: &'a [[u32; 2]],
    /// Per row and body, J: linear then angular part.
    pub jacobian: &'a [[[f64; 6]; 2]],
    /// Per row and body, M⁻¹Jᵀ: the linear then angular velocity change.
    pub response: &'a [[[f64; 6]; 2]],
}

impl<'a> LcpProblem<'a> {
    /// The standard LCP: lo = 0, hi = +∞.
    pub fn standard(a: &'a [f64], b: &'a [f64]) -> Self {
        Self {
            a,
            b,
            lo: &[],
            hi: &[],
            findex: &[],
            factors: None,
            start: None,
        }
    }

    /// A boxed LCP with fixed bounds.
    pub fn boxed(a: &'a [f64], b: &'a [f64], lo: &'a [f64], hi: &'a [f64]) -> Self {
        Self {
            a,
            b,
            lo,
            hi,
            findex: &[],
            factors: None,
            start: None,
        }
    }

    /// The same problem with friction rows (see [`LcpProblem::findex`]).
    pub fn with_friction(self, findex: &'a [Option<usize>]) -> Self {
        Self { findex, ..self }
    }

    /// The same problem with A's factors (see [`RowFactors`]).
    pub fn with_start(self, start: &'a [f64]) -> Self {
        LcpProblem {
            start: Some(start),
            ..self
        }
    }

    pub fn with_factors(self, factors: RowFactors<'a>) -> Self {
        Self {
            factors: Some(factors),
            ..self
        }
    }

    /// Number of rows n.
    pub fn size(&self) -> usize {
        self.b.len()
    }
}

/// How the factor of the clamped block A_CC follows the changes of C.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Factorization {
    /// Update the LDLᵀ factor on every change (O(|C|²) a pivot). The default.
    Incremental,
    /// Refactor A_CC from scratch after every change (O(|C|³) a pivot); kept to
    /// measure what the updates save, and always used for non-symmetric A.
    Refactor,
}

/// Tuning of [`LcpWorkspace::solve`]; the defaults suit contact problems.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct LcpOptions {
    /// Largest accepted scaled violation of the conditions (see the module
    /// documentation). Default 1e-9.
    pub tolerance: f64,
    /// Row d counts as dependent on the clamped rows, and is never clamped
    /// through "w_d reaches 0", when its Schur complement Δa_d ≤
    /// `pivot_tolerance` · A_dd. Default 1e-10: two orders above the rounding of
    /// Δa_d on 128-row stacks, far below a real contact's Δa_d.
    pub pivot_tolerance: f64,
    /// Pivots (steps) allowed per pass before [`LcpError::IterationLimit`];
    /// `None` means 50 n + 100, about 25 times what contact problems take.
    pub max_pivots: Option<usize>,
    /// Solves allowed to make friction bounds consistent with the normal
    /// impulses (see the module documentation). Default 50.
    pub max_friction_passes: usize,
    /// Incremental LDLᵀ (default) or refactor-each-pivot.
    pub factorization: Factorization,
    /// Clamped-set size from which full LDLᵀ factorisations use faer instead
    /// of the hand-rolled loop. Default [`FAER_MIN_CLAMPED`].
    pub faer_min_clamped: usize,
    /// Friction passes after the first start from the last pass's sets
    /// (`resume_pass`) instead of from nothing. Default true; the answer
    /// meets the same conditions either way, its rounding differs.
    pub resume_passes: bool,
}

/// Clamped-set size from which faer is used by default (NOTES.md: faer is
/// ahead from n ≈ 64, on par below).
pub const FAER_MIN_CLAMPED: usize = 64;

impl Default for LcpOptions {
    fn default() -> Self {
        Self {
            tolerance: 1e-9,
            pivot_tolerance: 1e-10,
            max_pivots: None,
            max_friction_passes: 50,
            factorization: Factorization::Incremental,
            faer_min_clamped: FAER_MIN_CLAMPED,
            resume_passes: true,
        }
    }
}

/// A verified solution.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LcpSolution {
    /// x (impulses), within the bounds.
    pub x: Vec<f64>,
    /// w = A x + b, recomputed from x.
    pub w: Vec<f64>,
    /// Pivoting steps taken over all passes.
    pub pivots: usize,
    /// Largest scaled violation found by the final check (≤ the tolerance).
    pub max_violation: f64,
    /// Solves needed to make friction bounds consistent (1 without friction).
    pub friction_passes: usize,
    /// Pivots raised to the floor of 1e-13 · max A_ii (see the module documentation).
    pub regularized_pivots: usize,
}

/// Why a solve failed. Every variant carries the system size.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum LcpError {
    /// An unbounded pivot ray: row `row` cannot reach its condition.
    #[error(
        "LCP with {size} rows has no solution: row {row} can never reach its complementarity \
         condition (unbounded pivoting ray); for contacts, check that b lies in the range of A \
         (no bias pushing two opposed contacts apart)"
    )]
    Infeasible { size: usize, row: usize },
    /// The pivot cap was reached (cycling through degenerate pivots).
    #[error(
        "LCP with {size} rows stopped after {pivots} pivots without converging (degenerate \
         cycling); raise LcpOptions::max_pivots or remove duplicate contacts"
    )]
    IterationLimit { size: usize, pivots: usize },
    /// The conditions could not be met to the tolerance, or a factor broke down.
    #[error("LCP with {size} rows failed numerically: {detail}")]
    Numerical { size: usize, detail: String },
    /// A, b or a bound holds NaN or an infinity where none is allowed.
    #[error(
        "LCP with {size} rows has a non-finite value in {what}[{index}]; check the system builder"
    )]
    NonFinite {
        size: usize,
        what: &'static str,
        index: usize,
    },
    /// Inconsistent sizes, bounds not bracketing 0, or a bad friction index.
    #[error("LCP with {size} rows is malformed: {detail}")]
    InvalidInput { size: usize, detail: String },
}

/// Solves with default options and a fresh workspace. For many solves, keep a
/// [`LcpWorkspace`] to avoid allocating each time.
pub fn solve(problem: &LcpProblem) -> Result<LcpSolution, LcpError> {
    LcpWorkspace::new().solve(problem, &LcpOptions::default())
}

/// Solves the standard LCP w = A x + b ≥ 0, x ≥ 0, xᵀw = 0 (A row-major n×n).
pub fn solve_standard(a: &[f64], b: &[f64]) -> Result<LcpSolution, LcpError> {
    solve(&LcpProblem::standard(a, b))
}

/// The error of a solve of `n` rows whose answer still missed the
/// conditions by `violation` after `passes` passes.
fn unmet(n: usize, has_friction: bool, passes: usize, violation: f64, tolerance: f64) -> LcpError {
    LcpError::Numerical {
        size: n,
        detail: if has_friction {
            format!(
                "friction bounds not consistent with the normal impulses after {passes} \
                 passes (max violation {violation:e} > tolerance {:e}); fall back to an \
                 iterative solver or raise LcpOptions::max_friction_passes",
                tolerance
            )
        } else {
            format!(
                "complementarity violated by {violation:e} (tolerance {:e}) after \
                 refining x; A may be too ill-conditioned",
                tolerance
            )
        },
    }
}

/// Checks that `p` is a problem [`LcpWorkspace::solve`] takes: sizes,
/// finite entries, bounds around zero, friction rows that name a normal
/// row. Returns its size n.
fn check_input(p: &LcpProblem) -> Result<usize, LcpError> {
    let n = p.b.len();
    let invalid = |detail: String| LcpError::InvalidInput { size: n, detail };
    if p.a.len() != n * n {
        return Err(invalid(format!(
            "A has {} entries, expected n² = {}",
            p.a.len(),
            n * n
        )));
    }
    for (name, len) in [
        ("lo", p.lo.len()),
        ("hi", p.hi.len()),
        ("findex", p.findex.len()),
    ] {
        if len != 0 && len != n {
            return Err(invalid(format!(
                "{name} has {len} entries, expected 0 or {n}"
            )));
        }
    }
    let non_finite = |what, index| LcpError::NonFinite {
        size: n,
        what,
        index,
    };
    if let Some(i) = p.a.iter().position(|v| !v.is_finite()) {
        return Err(non_finite("a", i));
    }
    if let Some(f) = p.factors {
        if f.body.len() != n || f.jacobian.len() != n || f.response.len() != n {
            return Err(invalid(format!("factors do not have {n} rows")));
        }
        if let Some(i) = f
            .body
            .iter()
            .position(|b| b.iter().any(|&k| k as usize >= f.bodies))
        {
            return Err(invalid(format!(
                "factors: row {i} names a body past {}",
                f.bodies
            )));
        }
        let finite = |rows: &[[[f64; 6]; 2]]| {
            rows.iter()
                .position(|r| r.iter().flatten().any(|v| !v.is_finite()))
        };
        if let Some(i) = finite(f.jacobian).or(finite(f.response)) {
            return Err(non_finite("factors", i));
        }
    }
    if let Some(i) = p.b.iter().position(|v| !v.is_finite()) {
        return Err(non_finite("b", i));
    }
    if let Some(i) = p.lo.iter().position(|v| v.is_nan() || *v == f64::INFINITY) {
        return Err(non_finite("lo", i));
    }
    if let Some(i) =
        p.hi.iter()
            .position(|v| v.is_nan() || *v == f64::NEG_INFINITY)
    {
        return Err(non_finite("hi", i));
    }
    if let Some(i) = p.lo.iter().position(|v| *v > 0.0) {
        return Err(invalid(format!("lo[{i}] = {} > 0", p.lo[i])));
    }
    if let Some(i) = p.hi.iter().position(|v| *v < 0.0) {
        return Err(invalid(format!("hi[{i}] = {} < 0", p.hi[i])));
    }
    for (i, f) in p.findex.iter().enumerate() {
        if let Some(j) = *f {
            if j >= n || j == i || p.findex[j].is_some() {
                return Err(invalid(format!(
                    "findex[{i}] = {j}: must name another, non-friction row"
                )));
            }
            let lo = p.lo.get(i).copied().unwrap_or(0.0);
            let hi = p.hi.get(i).copied().unwrap_or(f64::INFINITY);
            if !(lo.is_finite() && hi.is_finite()) {
                return Err(invalid(format!(
                    "friction row {i} needs finite coefficients (lo = −mu, hi = mu), got \
                     [{lo}, {hi}]"
                )));
            }
        }
    }
    Ok(n)
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

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RowState {
    Unprocessed,
    Clamped,
    AtLo,
    AtHi,
    /// Not clamped, inside its bounds with w = 0 (a dependent row).
    Free,
    /// lo = hi: x is fixed and w is unconstrained.
    Fixed,
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Side {
    Lo,
    Hi,
}

#[derive(Clone, Copy, Debug)]
enum Event {
    None,
    DriveZero,
    DriveBound(Side),
    Leave(usize, Side),
    Join(usize),
}

/// Row-major view of A.
#[derive(Clone, Copy)]
struct Mat<'a> {
    a: &'a [f64],
    n: usize,
}

impl Mat<'_> {
    #[inline]
    fn at(&self, i: usize, j: usize) -> f64 {
        self.a[i * self.n + j]
    }
    #[inline]
    fn row(&self, i: usize) -> &[f64] {
        &self.a[i * self.n..(i + 1) * self.n]
    }
}

/// Dot product with four accumulators (breaks the add chain so it vectorises).
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut s = [0.0; 4];
    let chunks = n / 4;
    for c in 0..chunks {
        let i = 4 * c;
        s[0] += a[i] * b[i];
        s[1] += a[i + 1] * b[i + 1];
        s[2] += a[i + 2] * b[i + 2];
        s[3] += a[i + 3] * b[i + 3];
    }
    let mut t = (s[0] + s[1]) + (s[2] + s[3]);
    for i in 4 * chunks..n {
        t += a[i] * b[i];
    }
    t
}

/// Factor of the clamped block A_CC, rows in the order of `LcpWorkspace::clamped`.
/// Symmetric: LDLᵀ, L strictly below the diagonal, D on it. Non-symmetric: LU with
/// partial pivoting (unit L below, U on and above), row r of it is clamped row
/// `perm[r]`. Column-major, column stride `cap`.
struct Factor {
    cap: usize,
    m: usize,
    ld: Vec<f64>,
    perm: Vec<usize>,
    /// The factor no longer matches C (refactor strategy or LU): rebuild before use.
    dirty: bool,
    scratch: Vec<f64>,
    regularized: usize,
    /// faer's scratch, sized when `cap` reaches the faer threshold.
    mem: Option<MemBuffer>,
}

impl Factor {
    fn new() -> Self {
        Self {
            cap: 0,
            m: 0,
            ld: Vec::new(),
            perm: Vec::new(),
            dirty: false,
            scratch: Vec::new(),
            regularized: 0,
            mem: None,
        }
    }

    fn reserve(&mut self, n: usize, faer_min: usize) {
        if n > self.cap {
            self.cap = n;
            self.ld = vec![0.0; n * n];
            self.perm = vec![0; n];
            self.scratch = vec![0.0; n];
            self.mem = None;
        }
        if self.mem.is_none() && self.cap >= faer_min {
            let req = ldlt::factor::cholesky_in_place_scratch::<f64>(
                self.cap,
                Par::Seq,
                Default::default(),
            );
            self.mem = Some(MemBuffer::new(req));
        }
    }

    fn clear(&mut self) {
        self.m = 0;
        self.dirty = false;
    }

    #[inline]
    fn d(&self, j: usize) -> f64 {
        self.ld[j * self.cap + j]
    }

    /// v ← L⁻¹ v (unit lower triangular), column by column so the inner loop
    /// is a contiguous axpy.
    fn forward(&self, v: &mut [f64]) {
        let (m, cap) = (self.m, self.cap);
        let v = &mut v[..m];
        for j in 0..m {
            let vj = v[j];
            if vj != 0.0 {
                let col = &self.ld[j * cap + j + 1..j * cap + m];
                for (vi, l) in v[j + 1..].iter_mut().zip(col) {
                    *vi -= l * vj;
                }
            }
        }
    }

    /// v ← L⁻ᵀ v, one contiguous dot product per column.
    fn backward(&self, v: &mut [f64]) {
        let (m, cap) = (self.m, self.cap);
        let v = &mut v[..m];
        for j in (0..m).rev() {
            let col = &self.ld[j * cap + j + 1..j * cap + m];
            let s = dot(col, &v[j + 1..]);
            v[j] -= s;
        }
    }

    /// v ← U⁻¹ v for the LU factor.
    fn backward_upper(&self, v: &mut [f64]) {
        let (m, cap) = (self.m, self.cap);
        for j in (0..m).rev() {
            v[j] /= self.ld[j * cap + j];
            let vj = v[j];
            let col = &self.ld[j * cap..j * cap + j];
            for (vi, u) in v[..j].iter_mut().zip(col) {
                *vi -= u * vj;
            }
        }
    }

    /// Raises a pivot to the floor, or reports that A is not PSD.
    fn checked_pivot(&mut self, pivot: f64, floor: f64) -> Result<f64, String> {
        if !pivot.is_finite() {
            return Err(format!("non-finite pivot {pivot} in the clamped factor"));
        }
        if pivot < -(NEGATIVE_PIVOT / PIVOT_FLOOR) * floor {
            return Err(format!(
                "negative pivot {pivot:e} in the clamped block: A is not positive semidefinite"
            ));
        }
        if pivot <= floor {
            self.regularized += 1;
            return Ok(floor);
        }
        Ok(pivot)
    }

    /// Appends a row to the LDLᵀ factor: L's new row `l` (= D⁻¹ L⁻¹ A_Ck) and pivot.
    fn append(&mut self, l: &[f64], pivot: f64) {
        let (m, cap) = (self.m, self.cap);
        for (j, &lj) in l[..m].iter().enumerate() {
            self.ld[j * cap + m] = lj;
        }
        self.ld[m * cap + m] = pivot;
        self.m += 1;
    }

    /// Removes position p from the LDLᵀ factor. Returns false if the update broke
    /// down (then the caller refactors).
    fn remove(&mut self, p: usize, floor: f64) -> bool {
        let (m, cap) = (self.m, self.cap);
        // l₃ = L[p+1.., p] and d_p, saved before the shift overwrites them.
        let t = m - p - 1;
        let alpha = self.d(p);
        self.scratch[..t].copy_from_slice(&self.ld[p * cap + p + 1..p * cap + m]);
        for j in 0..p {
            let c = j * cap;
            self.ld.copy_within(c + p + 1..c + m, c + p);
        }
        for j in p + 1..m {
            let src = j * cap + j;
            self.ld
                .copy_within(src..src + (m - j), (j - 1) * cap + (j - 1));
        }
        self.m -= 1;
        // Trailing block becomes L₃₃ D₃ L₃₃ᵀ + α l₃ l₃ᵀ: method C1 of Gill, Golub,
        // Murray & Saunders. For PSD A, α > 0 and every new pivot d̄_j ≥ d_j.
        let mut a = alpha;
        for j in 0..t {
            let jj = p + j;
            let pj = self.scratch[j];
            if pj == 0.0 {
                continue;
            }
            let dj = self.d(jj);
            let dbar = dj + a * pj * pj;
            if !(dbar.is_finite() && dbar > floor) {
                return false;
            }
            let beta = pj * a / dbar;
            a *= dj / dbar;
            self.ld[jj * cap + jj] = dbar;
            let col = &mut self.ld[jj * cap + jj + 1..jj * cap + p + t];
            for (wi, l) in self.scratch[j + 1..t].iter_mut().zip(col) {
                *wi -= pj * *l;
                *l += beta * *wi;
            }
        }
        true
    }

    /// Factors A_CC from scratch: LDLᵀ if `symmetric`, else LU.
    fn refactor(
        &mut self,
        mat: Mat,
        clamped: &[usize],
        symmetric: bool,
        faer_min: usize,
        floor: f64,
    ) -> Result<(), String> {
        let (m, cap) = (clamped.len(), self.cap);
        self.m = m;
        self.dirty = false;
        if symmetric {
            for (j, &cj) in clamped.iter().enumerate() {
                for (i, &ci) in clamped.iter().enumerate().skip(j) {
                    self.ld[j * cap + i] = mat.at(ci, cj);
                }
            }
            if let Some(mem) = self.mem.as_mut().filter(|_| m >= faer_min) {
                let view = MatMut::from_column_major_slice_with_stride_mut(&mut self.ld, m, m, cap);
                let ok = ldlt::factor::cholesky_in_place(
                    view,
                    Default::default(),
                    Par::Seq,
                    MemStack::new(mem),
                    Default::default(),
                )
                .is_ok();
                if ok && (0..m).all(|j| self.d(j).is_finite() && self.d(j) > floor) {
                    return Ok(());
                }
                // A pivot at or below the floor: redo by hand, which floors it.
                for (j, &cj) in clamped.iter().enumerate() {
                    for (i, &ci) in clamped.iter().enumerate().skip(j) {
                        self.ld[j * cap + i] = mat.at(ci, cj);
                    }
                }
            }
            // Right-looking LDLᵀ: after column j, the trailing block holds the
            // Schur complement of the leading j+1 rows, whose diagonal is Δa.
            for j in 0..m {
                let dj = self.checked_pivot(self.ld[j * cap + j], floor)?;
                self.ld[j * cap + j] = dj;
                for i in j + 1..m {
                    let t = self.ld[j * cap + i];
                    self.scratch[i] = t;
                    self.ld[j * cap + i] = t / dj;
                }
                for k in j + 1..m {
                    let tk = self.scratch[k];
                    if tk == 0.0 {
                        continue;
                    }
                    let (left, right) = self.ld.split_at_mut(k * cap);
                    let lcol = &left[j * cap + k..j * cap + m];
                    for (dst, l) in right[k..m].iter_mut().zip(lcol) {
                        *dst -= l * tk;
                    }
                }
            }
            return Ok(());
        }
        for (j, &cj) in clamped.iter().enumerate() {
            for (i, &ci) in clamped.iter().enumerate() {
                self.ld[j * cap + i] = mat.at(ci, cj);
            }
        }
        self.lu_in_place(m)
    }

    /// LU with partial pivoting of the m×m block already in `ld`.
    fn lu_in_place(&mut self, m: usize) -> Result<(), String> {
        let cap = self.cap;
        self.m = m;
        self.dirty = false;
        let amax = (0..m).fold(0.0f64, |a, j| {
            self.ld[j * cap..j * cap + m]
                .iter()
                .fold(a, |a, v| a.max(v.abs()))
        });
        for (r, p) in self.perm[..m].iter_mut().enumerate() {
            *p = r;
        }
        for j in 0..m {
            let col = &self.ld[j * cap + j..j * cap + m];
            let (off, piv) = col.iter().enumerate().fold((0, 0.0f64), |b, (i, v)| {
                if v.abs() > b.1.abs() { (i, *v) } else { b }
            });
            if piv.is_nan() || piv.abs() <= NOISE * amax {
                return Err(format!("singular non-symmetric block of {m} rows"));
            }
            let pr = j + off;
            if pr != j {
                for k in 0..m {
                    self.ld.swap(k * cap + j, k * cap + pr);
                }
                self.perm.swap(j, pr);
            }
            for i in j + 1..m {
                self.ld[j * cap + i] /= piv;
            }
            for k in j + 1..m {
                let f = self.ld[k * cap + j];
                if f == 0.0 {
                    continue;
                }
                let (left, right) = self.ld.split_at_mut(k * cap);
                let lcol = &left[j * cap + j + 1..j * cap + m];
                for (dst, l) in right[j + 1..m].iter_mut().zip(lcol) {
                    *dst -= l * f;
                }
            }
        }
        Ok(())
    }
}

/// Reusable buffers: one workspace solves any number of problems of any size
/// without allocating once it has seen the largest.
pub struct LcpWorkspace {
    n: usize,
    x: Vec<f64>,
    w: Vec<f64>,
    sigma: Vec<f64>,
    /// x of the last pass, kept while an exact friction step is tried.
    x_pass: Vec<f64>,
    /// Position of each row in C (usize::MAX if not clamped), for friction steps.
    cpos: Vec<usize>,
    prev_lo: Vec<f64>,
    prev_hi: Vec<f64>,
    lo: Vec<f64>,
    hi: Vec<f64>,
    state: Vec<RowState>,
    order: Vec<usize>,
    row_scale: Vec<f64>,
    /// C, in factor order.
    clamped: Vec<usize>,
    /// Δx over C (factor order) for the current direction.
    dxc: Vec<f64>,
    /// Δw of not-clamped rows for the current direction.
    dw: Vec<f64>,
    /// The bodies' velocity change of the current direction (with `RowFactors`).
    du: Vec<f64>,
    /// L⁻¹ A_Cd and D⁻¹ L⁻¹ A_Cd of the current direction (factor order).
    y: Vec<f64>,
    z: Vec<f64>,
    factor: Factor,
    symmetric: bool,
    floor: f64,
    pivots: usize,
    pivot_limit: usize,
}

impl Default for LcpWorkspace {
    fn default() -> Self {
        Self::new()
    }
}

/// Per-solve settings the drive needs.
#[derive(Clone, Copy)]
struct Ctx<'a> {
    mat: Mat<'a>,
    b: &'a [f64],
    opts: &'a LcpOptions,
    refactor: bool,
    factors: Option<RowFactors<'a>>,
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

    /// One Dantzig pass over all rows. `lazy_friction`: set each friction row's
    /// bounds from the current normal impulse when it is taken (ODE); otherwise
    /// they are frozen from the previous pass.
    fn run_pass(&mut self, p: &LcpProblem, ctx: Ctx, lazy_friction: bool) -> Result<(), LcpError> {
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
    fn resume_pass(&mut self, p: &LcpProblem, ctx: Ctx) -> Result<(), LcpError> {
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
    fn start_pass(&mut self, p: &LcpProblem, ctx: Ctx, start: &[f64]) -> Result<(), LcpError> {
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

    /// w_d = A_d x + b_d and σ_d = |b_d| + Σ|A_dj x_j|.
    fn fresh_w(&self, ctx: Ctx, d: usize) -> (f64, f64) {
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
    fn drive(&mut self, ctx: Ctx, d: usize) -> Result<(), LcpError> {
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
    fn direction(&mut self, ctx: Ctx, d: usize, dir: f64) -> Result<f64, LcpError> {
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

    fn ensure_factor(&mut self, ctx: Ctx) -> Result<(), LcpError> {
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
    fn clamp_driven(&mut self, ctx: Ctx, d: usize, schur: f64) -> Result<(), LcpError> {
        self.state[d] = RowState::Clamped;
        if ctx.refactor {
            self.clamped.push(d);
            self.factor.dirty = true;
            return Ok(());
        }
        self.append_clamped(schur, d)
    }

    /// A not-clamped row k joins C: append its factor row, pivot Δa_k.
    fn clamp_row(&mut self, ctx: Ctx, k: usize) -> Result<(), LcpError> {
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
    fn unclamp(&mut self, ctx: Ctx, r: usize) -> Result<(), LcpError> {
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
    fn friction_newton(&mut self, p: &LcpProblem, ctx: Ctx) -> bool {
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
    fn polish(&mut self, p: &LcpProblem, ctx: Ctx) -> Result<(), LcpError> {
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
    fn finish(&mut self, p: &LcpProblem, ctx: Ctx) -> Result<f64, LcpError> {
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

#[cfg(test)]
mod tests {
    use super::*;

    fn random_spd(n: usize, seed: u64) -> Vec<f64> {
        let mut state = seed;
        let mut next = || {
            state = state
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
        };
        let g: Vec<f64> = (0..n * n).map(|_| next()).collect();
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                a[i * n + j] = (0..n).map(|k| g[k * n + i] * g[k * n + j]).sum::<f64>()
                    + if i == j { 0.1 } else { 0.0 };
            }
        }
        a
    }

    /// L D Lᵀ of the factor, compared with A_CC.
    fn reconstruct_error(f: &Factor, a: &[f64], n: usize, c: &[usize]) -> f64 {
        let m = f.m;
        let l = |i: usize, j: usize| {
            if i == j {
                1.0
            } else if i > j {
                f.ld[j * f.cap + i]
            } else {
                0.0
            }
        };
        let mut err = 0.0f64;
        for i in 0..m {
            for j in 0..m {
                let v: f64 = (0..m).map(|k| l(i, k) * f.d(k) * l(j, k)).sum();
                err = err.max((v - a[c[i] * n + c[j]]).abs());
            }
        }
        err
    }

    #[test]
    fn ldlt_append_and_remove_match_a_fresh_factor() {
        for faer_min in [usize::MAX, 1] {
            let n = 12;
            let a = random_spd(n, 7);
            let mat = Mat { a: &a, n };
            let mut f = Factor::new();
            f.reserve(n, faer_min);
            let mut c: Vec<usize> = Vec::new();
            for k in [3, 0, 7, 11, 5, 2, 9, 1] {
                let m = c.len();
                let mut y: Vec<f64> = c.iter().map(|&j| a[k * n + j]).collect();
                y.resize(n, 0.0);
                f.forward(&mut y);
                let z: Vec<f64> = (0..m).map(|r| y[r] / f.d(r)).collect();
                let pivot = a[k * n + k] - dot(&y[..m], &z);
                f.append(&z, pivot);
                c.push(k);
            }
            assert!(reconstruct_error(&f, &a, n, &c) < 1e-12);
            for p in [2, 0, 4] {
                assert!(f.remove(p, 1e-300));
                c.remove(p);
                assert!(
                    reconstruct_error(&f, &a, n, &c) < 1e-12,
                    "faer_min {faer_min}"
                );
            }
            let mut g = Factor::new();
            g.reserve(n, faer_min);
            g.refactor(mat, &c, true, faer_min, 1e-300).unwrap();
            assert!(reconstruct_error(&g, &a, n, &c) < 1e-12);
        }
    }

    #[test]
    fn lu_refactor_solves_a_non_symmetric_block() {
        let n = 5;
        let mut a = random_spd(n, 3);
        a[1] += 0.7;
        a[n + 3] -= 0.4;
        let c = [4, 1, 3, 0];
        let mut f = Factor::new();
        f.reserve(n, usize::MAX);
        f.refactor(Mat { a: &a, n }, &c, false, usize::MAX, 0.0)
            .unwrap();
        let rhs = [1.0, -2.0, 0.5, 3.0];
        let mut v: Vec<f64> = (0..4).map(|r| rhs[f.perm[r]]).collect();
        f.forward(&mut v);
        f.backward_upper(&mut v);
        for (i, &ci) in c.iter().enumerate() {
            let s: f64 = c
                .iter()
                .enumerate()
                .map(|(j, &cj)| a[ci * n + cj] * v[j])
                .sum();
            assert!((s - rhs[i]).abs() < 1e-12);
        }
    }
}
