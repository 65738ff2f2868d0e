//! What a solve gives: a verified solution, or why it failed.

use serde::{Deserialize, Serialize};

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

/// The error of a solve of `n` rows whose answer still missed the
/// conditions by `violation` after `passes` passes.
pub(super) fn unmet(
    n: usize,
    has_friction: bool,
    passes: usize,
    violation: f64,
    tolerance: f64,
) -> LcpError {
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
