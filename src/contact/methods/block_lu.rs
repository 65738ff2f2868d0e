//! Sparse LU of a system whose unknowns come six to a body and whose
//! off-diagonal 6×6 blocks couple only bodies that share a contact: the
//! interior point's Newton matrix (`interior`), I + M⁻¹ Jᵀ G⁻¹ J.
//!
//! A pile's island is a sparse graph (a body touches a handful of others),
//! so eliminating body by body in minimum-degree order fills few blocks:
//! a 40-body island costs a few hundred 6×6 products where a dense LU of
//! its 240 unknowns costs 9·10⁶ flops. The pivots are the 6×6 diagonal
//! blocks, inverted with partial pivoting inside the block; across blocks
//! there is none, so a solve is trusted only where its residual is at
//! rounding level (`solve` checks it, after GMRES on the factors where the
//! substitution alone leaves more); the caller falls back to a dense LU
//! otherwise.

/// A 6×6 block, row-major.
type Block = [f64; 36];

/// The factorisation's pattern: the elimination order and each block row's
/// columns after fill.
pub(super) struct BlockPattern {
    /// Elimination position → body slot.
    order: Vec<usize>,
    /// Body slot → elimination position.
    position: Vec<usize>,
    /// Per position, the positions of its row's blocks, ascending (the
    /// pattern is structurally symmetric: a contact adds all four blocks
    /// of its two bodies, and fill keeps that).
    columns: Vec<Vec<usize>>,
    /// Index of row i's first block in the block list.
    start: Vec<usize>,
}

impl BlockPattern {
    /// The pattern of `bodies` body slots coupled by `edges` (slot pairs,
    /// either order, repeats allowed), eliminated in minimum-degree order
    /// (ties to the lower slot, so the order is a function of the edges).
    pub(super) fn new(bodies: usize, edges: impl IntoIterator<Item = (usize, usize)>) -> Self {
        let mut adjacent: Vec<Vec<usize>> = vec![Vec::new(); bodies];
        for (a, b) in edges {
            if a != b {
                adjacent[a].push(b);
                adjacent[b].push(a);
            }
        }
        for list in &mut adjacent {
            list.sort_unstable();
            list.dedup();
        }
        // Greedy minimum degree on the graph that elimination leaves:
        // eliminating a body joins its remaining neighbours into a clique
        // (the blocks its elimination fills).
        let mut filled = adjacent.clone();
        let mut live = adjacent;
        let mut done = vec![false; bodies];
        let mut order = Vec::with_capacity(bodies);
        for _ in 0..bodies {
            let k = (0..bodies)
                .filter(|&i| !done[i])
                .min_by_key(|&i| (live[i].len(), i))
                .expect("a body is left");
            done[k] = true;
            order.push(k);
            let neighbours = std::mem::take(&mut live[k]);
            for &i in &neighbours {
                live[i].retain(|&j| j != k);
                for &j in &neighbours {
                    if j != i {
                        if let Err(at) = live[i].binary_search(&j) {
                            live[i].insert(at, j);
                        }
                        if let Err(at) = filled[i].binary_search(&j) {
                            filled[i].insert(at, j);
                        }
                    }
                }
            }
        }
        let mut position = vec![0; bodies];
        for (p, &slot) in order.iter().enumerate() {
            position[slot] = p;
        }
        let mut columns = Vec::with_capacity(bodies);
        let mut start = Vec::with_capacity(bodies + 1);
        let mut count = 0;
        for &slot in &order {
            let mut row: Vec<usize> = filled[slot].iter().map(|&j| position[j]).collect();
            row.push(position[slot]);
            row.sort_unstable();
            start.push(count);
            count += row.len();
            columns.push(row);
        }
        start.push(count);
        BlockPattern {
            order,
            position,
            columns,
            start,
        }
    }

    /// How many blocks the pattern holds (fill included).
    pub(super) fn blocks(&self) -> usize {
        *self.start.last().unwrap_or(&0)
    }

    /// Index of the block coupling body slots `a` (row) and `b` (column),
    /// `None` where the pattern has none.
    pub(super) fn index(&self, a: usize, b: usize) -> Option<usize> {
        self.at(self.position[a], self.position[b])
    }

    /// Index of the block at elimination positions (`i`, `j`).
    fn at(&self, i: usize, j: usize) -> Option<usize> {
        self.columns[i]
            .binary_search(&j)
            .ok()
            .map(|t| self.start[i] + t)
    }
}

/// A block matrix on a pattern: the identity to begin with, contacts'
/// blocks added through `block_mut`.
pub(super) struct BlockMatrix<'p> {
    pattern: &'p BlockPattern,
    blocks: Vec<Block>,
}

impl<'p> BlockMatrix<'p> {
    pub(super) fn identity(pattern: &'p BlockPattern) -> Self {
        let mut blocks = vec![[0.0; 36]; pattern.blocks()];
        for slot in 0..pattern.order.len() {
            let d = pattern.index(slot, slot).expect("diagonal block");
            for c in 0..6 {
                blocks[d][7 * c] = 1.0;
            }
        }
        BlockMatrix { pattern, blocks }
    }

    /// How many bodies (six unknowns each) the matrix couples.
    pub(super) fn bodies(&self) -> usize {
        self.pattern.order.len()
    }

    /// The block of body slots (`a` row, `b` column), to add a contact's
    /// part to.
    pub(super) fn block_mut(&mut self, a: usize, b: usize) -> &mut Block {
        let k = self
            .pattern
            .index(a, b)
            .expect("the pattern holds every contact's blocks");
        &mut self.blocks[k]
    }

    /// The dense matrix (slot order), for the fallback.
    pub(super) fn to_dense(&self) -> faer::Mat<f64> {
        let p = self.pattern;
        let n = 6 * p.order.len();
        let mut m = faer::Mat::<f64>::zeros(n, n);
        for (i, cols) in p.columns.iter().enumerate() {
            for (t, &j) in cols.iter().enumerate() {
                let b = &self.blocks[p.start[i] + t];
                let (oi, oj) = (6 * p.order[i], 6 * p.order[j]);
                for x in 0..6 {
                    for y in 0..6 {
                        m[(oi + x, oj + y)] = b[6 * x + y];
                    }
                }
            }
        }
        m
    }

    /// The LU factors: `None` where a pivot block is singular to working
    /// precision (then the caller factors densely, with pivoting).
    pub(super) fn factor(&self) -> Option<BlockLu<'_>> {
        let p = self.pattern;
        let nb = p.order.len();
        let mut lu = self.blocks.clone();
        let mut pivot_inverse = Vec::with_capacity(nb);
        for k in 0..nb {
            let d = p.at(k, k).expect("diagonal block");
            let inverse = invert(&lu[d])?;
            pivot_inverse.push(inverse);
            // Row k's columns are ascending: those after k, and by the
            // pattern's symmetry the rows below k in column k.
            let below = &p.columns[k][p.columns[k].partition_point(|&i| i <= k)..];
            for &i in below {
                let ik = p.at(i, k).expect("symmetric pattern");
                let l = multiply(&lu[ik], &inverse);
                lu[ik] = l;
                for &j in below {
                    let kj = p.at(k, j).expect("symmetric pattern");
                    let ij = p.at(i, j).expect("fill holds the clique");
                    let u = lu[kj];
                    subtract_product(&mut lu[ij], &l, &u);
                }
            }
        }
        Some(BlockLu {
            pattern: p,
            original: &self.blocks,
            lu,
            pivot_inverse,
        })
    }
}

/// The factors of a `BlockMatrix`: L (unit block lower, below the
/// diagonal) and U (the pivot blocks, by their inverses, and the blocks
/// right of them) in one list.
pub(super) struct BlockLu<'m> {
    pattern: &'m BlockPattern,
    original: &'m [Block],
    lu: Vec<Block>,
    pivot_inverse: Vec<Block>,
}

impl BlockLu<'_> {
    /// x with K x = rhs (slot order, six entries a slot), or `None` where
    /// the residual stays beyond rounding (pivot growth: the caller solves
    /// densely). Where the substitution alone leaves more, GMRES with the
    /// factors as its preconditioner (`KRYLOV`) takes it down: near an
    /// interior point's answer G spans many orders of magnitude, and
    /// eliminating without pivoting across blocks grows the error.
    pub(super) fn solve(&self, rhs: &[f64]) -> Option<Vec<f64>> {
        let p = self.pattern;
        let nb = p.order.len();
        let b: Vec<[f64; 6]> = p
            .order
            .iter()
            .map(|&slot| std::array::from_fn(|a| rhs[6 * slot + a]))
            .collect();
        let mut x = self.substitute(b.clone());
        for cycle in 0..=KRYLOV_CYCLES {
            let (r, worst, scale) = self.residual(&b, &x);
            if worst <= RESIDUAL * scale {
                break;
            }
            if cycle == KRYLOV_CYCLES || !worst.is_finite() {
                return None;
            }
            self.gmres(r, &mut x);
        }
        let mut out = vec![0.0; 6 * nb];
        for (k, &slot) in p.order.iter().enumerate() {
            out[6 * slot..6 * slot + 6].copy_from_slice(&x[k]);
        }
        Some(out)
    }

    /// One cycle of right-preconditioned GMRES (`KRYLOV` vectors) on
    /// K dx = r, added to x: the Krylov space of K (LU)⁻¹ from r.
    fn gmres(&self, r: Vec<[f64; 6]>, x: &mut [[f64; 6]]) {
        let dot = |u: &[[f64; 6]], v: &[[f64; 6]]| -> f64 {
            u.iter()
                .zip(v)
                .map(|(a, b)| (0..6).map(|c| a[c] * b[c]).sum::<f64>())
                .sum()
        };
        let beta = dot(&r, &r).sqrt();
        if !(beta > 0.0 && beta.is_finite()) {
            return;
        }
        let scaled = |v: &[[f64; 6]], f: f64| -> Vec<[f64; 6]> {
            v.iter()
                .map(|a| std::array::from_fn(|c| a[c] * f))
                .collect()
        };
        let mut basis = vec![scaled(&r, 1.0 / beta)];
        let mut preconditioned: Vec<Vec<[f64; 6]>> = Vec::new();
        // Hessenberg columns, reduced by Givens rotations as they come.
        let mut h: Vec<Vec<f64>> = Vec::new();
        let mut rotations: Vec<(f64, f64)> = Vec::new();
        let mut g = vec![beta];
        for j in 0..KRYLOV {
            let z = self.substitute(basis[j].clone());
            let mut w = self.multiply(&z);
            preconditioned.push(z);
            let mut column = vec![0.0; j + 2];
            for (i, v) in basis.iter().enumerate() {
                let hij = dot(&w, v);
                column[i] = hij;
                for (a, b) in w.iter_mut().zip(v) {
                    for c in 0..6 {
                        a[c] -= hij * b[c];
                    }
                }
            }
            let norm = dot(&w, &w).sqrt();
            column[j + 1] = norm;
            for (i, &(cs, sn)) in rotations.iter().enumerate() {
                let (a, b) = (column[i], column[i + 1]);
                column[i] = cs * a + sn * b;
                column[i + 1] = -sn * a + cs * b;
            }
            let (a, b) = (column[j], column[j + 1]);
            let rho = crate::math::hypot(a, b);
            let (cs, sn) = if rho > 0.0 {
                (a / rho, b / rho)
            } else {
                (1.0, 0.0)
            };
            column[j] = rho;
            column[j + 1] = 0.0;
            rotations.push((cs, sn));
            g.push(-sn * g[j]);
            g[j] *= cs;
            h.push(column);
            if g[j + 1].abs() <= 1e-3 * RESIDUAL * beta || norm == 0.0 || !norm.is_finite() {
                break;
            }
            basis.push(scaled(&w, 1.0 / norm));
        }
        // y from the triangular H y = g, then x += Σ y_j z_j.
        let k = h.len();
        let mut y = vec![0.0; k];
        for i in (0..k).rev() {
            let mut v = g[i];
            for j in i + 1..k {
                v -= h[j][i] * y[j];
            }
            y[i] = if h[i][i] != 0.0 { v / h[i][i] } else { 0.0 };
        }
        for (z, &yj) in preconditioned.iter().zip(&y) {
            for (a, b) in x.iter_mut().zip(z) {
                for c in 0..6 {
                    a[c] += yj * b[c];
                }
            }
        }
    }

    /// Each term K_ij,ac · v_j,c of block row `i` of K v with the original
    /// blocks (elimination order), in a fixed order, with its entry `a`.
    fn row_terms(&self, i: usize, v: &[[f64; 6]], mut each: impl FnMut(usize, f64)) {
        let p = self.pattern;
        for (t, &j) in p.columns[i].iter().enumerate() {
            let k = &self.original[p.start[i] + t];
            for a in 0..6 {
                for c in 0..6 {
                    each(a, k[6 * a + c] * v[j][c]);
                }
            }
        }
    }

    /// K v with the original blocks (elimination order).
    fn multiply(&self, v: &[[f64; 6]]) -> Vec<[f64; 6]> {
        (0..v.len())
            .map(|i| {
                let mut out = [0.0; 6];
                self.row_terms(i, v, |a, term| out[a] += term);
                out
            })
            .collect()
    }

    /// L U x = b by forward and back substitution (elimination order).
    fn substitute(&self, mut y: Vec<[f64; 6]>) -> Vec<[f64; 6]> {
        let p = self.pattern;
        let nb = y.len();
        for k in 0..nb {
            for (t, &j) in p.columns[k].iter().enumerate() {
                if j >= k {
                    break;
                }
                let yj = y[j];
                subtract_apply(&mut y[k], &self.lu[p.start[k] + t], &yj);
            }
        }
        let mut x = vec![[0.0f64; 6]; nb];
        for k in (0..nb).rev() {
            let mut r = y[k];
            for (t, &j) in p.columns[k].iter().enumerate() {
                if j > k {
                    let xj = x[j];
                    subtract_apply(&mut r, &self.lu[p.start[k] + t], &xj);
                }
            }
            x[k] = apply(&self.pivot_inverse[k], &r);
        }
        x
    }

    /// b − K x, its largest entry, and the largest sum of the sizes of the
    /// terms an entry adds up (what rounding is measured against).
    fn residual(&self, b: &[[f64; 6]], x: &[[f64; 6]]) -> (Vec<[f64; 6]>, f64, f64) {
        let mut worst = 0.0f64;
        let mut scale = 0.0f64;
        let r = (0..b.len())
            .map(|i| {
                let mut r = b[i];
                let mut size: [f64; 6] = std::array::from_fn(|a| b[i][a].abs());
                self.row_terms(i, x, |a, term| {
                    r[a] -= term;
                    size[a] += term.abs();
                });
                for a in 0..6 {
                    worst = worst.max(r[a].abs());
                    scale = scale.max(size[a]);
                }
                r
            })
            .collect();
        (r, worst, scale)
    }
}

/// Krylov vectors of a GMRES cycle, and cycles at most, that a block solve
/// may take to bring its residual to `RESIDUAL`: near the answer a pile
/// island's Newton systems can come out of the substitution just short of
/// it, and iterative refinement does not mend that.
const KRYLOV: usize = 12;
const KRYLOV_CYCLES: usize = 2;

/// Largest residual of a block solve, relative to the sizes of the terms
/// it sums, that is trusted (a dense LU with pivoting reaches ~1e-15).
const RESIDUAL: f64 = 1e-11;

/// Smallest pivot, relative to the block's largest entry, that a pivot
/// block's inversion accepts.
const PIVOT: f64 = 1e-15;

/// Inverse of a 6×6 block by Gauss–Jordan elimination with partial
/// pivoting; `None` where a pivot is below `PIVOT` of the largest entry.
fn invert(a: &Block) -> Option<Block> {
    let mut m = *a;
    let mut inv = [0.0; 36];
    for c in 0..6 {
        inv[7 * c] = 1.0;
    }
    let largest = m.iter().fold(0.0f64, |s, x| s.max(x.abs()));
    if !(largest > 0.0 && largest.is_finite()) {
        return None;
    }
    for c in 0..6 {
        let r = (c..6)
            .max_by(|&x, &y| m[6 * x + c].abs().total_cmp(&m[6 * y + c].abs()))
            .expect("rows left");
        let pivot = m[6 * r + c];
        if pivot.abs() < PIVOT * largest {
            return None;
        }
        if r != c {
            for k in 0..6 {
                m.swap(6 * r + k, 6 * c + k);
                inv.swap(6 * r + k, 6 * c + k);
            }
        }
        let scale = 1.0 / pivot;
        for k in 0..6 {
            m[6 * c + k] *= scale;
            inv[6 * c + k] *= scale;
        }
        for x in 0..6 {
            if x != c {
                let f = m[6 * x + c];
                if f != 0.0 {
                    for k in 0..6 {
                        m[6 * x + k] -= f * m[6 * c + k];
                        inv[6 * x + k] -= f * inv[6 * c + k];
                    }
                }
            }
        }
    }
    Some(inv)
}

fn multiply(a: &Block, b: &Block) -> Block {
    let mut c = [0.0; 36];
    for i in 0..6 {
        for k in 0..6 {
            let f = a[6 * i + k];
            if f != 0.0 {
                for j in 0..6 {
                    c[6 * i + j] += f * b[6 * k + j];
                }
            }
        }
    }
    c
}

/// c −= a b.
fn subtract_product(c: &mut Block, a: &Block, b: &Block) {
    for i in 0..6 {
        for k in 0..6 {
            let f = a[6 * i + k];
            if f != 0.0 {
                for j in 0..6 {
                    c[6 * i + j] -= f * b[6 * k + j];
                }
            }
        }
    }
}

fn apply(a: &Block, x: &[f64; 6]) -> [f64; 6] {
    let mut y = [0.0; 6];
    for i in 0..6 {
        for k in 0..6 {
            y[i] += a[6 * i + k] * x[k];
        }
    }
    y
}

/// y −= a x.
fn subtract_apply(y: &mut [f64; 6], a: &Block, x: &[f64; 6]) {
    for i in 0..6 {
        for k in 0..6 {
            y[i] -= a[6 * i + k] * x[k];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::linalg::solvers::Solve;

    /// A deterministic pseudo-random number in [−1, 1).
    fn noise(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    /// A pile-like body graph: each body touches the next and a few
    /// farther ones; blocks I + a nonsymmetric coupling per edge, as the
    /// Newton matrix's contacts add them.
    fn pile(bodies: usize, seed: &mut u64) -> (BlockPattern, Vec<(usize, usize)>) {
        let mut edges = Vec::new();
        for i in 1..bodies {
            edges.push((i - 1, i));
            let j = ((noise(seed) + 1.0) * 0.5 * i as f64) as usize;
            edges.push((j.min(i - 1), i));
        }
        (BlockPattern::new(bodies, edges.clone()), edges)
    }

    fn fill(m: &mut BlockMatrix, edges: &[(usize, usize)], seed: &mut u64) {
        for &(a, b) in edges {
            // A contact's 12×12 part: response ⊗ weighted jacobian, rank 3.
            let mut jac = [[0.0; 12]; 3];
            let mut resp = [[0.0; 12]; 3];
            for r in 0..3 {
                for c in 0..12 {
                    jac[r][c] = noise(seed);
                    resp[r][c] = jac[r][c] * (1.0 + 0.3 * noise(seed));
                }
            }
            let weight = 10f64.powf(3.0 * noise(seed));
            for (sr, br) in [(0, a), (1, b)] {
                for (sq, bq) in [(0, a), (1, b)] {
                    let block = m.block_mut(br, bq);
                    for x in 0..6 {
                        for y in 0..6 {
                            for r in 0..3 {
                                block[6 * x + y] +=
                                    weight * resp[r][6 * sr + x] * jac[r][6 * sq + y];
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn block_lu_solves_as_the_dense_lu_does() {
        let mut seed = 7;
        for bodies in [1, 2, 5, 12, 40, 150] {
            let (pattern, edges) = pile(bodies, &mut seed);
            let mut m = BlockMatrix::identity(&pattern);
            fill(&mut m, &edges, &mut seed);
            let rhs: Vec<f64> = (0..6 * bodies).map(|_| noise(&mut seed)).collect();
            let lu = m.factor().expect("pivot blocks are regular");
            let x = lu.solve(&rhs).expect("residual at rounding level");
            let dense = m.to_dense();
            let b = faer::Mat::<f64>::from_fn(6 * bodies, 1, |i, _| rhs[i]);
            let xd = dense.partial_piv_lu().solve(&b);
            let size = (0..6 * bodies).fold(0.0f64, |s, i| s.max(xd[(i, 0)].abs()));
            for i in 0..6 * bodies {
                assert!(
                    (x[i] - xd[(i, 0)]).abs() <= 1e-9 * size,
                    "{bodies} bodies, unknown {i}: {} vs {}",
                    x[i],
                    xd[(i, 0)]
                );
            }
        }
    }

    #[test]
    fn a_singular_pivot_block_is_refused() {
        let pattern = BlockPattern::new(2, [(0, 1)]);
        let mut m = BlockMatrix::identity(&pattern);
        // Body 0's block: the identity less itself in one direction.
        m.block_mut(0, 0)[0] = 0.0;
        assert!(m.factor().is_none());
    }

    #[test]
    fn minimum_degree_fills_nothing_on_a_chain() {
        // A chain eliminated from its ends fills no block.
        let bodies = 30;
        let pattern = BlockPattern::new(bodies, (1..bodies).map(|i| (i - 1, i)));
        assert_eq!(pattern.blocks(), bodies + 2 * (bodies - 1));
    }
}
