//! The problem a solve takes (A, b, the bounds, the friction rows, and
//! optionally A's factors and a guess), and its input check.

use super::solution::LcpError;

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

    /// The same problem started from a guess of x (see [`LcpProblem::start`]).
    pub fn with_start(self, start: &'a [f64]) -> Self {
        LcpProblem {
            start: Some(start),
            ..self
        }
    }

    /// The same problem with A's factors (see [`RowFactors`]).
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

/// Checks that `p` is a problem [`LcpWorkspace::solve`](super::LcpWorkspace::solve) takes: sizes,
/// finite entries, bounds around zero, friction rows that name a normal
/// row. Returns its size n.
pub(super) fn check_input(p: &LcpProblem) -> Result<usize, LcpError> {
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
