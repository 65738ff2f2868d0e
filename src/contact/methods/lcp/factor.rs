//! The factor of the clamped block A_CC that the drive keeps (see the
//! module documentation, *Factorisation*): LDLᵀ, appended to and updated
//! in place, for symmetric A; LU with partial pivoting otherwise. With it,
//! the row-major view of A and the dot product the solver shares.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt;
use faer::{MatMut, Par};

use super::{NEGATIVE_PIVOT, NOISE, PIVOT_FLOOR};

/// Row-major view of A.
#[derive(Clone, Copy)]
pub(super) struct Mat<'a> {
    pub(super) a: &'a [f64],
    pub(super) n: usize,
}

impl Mat<'_> {
    #[inline]
    pub(super) fn at(&self, i: usize, j: usize) -> f64 {
        self.a[i * self.n + j]
    }
    #[inline]
    pub(super) fn row(&self, i: usize) -> &[f64] {
        &self.a[i * self.n..(i + 1) * self.n]
    }
}

/// Dot product with four accumulators (breaks the add chain so it vectorises).
#[inline]
pub(super) fn dot(a: &[f64], b: &[f64]) -> f64 {
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
pub(super) struct Factor {
    pub(super) cap: usize,
    pub(super) m: usize,
    pub(super) ld: Vec<f64>,
    pub(super) perm: Vec<usize>,
    /// The factor no longer matches C (refactor strategy or LU): rebuild before use.
    pub(super) dirty: bool,
    scratch: Vec<f64>,
    pub(super) regularized: usize,
    /// faer's scratch, sized when `cap` reaches the faer threshold.
    mem: Option<MemBuffer>,
}

impl Factor {
    pub(super) fn new() -> Self {
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

    pub(super) fn reserve(&mut self, n: usize, faer_min: usize) {
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

    pub(super) fn clear(&mut self) {
        self.m = 0;
        self.dirty = false;
    }

    #[inline]
    pub(super) fn d(&self, j: usize) -> f64 {
        self.ld[j * self.cap + j]
    }

    /// v ← L⁻¹ v (unit lower triangular), column by column so the inner loop
    /// is a contiguous axpy.
    pub(super) fn forward(&self, v: &mut [f64]) {
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
    pub(super) fn backward(&self, v: &mut [f64]) {
        let (m, cap) = (self.m, self.cap);
        let v = &mut v[..m];
        for j in (0..m).rev() {
            let col = &self.ld[j * cap + j + 1..j * cap + m];
            let s = dot(col, &v[j + 1..]);
            v[j] -= s;
        }
    }

    /// v ← U⁻¹ v for the LU factor.
    pub(super) fn backward_upper(&self, v: &mut [f64]) {
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
    pub(super) fn checked_pivot(&mut self, pivot: f64, floor: f64) -> Result<f64, String> {
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
    pub(super) fn append(&mut self, l: &[f64], pivot: f64) {
        let (m, cap) = (self.m, self.cap);
        for (j, &lj) in l[..m].iter().enumerate() {
            self.ld[j * cap + m] = lj;
        }
        self.ld[m * cap + m] = pivot;
        self.m += 1;
    }

    /// Removes position p from the LDLᵀ factor. Returns false if the update broke
    /// down (then the caller refactors).
    pub(super) fn remove(&mut self, p: usize, floor: f64) -> bool {
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
    pub(super) fn refactor(
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
    pub(super) fn lu_in_place(&mut self, m: usize) -> Result<(), String> {
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
