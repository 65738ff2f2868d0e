//! The tuning of a solve.

use serde::{Deserialize, Serialize};

/// How the factor of the clamped block A_CC follows the changes of C.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Factorization {
    /// Update the LDLᵀ factor on every change (O(|C|²) a pivot). The default.
    Incremental,
    /// Refactor A_CC from scratch after every change (O(|C|³) a pivot); kept to
    /// measure what the updates save, and always used for non-symmetric A.
    Refactor,
}

/// Tuning of [`LcpWorkspace::solve`](super::LcpWorkspace::solve); the defaults suit contact problems.
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
    /// Pivots (steps) allowed per pass before [`LcpError::IterationLimit`](super::LcpError::IterationLimit);
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
