//! Dantzig's method (`lcp`) on an island's contact system: its dense
//! matrix A = J M⁻¹ Jᵀ, the factors and the warm start that make a pivot
//! cheap on a large system, the retry on the slightly compliant system
//! where the exact one fails, and the fallback on simpler systems where
//! both do.

use super::lcp;
use super::sweeps::projected_gauss_seidel;
use crate::contact::system::{IterativeSystem, Row};
use std::cell::RefCell;

/// Compliance added to the diagonal of a contact system the exact solve
/// failed on, relative to its largest diagonal entry. Redundant contacts (a
/// pyramid, a box on four corners) make A singular; Dantzig's method keeps
/// dependent rows out of the clamped set, but rounding can still let one in,
/// and its near-zero pivot then ruins the factor ("negative pivot"). With
/// A + εI every clamped block is positive definite with condition ≤ 1/ε.
/// The answer solves w = (A + εI) p + b exactly: a contact holding impulse p
/// closes at ε·A_max·p, e.g. 1e-8 · 0.3 /kg · 0.8 N s = 2.4e-9 m/s for the
/// 8 kg boxes of a resting stack (24 pm per step, which the overlap recovery
/// of the next step removes) — the constraint-force mixing of ODE and
/// Bullet, used here only where the exact solve failed.
const COMPLIANCE: f64 = 1e-8;

/// The storage behind `lcp::RowFactors` for a list of rows.
pub(crate) struct RowFactorsOf {
    body: Vec<[u32; 2]>,
    jacobian: Vec<[[f64; 6]; 2]>,
    response: Vec<[[f64; 6]; 2]>,
}

impl RowFactorsOf {
    pub(crate) fn new(rows: &[Row]) -> Self {
        RowFactorsOf {
            body: rows.iter().map(|r| [r.a as u32, r.b as u32]).collect(),
            jacobian: rows.iter().map(Row::jacobian).collect(),
            response: rows.iter().map(Row::response).collect(),
        }
    }

    pub(crate) fn view(&self, bodies: usize) -> lcp::RowFactors<'_> {
        lcp::RowFactors {
            bodies,
            body: &self.body,
            jacobian: &self.jacobian,
            response: &self.response,
        }
    }
}

thread_local! {
    /// One workspace per thread: no allocation per solve once warmed up.
    static WORKSPACE: RefCell<lcp::LcpWorkspace> = RefCell::new(lcp::LcpWorkspace::new());
}

/// Dantzig's method set up on one system: its dense matrix, and where the
/// system is large enough, the matrix's factors and the start.
pub(crate) struct Dantzig<'a> {
    /// A = J M⁻¹ Jᵀ, row-major.
    a: Vec<f64>,
    b: &'a [f64],
    lo: &'a [f64],
    hi: &'a [f64],
    findex: &'a [Option<usize>],
    bodies: usize,
    /// A's factors, so that Dantzig's drive updates w in O(rows) a pivot.
    factors: Option<RowFactorsOf>,
    start: Option<Vec<f64>>,
    options: lcp::LcpOptions,
}

impl<'a> Dantzig<'a> {
    /// Dantzig's method on `system` (its compliance and tolerance are the
    /// iterative solve's, and not used). Where `factored` it takes A's
    /// factors and starts from `start`, resuming its friction passes: the
    /// sets a start close to the answer implies are most of the answer's
    /// (`lcp::LcpProblem::start`). Elsewhere it starts afresh, with the
    /// dense product alone, and `start` is not used.
    pub(crate) fn new(
        system: &IterativeSystem<'a>,
        bodies: usize,
        factored: bool,
        start: Option<Vec<f64>>,
    ) -> Self {
        let rows = system.rows;
        let m = rows.len();
        let mut a = vec![0.0; m * m];
        for i in 0..m {
            for j in 0..m {
                a[i * m + j] = rows[i].coupling(&rows[j]);
            }
        }
        Dantzig {
            a,
            b: system.b,
            lo: system.lo,
            hi: system.hi,
            findex: system.findex,
            bodies,
            factors: factored.then(|| RowFactorsOf::new(rows)),
            start: start.filter(|_| factored),
            options: lcp::LcpOptions {
                resume_passes: factored,
                ..Default::default()
            },
        }
    }

    /// The dense matrix A, row-major.
    pub(crate) fn matrix(&self) -> &[f64] {
        &self.a
    }

    /// Solves the exact system.
    pub(crate) fn solve(&self) -> Result<lcp::LcpSolution, lcp::LcpError> {
        self.solve_with(&self.a)
    }

    /// Solves the system with the contacts made slightly compliant
    /// (`COMPLIANCE`): it removes the broken factors of redundant contacts,
    /// and its friction bounds settle where the singular system's cycled
    /// (the pyramid's do). Same factors, start and options as `solve`.
    pub(crate) fn solve_compliant(&self) -> Result<lcp::LcpSolution, lcp::LcpError> {
        self.solve_with(&compliant(&self.a, self.b.len()))
    }

    fn solve_with(&self, a: &[f64]) -> Result<lcp::LcpSolution, lcp::LcpError> {
        let problem = lcp::LcpProblem {
            a,
            b: self.b,
            lo: self.lo,
            hi: self.hi,
            findex: self.findex,
            factors: self.factors.as_ref().map(|f| f.view(self.bodies)),
            start: self.start.as_deref(),
        };
        WORKSPACE.with(|ws| ws.borrow_mut().solve(&problem, &self.options))
    }

    /// When the coupled friction problem fails (the friction bounds depend on the
    /// normal impulses, which is not an LCP and may not converge): solve the
    /// normal rows alone exactly, then the whole system with the friction bounds
    /// frozen at μ times those normal impulses (a boxed LCP with constant
    /// bounds). Projected Gauss–Seidel is the last resort.
    pub(crate) fn fallback(&self) -> Vec<f64> {
        let (a, m, b, lo, hi, findex) = (
            &self.a[..],
            self.b.len(),
            self.b,
            self.lo,
            self.hi,
            self.findex,
        );
        let Some(pn) = solve_normal_rows(a, m, b, findex) else {
            return projected_gauss_seidel(a, m, b, lo, hi, findex);
        };
        let (mut flo, mut fhi) = (lo.to_vec(), hi.to_vec());
        for i in 0..m {
            if let Some(j) = findex[i] {
                flo[i] = lo[i] * pn[j];
                fhi[i] = hi[i] * pn[j];
            }
        }
        match lcp::solve(&lcp::LcpProblem::boxed(a, b, &flo, &fhi)) {
            Ok(full) => full.x,
            Err(_) => pn,
        }
    }
}

fn compliant(a: &[f64], m: usize) -> Vec<f64> {
    let scale = (0..m).map(|i| a[i * m + i]).fold(0.0, f64::max);
    let mut reg = a.to_vec();
    for i in 0..m {
        reg[i * m + i] += COMPLIANCE * scale;
    }
    reg
}

/// The standard LCP on the normal rows alone (friction rows left at zero),
/// as a full-length impulse vector; `None` when the solver fails.
pub(crate) fn solve_normal_rows(
    a: &[f64],
    m: usize,
    b: &[f64],
    findex: &[Option<usize>],
) -> Option<Vec<f64>> {
    let normal: Vec<usize> = (0..m).filter(|&i| findex[i].is_none()).collect();
    let k = normal.len();
    let mut an = vec![0.0; k * k];
    for (r, &i) in normal.iter().enumerate() {
        for (c, &j) in normal.iter().enumerate() {
            an[r * k + c] = a[i * m + j];
        }
    }
    let bn: Vec<f64> = normal.iter().map(|&i| b[i]).collect();
    let sol = lcp::solve_standard(&an, &bn).ok()?;
    let mut p = vec![0.0; m];
    for (r, &i) in normal.iter().enumerate() {
        p[i] = sol.x[r];
    }
    Some(p)
}
