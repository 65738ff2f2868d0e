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

use crate::contact::system::{IterativeState, IterativeSystem, Row, RowSide, Step};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::sparse::linalg::SupernodalThreshold;
use faer::sparse::linalg::cholesky::{
    CholeskySymbolicParams, LltRef, SymbolicCholesky, SymbolicCholeskyRaw, SymmetricOrdering,
    factorize_symbolic_cholesky, simplicial, supernodal,
};
use faer::sparse::{SparseColMatRef, SymbolicSparseColMatRef};
use faer::{Conj, MatMut, Par, Side};
use std::cell::RefCell;
use std::rc::Rc;

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

/// The subspace steps a solve has left: at most `steps`, and none after
/// `rejections` rejected in a row.
pub(crate) struct Tries {
    left: usize,
    rejected_in_a_row: usize,
    rejections_allowed: usize,
}

impl Tries {
    pub(crate) fn new(steps: usize, rejections: usize) -> Self {
        Tries {
            left: steps,
            rejected_in_a_row: 0,
            rejections_allowed: rejections,
        }
    }

    pub(crate) fn may_try(&self) -> bool {
        self.left > 0 && self.rejected_in_a_row < self.rejections_allowed
    }

    /// Counts a step taken, and what became of it.
    pub(crate) fn record(&mut self, step: &Step) {
        self.left -= 1;
        match step {
            Step::Kept => self.rejected_in_a_row = 0,
            Step::Rejected => self.rejected_in_a_row += 1,
            Step::NotTaken => {}
        }
    }
}

/// Solves the rows strictly inside their bounds together (see
/// `subspace`), then projects onto the bounds in row order (a friction
/// row's bound follows its normal row's new impulse). Kept only if it
/// brings p closer to meeting the conditions: the projection can spoil
/// a step (a row the sweeps took for pushing is clamped to zero, and the
/// rest no longer balance). Not "lowers ½pᵀAp + bᵀp": with friction
/// bounds that follow the normal impulses the answer is no minimum of
/// it, and near the answer good steps raise it (judged that way, a
/// stack of 100 swayed 5 mm).
pub(super) fn step(
    system: &IterativeSystem,
    by_body: &[Vec<usize>],
    s: &mut IterativeState,
) -> Step {
    let m = system.rows.len();
    let free: Vec<usize> = (0..m).filter(|&i| system.is_free(i, s)).collect();
    let residual: Vec<f64> = free.iter().map(|&i| system.velocity(i, s)).collect();
    let Some(step) = free_block_step(
        system.rows,
        system.diag,
        by_body,
        &free,
        &residual,
        system.compliance,
    ) else {
        return Step::NotTaken;
    };
    let before = s.clone();
    let residual_before = system.natural_residual(s);
    let mut target = s.p.clone();
    for (&i, d) in free.iter().zip(&step) {
        target[i] += d;
    }
    for (i, (row, t)) in system.rows.iter().zip(target).enumerate() {
        let (l, h) = system.bounds(i, &s.p);
        let delta = t.clamp(l, h) - s.p[i];
        if delta != 0.0 && delta.is_finite() {
            s.p[i] += delta;
            row.change_velocities(delta, &mut s.dv, &mut s.dw);
        }
    }
    if system.natural_residual(s) < residual_before {
        Step::Kept
    } else {
        *s = before;
        Step::Rejected
    }
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
    let (start, free_of, sides) = free_rows_by_body(rows, by_body, free);
    // Lower triangle, one entry per coupled pair (coupling sums over both
    // shared bodies, so a pair met through two bodies is entered once),
    // gathered row by row (columns ascending). An entry is summed body by
    // body, row i's A side first, as `Row::coupling` sums it (a body that
    // does not move adds nothing there): the same values to the bit, from
    // each body's list of rows instead of a test of every pair's bodies.
    let mut row_ptr = Vec::with_capacity(n + 1);
    row_ptr.push(0usize);
    // Row k's entries are at most its bodies' free rows, so all rows' at
    // most the sum of each body's count squared: reserved at once (pushed
    // one at a time, their growth was 5 % of the pyramid's instructions).
    let most: usize = start.windows(2).map(|w| (w[1] - w[0]).pow(2)).sum();
    let (mut cols, mut vals) = (Vec::with_capacity(most), Vec::with_capacity(most));
    // A moving body's free rows and their sides on it; none for a body
    // the row does not move.
    let on = |body: usize, moves: bool| -> (&[usize], &[RowSide]) {
        if moves {
            let list = start[body]..start[body + 1];
            (&free_of[list.clone()], &sides[list])
        } else {
            (&[], &[])
        }
    };
    for (k, &i) in free.iter().enumerate() {
        let row = &rows[i];
        let (moves_a, moves_b) = row.moves();
        let ((rows_a, sides_a), (rows_b, sides_b)) = (on(row.a, moves_a), on(row.b, moves_b));
        let (own_a, own_b) = (row.side(row.a), row.side(row.b));
        // The two bodies' rows up to k merged (each list ascending), each
        // entry summed from the list or lists it is in.
        let (mut x, mut y) = (0, 0);
        loop {
            let pa = rows_a.get(x).copied().unwrap_or(usize::MAX);
            let pb = rows_b.get(y).copied().unwrap_or(usize::MAX);
            let l = pa.min(pb);
            if l > k {
                break;
            }
            let mut val = 0.0;
            if pa == l {
                val += own_a.coupling(&sides_a[x]);
                x += 1;
            }
            if pb == l {
                val += own_b.coupling(&sides_b[y]);
                y += 1;
            }
            if l == k {
                val += compliance * diag[i];
            }
            cols.push(l);
            vals.push(val);
        }
        row_ptr.push(cols.len());
    }
    // Row k's entries at and left of the diagonal are column k's at and
    // above it: the rows as gathered are the upper triangle by columns.
    let block = UpperBlock {
        n,
        col_ptr: row_ptr,
        row_idx: cols,
        values: vals,
    };
    let mut step: Vec<f64> = residual.iter().map(|r| -r).collect();
    block.solve_in_place(&mut step)?;
    step.iter().all(|x| x.is_finite()).then_some(step)
}

/// Each body's free rows by their position in the block, ascending (its
/// rows are in row order, and so in block order), laid out flat: body b's
/// are `free_of[start[b]..start[b + 1]]`; and their sides on it, laid out
/// as `free_of`. Returns `(start, free_of, sides)`.
fn free_rows_by_body(
    rows: &[Row],
    by_body: &[Vec<usize>],
    free: &[usize],
) -> (Vec<usize>, Vec<usize>, Vec<RowSide>) {
    let n = free.len();
    let mut position = vec![usize::MAX; rows.len()];
    for (k, &i) in free.iter().enumerate() {
        position[i] = k;
    }
    let mut start = Vec::with_capacity(by_body.len() + 1);
    let mut free_of = Vec::with_capacity(2 * n);
    start.push(0);
    for list in by_body {
        free_of.extend(
            list.iter()
                .map(|&i| position[i])
                .filter(|&k| k != usize::MAX),
        );
        start.push(free_of.len());
    }
    let mut sides = Vec::with_capacity(free_of.len());
    for (body, w) in start.windows(2).enumerate() {
        sides.extend(
            free_of[w[0]..w[1]]
                .iter()
                .map(|&k| rows[free[k]].side(body)),
        );
    }
    (start, free_of, sides)
}

/// The free block's upper triangle in compressed columns (rows ascending
/// in each column).
struct UpperBlock {
    n: usize,
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    values: Vec<f64>,
}

/// How many symbolic factorisations each thread keeps.
const SYMBOLIC_KEPT: usize = 4;

/// faer factors a block by dense supernodes where its flops per factor
/// entry exceed 40 times this (its default, 1.0, keeps every block here
/// simplicial). At 0.5 the pyramid's blocks (each cube's rows coupled with
/// the two cubes below it and the two above) go supernodal, which is
/// faster, while the stacks' banded blocks stay simplicial.
const SUPERNODAL_THRESHOLD: SupernodalThreshold = SupernodalThreshold(0.5);

/// A kept symbolic factorisation, the pattern it was made for (column
/// pointers, rows) and that pattern in its fill-reducing order.
struct KeptSymbolic {
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    symbolic: Rc<SymbolicCholesky<usize>>,
    permuted: Rc<Permuted>,
}

/// The block permuted into the symbolic factorisation's order, laid out
/// as faer's numeric factorisation takes it (the triangle and the order
/// of entries that `permute_self_adjoint_to_unsorted` gives): its pattern,
/// and where each entry of the block as gathered lands in it. Moving the
/// values there is all that the permutation then costs a factorisation,
/// where faer would redo the layout each time (5 % of the pyramid's run),
/// and the numeric factorisation reads exactly what it read before.
struct Permuted {
    col_ptr: Vec<usize>,
    row_idx: Vec<usize>,
    /// For each entry of the permuted layout, the entry of the block as
    /// gathered that lands there.
    from: Vec<usize>,
}

impl Permuted {
    /// The layout of `block` permuted for `symbolic`, found by permuting
    /// each entry's own index as its value. None without a permutation.
    fn new(block: &UpperBlock, symbolic: &SymbolicCholesky<usize>) -> Option<Permuted> {
        let perm = symbolic.perm()?;
        let n = block.n;
        let nnz = block.values.len();
        let out_side = match symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(_) => Side::Upper,
            SymbolicCholeskyRaw::Supernodal(_) => Side::Lower,
        };
        let index: Vec<f64> = (0..nnz).map(|e| e as f64).collect();
        let mut moved = vec![0.0; nnz];
        let mut col_ptr = vec![0usize; n + 1];
        let mut row_idx = vec![0usize; nnz];
        let pattern =
            SymbolicSparseColMatRef::new_checked(n, n, &block.col_ptr, None, &block.row_idx);
        let mut work = MemBuffer::try_new(
            faer::sparse::utils::permute_self_adjoint_scratch::<usize>(n),
        )
        .ok()?;
        faer::sparse::utils::permute_self_adjoint_to_unsorted(
            &mut moved,
            &mut col_ptr,
            &mut row_idx,
            SparseColMatRef::new(pattern, &index),
            perm,
            Side::Upper,
            out_side,
            MemStack::new(&mut work),
        );
        let mut landed = vec![false; nnz];
        let mut from = Vec::with_capacity(nnz);
        for &e in &moved {
            let e = e as usize;
            if e >= nnz || landed[e] {
                return None;
            }
            landed[e] = true;
            from.push(e);
        }
        Some(Permuted {
            col_ptr,
            row_idx,
            from,
        })
    }
}

thread_local! {
    /// The symbolic factorisations (fill-reducing order, elimination tree)
    /// of the latest free blocks, by their pattern. A resting stack's or
    /// pile's free rows are the same from one solve to the next, and the
    /// ordering and symbolic analysis cost more than the numeric factor
    /// (the stack of 50: 15 % of the run against 11 %). The symbolic
    /// factorisation is a function of the pattern alone, so a kept one
    /// gives the same factor to the last bit.
    static SYMBOLIC: RefCell<Vec<KeptSymbolic>> =
        const { RefCell::new(Vec::new()) };
}

/// The buffers of one numeric factorisation, kept by each thread: the
/// block's values in the factorisation's order, the factor's values, and
/// faer's scratch memory with the size and alignment it was made for.
/// Allocated and zeroed for every step they were 7 % of the pyramid's
/// instructions; what they hold is overwritten before it is read, so the
/// answers do not depend on what the thread solved before.
#[derive(Default)]
struct Scratch {
    values: Vec<f64>,
    factor: Vec<f64>,
    work: Option<(usize, usize, MemBuffer)>,
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

impl UpperBlock {
    /// Solves the block's system in place on `x` (the right-hand side in,
    /// the answer out) by its Cholesky factor, with a kept symbolic
    /// factorisation where one has this pattern. None where it fails.
    fn solve_in_place(&self, x: &mut [f64]) -> Option<()> {
        let kept = SYMBOLIC.with(|kept| {
            kept.borrow()
                .iter()
                .find(|k| k.col_ptr == self.col_ptr && k.row_idx == self.row_idx)
                .map(|k| (k.symbolic.clone(), k.permuted.clone()))
        });
        let (symbolic, permuted) = match kept {
            Some(s) => s,
            None => {
                let pattern = SymbolicSparseColMatRef::new_checked(
                    self.n,
                    self.n,
                    &self.col_ptr,
                    None,
                    &self.row_idx,
                );
                let params = CholeskySymbolicParams {
                    supernodal_flop_ratio_threshold: SUPERNODAL_THRESHOLD,
                    ..Default::default()
                };
                let s = Rc::new(
                    factorize_symbolic_cholesky(
                        pattern,
                        Side::Upper,
                        SymmetricOrdering::Amd,
                        params,
                    )
                    .ok()?,
                );
                let p = Rc::new(Permuted::new(self, &s)?);
                SYMBOLIC.with(|kept| {
                    let mut kept = kept.borrow_mut();
                    if kept.len() == SYMBOLIC_KEPT {
                        kept.remove(0);
                    }
                    kept.push(KeptSymbolic {
                        col_ptr: self.col_ptr.clone(),
                        row_idx: self.row_idx.clone(),
                        symbolic: s.clone(),
                        permuted: p.clone(),
                    });
                });
                (s, p)
            }
        };
        SCRATCH.with(|scratch| {
            let mut scratch = scratch.borrow_mut();
            self.factor_and_solve(&symbolic, &permuted, &mut scratch, x)
        })
    }

    /// The numeric factorisation and the solve, in `scratch`'s buffers.
    fn factor_and_solve(
        &self,
        symbolic: &SymbolicCholesky<usize>,
        permuted: &Permuted,
        scratch: &mut Scratch,
        x: &mut [f64],
    ) -> Option<()> {
        let Scratch {
            values,
            factor,
            work,
        } = scratch;
        values.clear();
        values.extend(permuted.from.iter().map(|&e| self.values[e]));
        let matrix = SparseColMatRef::new(
            SymbolicSparseColMatRef::new_unsorted_checked(
                self.n,
                self.n,
                &permuted.col_ptr,
                None,
                &permuted.row_idx,
            ),
            values,
        );
        // Every entry of the factor is written by the factorisation
        // (supernodal: zeroed first; simplicial: each row of L once), so
        // the buffer is only sized, never cleared.
        factor.resize(symbolic.len_val(), 0.0);
        let factor = factor.as_mut_slice();
        let req = symbolic
            .factorize_numeric_llt_scratch::<f64>(Par::Seq, Default::default())
            .or(symbolic.solve_in_place_scratch::<f64>(1, Par::Seq));
        let fits = work.as_ref().is_some_and(|(size, align, _)| {
            *size >= req.size_bytes() && *align >= req.align_bytes()
        });
        if !fits {
            *work = Some((
                req.size_bytes(),
                req.align_bytes(),
                MemBuffer::try_new(req).ok()?,
            ));
        }
        let (_, _, work) = work.as_mut()?;
        let stack = MemStack::new(work);
        match symbolic.raw() {
            SymbolicCholeskyRaw::Simplicial(s) => simplicial::factorize_simplicial_numeric_llt(
                factor,
                matrix,
                Default::default(),
                s,
                stack,
            )
            .ok()?,
            SymbolicCholeskyRaw::Supernodal(s) => supernodal::factorize_supernodal_numeric_llt(
                factor,
                matrix,
                Default::default(),
                s,
                Par::Seq,
                stack,
                Default::default(),
            )
            .ok()?,
        };
        let llt = LltRef::new(symbolic, factor);
        let rhs = MatMut::from_column_major_slice_mut(x, self.n, 1);
        llt.solve_in_place_with_conj(Conj::No, rhs, Par::Seq, MemStack::new(work));
        Some(())
    }
}
