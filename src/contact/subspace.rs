//! The subspace step of the iterative contact solve (projected Gauss–Seidel
//! with subspace minimisation, Silcowski, Erleben et al.): once the sweeps
//! have found which rows push (strictly inside their bounds: the *free*
//! rows) the step solves those rows' equations w_F = 0 all at once with a
//! sparse Cholesky factorisation, the others held where they are.
//!
//! Why: the sweeps pass a load one contact per sweep. The bottom of a stack
//! of 100 hears of its top's weight only after hundreds of sweeps, and a
//! tall stack solved by sweeps alone sways by centimetres. The free rows of
//! a resting stack are the same every step, and one solve on them carries
//! the whole load down to rounding. A is J M⁻¹ Jᵀ, so two rows couple only
//! through a body that moves; a stack's block is banded, a pile's sparse.

use super::solver::Row;
use faer::linalg::solvers::Solve;
use faer::sparse::{SparseColMat, Triplet};
use faer::{Mat, Side};

/// Each body's rows, counting only bodies an impulse moves (a fixed body's
/// rows do not couple through it).
pub(super) fn rows_by_body(rows: &[Row], bodies: usize) -> Vec<Vec<usize>> {
    let mut by_body = vec![Vec::new(); bodies];
    for (i, row) in rows.iter().enumerate() {
        let (moves_a, moves_b) = row.moves();
        if moves_a {
            by_body[row.a].push(i);
        }
        if moves_b && row.b != row.a {
            by_body[row.b].push(i);
        }
    }
    by_body
}

/// The change δ of the free rows' impulses that zeroes their velocities
/// w_F: (A_FF + c·diag) δ = −w_F, with c the solve's compliance (which
/// makes the block positive definite where redundant rows make A_FF
/// singular). `free` lists the free rows in row order, `residual` their
/// current w. None where the factorisation fails.
pub(super) fn free_block_step(
    rows: &[Row],
    diag: &[f64],
    by_body: &[Vec<usize>],
    free: &[usize],
    residual: &[f64],
    compliance: f64,
) -> Option<Vec<f64>> {
    let n = free.len();
    if n == 0 {
        return None;
    }
    // Position of each row in the free block.
    let mut position = vec![usize::MAX; rows.len()];
    for (k, &i) in free.iter().enumerate() {
        position[i] = k;
    }
    // Lower triangle, one entry per coupled pair (coupling sums over both
    // shared bodies, so a pair met through two bodies is entered once).
    let mut entries = Vec::new();
    let mut neighbours = Vec::new();
    for (k, &i) in free.iter().enumerate() {
        neighbours.clear();
        let (moves_a, moves_b) = rows[i].moves();
        for (body, moves) in [(rows[i].a, moves_a), (rows[i].b, moves_b)] {
            if moves {
                neighbours.extend(
                    by_body[body]
                        .iter()
                        .map(|&j| position[j])
                        .filter(|&l| l <= k),
                );
            }
        }
        neighbours.sort_unstable();
        neighbours.dedup();
        for &l in &neighbours {
            let mut val = rows[i].coupling(&rows[free[l]]);
            if l == k {
                val += compliance * diag[i];
            }
            entries.push(Triplet::new(k, l, val));
        }
    }
    let block = SparseColMat::<usize, f64>::try_new_from_triplets(n, n, &entries).ok()?;
    let factor = block.sp_cholesky(Side::Lower).ok()?;
    let mut step = Mat::<f64>::from_fn(n, 1, |k, _| -residual[k]);
    factor.solve_in_place(&mut step);
    let step: Vec<f64> = (0..n).map(|k| step[(k, 0)]).collect();
    step.iter().all(|x| x.is_finite()).then_some(step)
}
