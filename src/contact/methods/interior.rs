//! An interior-point solve of a large island's boxed LCP in velocity
//! space: cost about linear in its rows, whatever their redundancy.
//!
//! The system is the iterative solve's, w = (A + c·diag) p + b with
//! A = J M⁻¹ Jᵀ, a normal row's p ≥ 0 ⟂ w ≥ 0, a friction row's p within
//! ± μ times its normal row's p, w ≥ 0 at the lower bound, ≤ 0 at the
//! upper one, 0 between. Redundant contacts (a pile's systems have five
//! times more rows than their bodies have degrees of freedom) make A
//! singular, so methods on the rows (Dantzig's pivots, Gauss–Seidel
//! sweeps) cycle or crawl there; the velocities the answer gives are
//! unique all the same. Each Newton step of a primal–dual interior-point
//! method (Mehrotra's predictor–corrector) solves (A + G) Δp = r, G block
//! diagonal per contact (the complementarity's Jacobian: a friction row's
//! bounds move with its normal row's impulse, so G is lower triangular per
//! contact). By Woodbury that is a system of the moving bodies' velocities,
//! (I + M⁻¹ Jᵀ G⁻¹ J) Δu = M⁻¹ Jᵀ G⁻¹ r, six unknowns a body, then
//! Δp = G⁻¹ (r − J Δu): never A.
//!
//! The interior iterates never sit on a bound; once they are close, each
//! row is put on the bound its complementarity points at and the rows
//! left free are solved together exactly (the iterative solve's subspace
//! step), so the answer meets the same conditions, to the same tolerance,
//! as the sweeps' would.

use super::block_lu::{BlockLu, BlockMatrix, BlockPattern};
use super::subspace;
use crate::contact::system::NO_RESPONSE;
use crate::contact::system::{IterativeState, IterativeSystem, Row, Step};
use faer::Mat;
use faer::linalg::solvers::{PartialPivLu, Solve};
use nalgebra::Vector3;

/// Newton steps at most before the solve gives up (and the caller solves
/// as before).
const MAX_STEPS: usize = 60;
/// Moving bodies at most. The Newton systems are factored block by block
/// in the bodies' contact graph (`block_lu`), six unknowns a body, so an
/// 82-body pile island of 1400 rows costs about what its rows do.
const MAX_BODIES: usize = 1000;
/// Moving bodies at most for which a Newton system whose block solve is
/// refused is factored densely (with pivoting); beyond, such a system ends
/// the solve (a dense LU of 500 unknowns costs 10⁸ flops a step).
pub(crate) const DENSE_BODIES: usize = 48;
/// Added to the Newton matrix's diagonal, times A_ii, and nowhere else:
/// it damps the steps along what the rows leave undetermined (the friction
/// of redundant corners, free between its bounds with w ≈ 0, swung from
/// one bound to the other and blocked the steps), and changes no answer
/// (the residuals are the system's own). Less leaves those swings; more
/// slows the steps toward the answer.
const DAMPING: f64 = 3e-9;
/// Fraction of the way to the nearest bound a step may go.
const TO_BOUND: f64 = 0.995;
/// Newton steps from the first close enough to try the finish after
/// which the solve stops (and the caller solves as before): a large
/// island's iterates keep closing in for 20 steps and more.
const FINISH_ATTEMPTS: usize = 25;
/// Newton steps after which a solve not yet close to the answer stops.
const FAR_STEPS: usize = 30;
/// Attempts from which the finish also solves the free rows exactly (the
/// subspace step: a sparse factorisation of the free rows, most of the
/// finish's cost). Late, because the Newton steps get there by themselves
/// as often.
const POLISH_FROM: usize = 15;

/// A row's part in the complementarity.
#[derive(Clone, Copy)]
enum Kind {
    /// Nothing moves it (both bodies fixed): p = 0, left out.
    Dead,
    Normal,
    /// Friction row with its normal row and bound coefficients.
    Friction {
        normal: usize,
        lo: f64,
        hi: f64,
    },
}

/// What the interior solve came to.
pub(crate) struct InteriorAnswer {
    pub p: Vec<f64>,
    pub met: bool,
    pub steps: u32,
}

/// Solves the system from `warm` (the last solve's impulses, or zero).
/// `None` where a Newton system could not be factored.
pub(crate) fn solve(
    system: &IterativeSystem,
    warm: &[f64],
    bodies: usize,
) -> Option<InteriorAnswer> {
    let rows = system.rows;
    let m = rows.len();
    let kind = kinds(system);
    let (slot, moving) = moving_bodies(rows, bodies);
    if !takes(moving) {
        return None;
    }
    let pattern = BlockPattern::new(
        moving,
        rows.iter()
            .filter(|r| slot[r.a] != usize::MAX && slot[r.b] != usize::MAX)
            .map(|r| (slot[r.a], slot[r.b])),
    );
    let bmax = system
        .b
        .iter()
        .fold(0.0f64, |s, x| s.max(x.abs()))
        .max(1e-12);
    let mut it = Iterate::start(system, &kind, warm, bmax, bodies);
    let pairs = kind.iter().fold(0usize, |c, k| match k {
        Kind::Dead => c,
        Kind::Normal => c + 1,
        Kind::Friction { .. } => c + 2,
    });
    if pairs == 0 {
        return None;
    }
    let newton = Newton {
        system,
        kind: &kind,
        slot: &slot,
        pattern: &pattern,
        unknowns: 6 * moving,
        bodies,
    };

    let mut steps = 0;
    let mut attempts = 0;
    let mut stalled = 0;
    let mut da = vec![0.0; m];
    let mut dc = vec![0.0; m];
    while steps < MAX_STEPS {
        steps += 1;
        let w: Vec<f64> = (0..m).map(|i| system.velocity(i, &it.state)).collect();
        let gaps = Gaps::of(&kind, &it.p);
        let mu = complementarity(&kind, &it.p, &gaps, &it.s, &it.z, &it.y) / pairs as f64;
        // Close enough to read the sets off: try the exact finish.
        let close = mu < 1e-3 * system.tolerance * bmax / max_diag(system);
        if close {
            attempts += 1;
        }
        // Far from the answer after this many steps: stalled (see below).
        let hopeless = !close && steps >= FAR_STEPS;
        if close || steps == MAX_STEPS || hopeless {
            let last = steps == MAX_STEPS || attempts == FINISH_ATTEMPTS || hopeless;
            let answer = finish(system, &it.p, bodies, last, attempts >= POLISH_FROM);
            if answer.met || last {
                return Some(InteriorAnswer {
                    steps: steps as u32,
                    ..answer
                });
            }
        }
        let (d, alpha) = newton.step(&it, &w, &gaps, (mu, pairs), (&mut da, &mut dc))?;
        // Stalled near the answer (the friction bounds move with the
        // normal impulses, so the problem is not monotone and the centring
        // can fail): hand over.
        if attempts > 0 && alpha < 0.1 {
            stalled += 1;
            if stalled >= 3 {
                attempts = FINISH_ATTEMPTS - 1;
            }
        }
        it.advance(alpha, &d, system, bodies);
    }
    None
}

/// Each row's part in the complementarity.
fn kinds(system: &IterativeSystem) -> Vec<Kind> {
    (0..system.rows.len())
        .map(|i| {
            if system.diag[i] <= NO_RESPONSE {
                Kind::Dead
            } else {
                match system.findex[i] {
                    None => Kind::Normal,
                    Some(k) if system.diag[k] > NO_RESPONSE => Kind::Friction {
                        normal: k,
                        lo: system.lo[i],
                        hi: system.hi[i],
                    },
                    Some(_) => Kind::Dead,
                }
            }
        })
        .collect()
}

/// The primal–dual iterate: the impulses p (and the velocity changes
/// they give, `state`), and the dual variables: s for a normal row (its
/// w), z and y for a friction row's lower and upper bound (w = z − y).
struct Iterate {
    p: Vec<f64>,
    s: Vec<f64>,
    z: Vec<f64>,
    y: Vec<f64>,
    state: IterativeState,
}

/// A Newton direction of every part of the iterate.
struct Direction {
    dp: Vec<f64>,
    ds: Vec<f64>,
    dz: Vec<f64>,
    dy: Vec<f64>,
}

impl Iterate {
    /// The start: the warm impulses pushed inside the bounds, each dual
    /// variable at least a tenth of the largest |b|.
    fn start(
        system: &IterativeSystem,
        kind: &[Kind],
        warm: &[f64],
        bmax: f64,
        bodies: usize,
    ) -> Iterate {
        let m = kind.len();
        let mut p = vec![0.0; m];
        for i in 0..m {
            match kind[i] {
                Kind::Dead => {}
                Kind::Normal => p[i] = warm[i].max(0.1 * bmax / system.diag[i]),
                Kind::Friction { .. } => {}
            }
        }
        for i in 0..m {
            if let Kind::Friction { normal, lo, hi } = kind[i] {
                let (l, h) = (lo * p[normal], hi * p[normal]);
                let mid = 0.5 * (l + h);
                p[i] = warm[i].clamp(mid + 0.5 * (l - mid), mid + 0.5 * (h - mid));
            }
        }
        let state = state_of(system, &p, bodies);
        let w0: Vec<f64> = (0..m).map(|i| system.velocity(i, &state)).collect();
        let floor = 0.1 * bmax;
        let mut s = vec![0.0; m];
        let mut z = vec![0.0; m];
        let mut y = vec![0.0; m];
        for i in 0..m {
            match kind[i] {
                Kind::Dead => {}
                Kind::Normal => s[i] = w0[i].max(0.0) + floor,
                Kind::Friction { .. } => {
                    z[i] = w0[i].max(0.0) + floor;
                    y[i] = (-w0[i]).max(0.0) + floor;
                }
            }
        }
        Iterate { p, s, z, y, state }
    }

    /// A step `alpha` along `d`.
    fn advance(&mut self, alpha: f64, d: &Direction, system: &IterativeSystem, bodies: usize) {
        for i in 0..self.p.len() {
            self.p[i] += alpha * d.dp[i];
            self.s[i] += alpha * d.ds[i];
            self.z[i] += alpha * d.dz[i];
            self.y[i] += alpha * d.dy[i];
        }
        self.state = state_of(system, &self.p, bodies);
    }
}

/// What the Newton steps of one solve share: the system, its rows' kinds,
/// the moving bodies' slots in the velocity system (`usize::MAX` for the
/// others) and that system's block pattern.
struct Newton<'a> {
    system: &'a IterativeSystem<'a>,
    kind: &'a [Kind],
    slot: &'a [usize],
    pattern: &'a BlockPattern,
    /// Six a moving body.
    unknowns: usize,
    bodies: usize,
}

impl Newton<'_> {
    /// Mehrotra's predictor–corrector direction from `it` (`w` its rows'
    /// velocities, `mu` its mean complementarity over `pairs`) and the
    /// step along it; `None` where a Newton system could not be factored
    /// or the step is not finite. `da`, `dc`: each friction row's change
    /// of its gaps to its bounds, scratch.
    fn step(
        &self,
        it: &Iterate,
        w: &[f64],
        gaps: &Gaps,
        (mu, pairs): (f64, usize),
        (da, dc): (&mut [f64], &mut [f64]),
    ) -> Option<(Direction, f64)> {
        let kind = self.kind;
        let m = kind.len();
        let (p, s, z, y) = (&it.p[..], &it.s[..], &it.z[..], &it.y[..]);
        // Residuals of w's equations.
        let rw: Vec<f64> = (0..m)
            .map(|i| match kind[i] {
                Kind::Dead => 0.0,
                Kind::Normal => w[i] - s[i],
                Kind::Friction { .. } => w[i] - z[i] + y[i],
            })
            .collect();
        let (g, e) = self.weights(it, gaps);
        let k = newton_matrix(self.pattern, self.system.rows, kind, self.slot, &g, &e);
        let mut factor = Factor::of(&k)?;
        let mut solve_for = |r: &[f64]| self.solve_for(&k, &mut factor, (&g, &e), r);
        // Predictor (σ = 0), then Mehrotra's corrector.
        let rhs_of = |target: &dyn Fn(usize, u8) -> f64| -> Vec<f64> {
            (0..m)
                .map(|i| match kind[i] {
                    Kind::Dead => 0.0,
                    Kind::Normal => -rw[i] + target(i, 0) / p[i],
                    Kind::Friction { .. } => {
                        -rw[i] + target(i, 1) / gaps.lo[i] - target(i, 2) / gaps.hi[i]
                    }
                })
                .collect()
        };
        let affine_target = |i: usize, which: u8| match which {
            0 => -p[i] * s[i],
            1 => -gaps.lo[i] * z[i],
            _ => -gaps.hi[i] * y[i],
        };
        let dp_aff = solve_for(&rhs_of(&affine_target))?;
        let (ds_aff, dz_aff, dy_aff) = dual(kind, it, gaps, &dp_aff, &affine_target, (da, dc));
        let alpha_aff = step_length(
            kind,
            (p, gaps, s, z, y),
            (&dp_aff, da, dc, &ds_aff, &dz_aff, &dy_aff),
        );
        let mu_aff = complementarity_along(
            kind,
            (p, gaps, s, z, y),
            alpha_aff,
            (&dp_aff, da, dc, &ds_aff, &dz_aff, &dy_aff),
        ) / pairs as f64;
        let sigma = (mu_aff / mu).powi(3).min(1.0);
        let (da_aff, dc_aff) = (da.to_vec(), dc.to_vec());
        let corrected = |i: usize, which: u8| match which {
            0 => sigma * mu - p[i] * s[i] - dp_aff[i] * ds_aff[i],
            1 => sigma * mu - gaps.lo[i] * z[i] - da_aff[i] * dz_aff[i],
            _ => sigma * mu - gaps.hi[i] * y[i] - dc_aff[i] * dy_aff[i],
        };
        let dp = solve_for(&rhs_of(&corrected))?;
        let (ds, dz, dy) = dual(kind, it, gaps, &dp, &corrected, (da, dc));
        let alpha = (TO_BOUND
            * step_length(kind, (p, gaps, s, z, y), (&dp, da, dc, &ds, &dz, &dy)))
        .min(1.0);
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !alpha.is_finite()
            || alpha <= 0.0
            || !finite(&dp)
            || !finite(&ds)
            || !finite(&dz)
            || !finite(&dy)
        {
            return None;
        }
        Some((Direction { dp, ds, dz, dy }, alpha))
    }

    /// G, per row: its diagonal g and its coupling e to its normal row.
    fn weights(&self, it: &Iterate, gaps: &Gaps) -> (Vec<f64>, Vec<f64>) {
        let system = self.system;
        let m = self.kind.len();
        let (p, s, z, y) = (&it.p, &it.s, &it.z, &it.y);
        let mut g = vec![1.0; m];
        let mut e = vec![0.0; m];
        for i in 0..m {
            let c = (system.compliance + DAMPING) * system.diag[i];
            match self.kind[i] {
                Kind::Dead => {}
                Kind::Normal => g[i] = c + s[i] / p[i],
                Kind::Friction { lo, hi, .. } => {
                    g[i] = c + z[i] / gaps.lo[i] + y[i] / gaps.hi[i];
                    e[i] = -lo * z[i] / gaps.lo[i] - hi * y[i] / gaps.hi[i];
                }
            }
        }
        (g, e)
    }

    /// Δp with (A + G) Δp = r, by Woodbury: t = G⁻¹ r, the velocity system
    /// K Δu = M⁻¹ Jᵀ t, then Δp = G⁻¹ (r − J Δu).
    fn solve_for<'m>(
        &self,
        k: &'m BlockMatrix,
        factor: &mut Factor<'m>,
        (g, e): (&[f64], &[f64]),
        r: &[f64],
    ) -> Option<Vec<f64>> {
        let (kind, slot, rows) = (self.kind, self.slot, self.system.rows);
        let m = kind.len();
        // t = G⁻¹ r
        let t = ginv(kind, g, e, r);
        let mut rhs = vec![0.0; self.unknowns];
        for (i, row) in rows.iter().enumerate() {
            if t[i] == 0.0 {
                continue;
            }
            let resp = row.response();
            for (side, body) in [(0, row.a), (1, row.b)] {
                if slot[body] == usize::MAX {
                    continue;
                }
                for c in 0..6 {
                    rhs[6 * slot[body] + c] += t[i] * resp[side][c];
                }
            }
        }
        let du = factor.solve(k, &rhs)?;
        let mut dv = vec![Vector3::zeros(); self.bodies];
        let mut dw = vec![Vector3::zeros(); self.bodies];
        for b in 0..self.bodies {
            if slot[b] != usize::MAX {
                let o = 6 * slot[b];
                dv[b] = Vector3::new(du[o], du[o + 1], du[o + 2]);
                dw[b] = Vector3::new(du[o + 3], du[o + 4], du[o + 5]);
            }
        }
        let r2: Vec<f64> = (0..m).map(|i| r[i] - rows[i].velocity(&dv, &dw)).collect();
        Some(ginv(kind, g, e, &r2))
    }
}

/// The dual variables' direction that goes with `dp` towards `target`
/// (which: 0 a normal row's, 1 and 2 a friction row's lower and upper
/// bound's complementarity), with each friction row's gap changes written
/// into `da`, `dc`.
fn dual(
    kind: &[Kind],
    it: &Iterate,
    gaps: &Gaps,
    dp: &[f64],
    target: &dyn Fn(usize, u8) -> f64,
    (da, dc): (&mut [f64], &mut [f64]),
) -> (Vec<f64>, Vec<f64>, Vec<f64>) {
    let m = kind.len();
    let (p, s, z, y) = (&it.p, &it.s, &it.z, &it.y);
    let mut ds = vec![0.0; m];
    let mut dz = vec![0.0; m];
    let mut dy = vec![0.0; m];
    for i in 0..m {
        match kind[i] {
            Kind::Dead => {}
            Kind::Normal => ds[i] = (target(i, 0) - s[i] * dp[i]) / p[i],
            Kind::Friction { normal, lo, hi } => {
                da[i] = dp[i] - lo * dp[normal];
                dc[i] = hi * dp[normal] - dp[i];
                dz[i] = (target(i, 1) - z[i] * da[i]) / gaps.lo[i];
                dy[i] = (target(i, 2) - y[i] * dc[i]) / gaps.hi[i];
            }
        }
    }
    (ds, dz, dy)
}

/// The complementarity's sum after a step `alpha` along a direction.
#[allow(clippy::type_complexity)]
fn complementarity_along(
    kind: &[Kind],
    (p, gaps, s, z, y): (&[f64], &Gaps, &[f64], &[f64], &[f64]),
    alpha: f64,
    (dp, da, dc, ds, dz, dy): (&[f64], &[f64], &[f64], &[f64], &[f64], &[f64]),
) -> f64 {
    let mut sum = 0.0;
    for i in 0..p.len() {
        match kind[i] {
            Kind::Dead => {}
            Kind::Normal => sum += (p[i] + alpha * dp[i]) * (s[i] + alpha * ds[i]),
            Kind::Friction { .. } => {
                sum += (gaps.lo[i] + alpha * da[i]) * (z[i] + alpha * dz[i])
                    + (gaps.hi[i] + alpha * dc[i]) * (y[i] + alpha * dy[i])
            }
        }
    }
    sum
}

/// The bodies the rows move, numbered for the velocity system (`usize::MAX`
/// for the others), and how many.
fn moving_bodies(rows: &[Row], bodies: usize) -> (Vec<usize>, usize) {
    let mut slot = vec![usize::MAX; bodies];
    let mut moving = 0;
    for row in rows {
        let (ma, mb) = row.moves();
        for (body, moves) in [(row.a, ma), (row.b, mb)] {
            if moves && slot[body] == usize::MAX {
                slot[body] = moving;
                moving += 1;
            }
        }
    }
    (slot, moving)
}

/// How many bodies the rows move (the Newton systems' six unknowns each).
pub(crate) fn moving_count(rows: &[Row], bodies: usize) -> usize {
    moving_bodies(rows, bodies).1
}

/// Whether `solve` takes a system that moves this many bodies
/// (`MAX_BODIES`).
fn takes(moving: usize) -> bool {
    moving <= MAX_BODIES
}

fn max_diag(system: &IterativeSystem) -> f64 {
    system.diag.iter().fold(NO_RESPONSE, |a, &d| a.max(d))
}

/// Each friction row's distance to its lower and upper bound.
struct Gaps {
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl Gaps {
    fn of(kind: &[Kind], p: &[f64]) -> Gaps {
        let mut gaps = Gaps {
            lo: vec![0.0; p.len()],
            hi: vec![0.0; p.len()],
        };
        for (i, k) in kind.iter().enumerate() {
            if let Kind::Friction { normal, lo, hi } = *k {
                gaps.lo[i] = p[i] - lo * p[normal];
                gaps.hi[i] = hi * p[normal] - p[i];
            }
        }
        gaps
    }
}

fn complementarity(kind: &[Kind], p: &[f64], gaps: &Gaps, s: &[f64], z: &[f64], y: &[f64]) -> f64 {
    (0..p.len())
        .map(|i| match kind[i] {
            Kind::Dead => 0.0,
            Kind::Normal => p[i] * s[i],
            Kind::Friction { .. } => gaps.lo[i] * z[i] + gaps.hi[i] * y[i],
        })
        .sum()
}

/// The largest step (up to a large cap) that keeps every positive
/// quantity positive.
#[allow(clippy::type_complexity)]
fn step_length(
    kind: &[Kind],
    (p, gaps, s, z, y): (&[f64], &Gaps, &[f64], &[f64], &[f64]),
    (dp, da, dc, ds, dz, dy): (&[f64], &[f64], &[f64], &[f64], &[f64], &[f64]),
) -> f64 {
    let mut alpha = 1.0f64;
    let mut limit = |x: f64, dx: f64| {
        if dx < 0.0 {
            alpha = alpha.min(-x / dx);
        }
    };
    for i in 0..p.len() {
        match kind[i] {
            Kind::Dead => {}
            Kind::Normal => {
                limit(p[i], dp[i]);
                limit(s[i], ds[i]);
            }
            Kind::Friction { .. } => {
                limit(gaps.lo[i], da[i]);
                limit(gaps.hi[i], dc[i]);
                limit(z[i], dz[i]);
                limit(y[i], dy[i]);
            }
        }
    }
    alpha
}

/// G⁻¹ r, G lower triangular per contact (a friction row after its
/// normal row).
fn ginv(kind: &[Kind], g: &[f64], e: &[f64], r: &[f64]) -> Vec<f64> {
    let mut t = vec![0.0; r.len()];
    for i in 0..r.len() {
        t[i] = match kind[i] {
            Kind::Dead => 0.0,
            Kind::Normal => r[i] / g[i],
            Kind::Friction { normal, .. } => (r[i] - e[i] * t[normal]) / g[i],
        };
    }
    t
}

/// A Newton matrix's factors: block by block, or dense where a block
/// factorisation or solve was refused.
enum Factor<'m> {
    Blocks(BlockLu<'m>),
    Dense(PartialPivLu<f64>),
}

impl<'m> Factor<'m> {
    fn of(k: &'m BlockMatrix) -> Option<Self> {
        match k.factor() {
            Some(lu) => Some(Factor::Blocks(lu)),
            None => Self::dense(k),
        }
    }

    fn dense(k: &BlockMatrix) -> Option<Self> {
        (k.bodies() <= DENSE_BODIES).then(|| Factor::Dense(k.to_dense().partial_piv_lu()))
    }

    /// Δu with K Δu = rhs; a block solve whose residual is refused turns
    /// this factor dense.
    fn solve(&mut self, k: &'m BlockMatrix, rhs: &[f64]) -> Option<Vec<f64>> {
        if let Factor::Blocks(lu) = self {
            if let Some(x) = lu.solve(rhs) {
                return Some(x);
            }
            *self = Self::dense(k)?;
        }
        let Factor::Dense(lu) = self else {
            unreachable!("a block factor returned above")
        };
        let b = Mat::<f64>::from_fn(rhs.len(), 1, |i, _| rhs[i]);
        let x = lu.solve(&b);
        Some((0..rhs.len()).map(|i| x[(i, 0)]).collect())
    }
}

/// I + M⁻¹ Jᵀ G⁻¹ J over the moving bodies' velocities, contact by
/// contact: a contact's rows share its two bodies, so its part is one
/// 12×12 block, Σ_r (M⁻¹J_rᵀ) ⊗ (G⁻¹J)_r, added into the four 6×6 blocks
/// of its bodies.
fn newton_matrix<'p>(
    pattern: &'p BlockPattern,
    rows: &[Row],
    kind: &[Kind],
    slot: &[usize],
    g: &[f64],
    e: &[f64],
) -> BlockMatrix<'p> {
    let mut k = BlockMatrix::identity(pattern);
    let m = rows.len();
    let mut i = 0;
    while i < m {
        if !matches!(kind[i], Kind::Normal) {
            i += 1;
            continue;
        }
        // The contact: normal row i and the friction rows that follow it.
        let mut end = i + 1;
        while end < m && matches!(kind[end], Kind::Friction { normal, .. } if normal == i) {
            end += 1;
        }
        let (a, b) = (rows[i].a, rows[i].b);
        let jn = flat(&rows[i].jacobian());
        let mut block = [[0.0f64; 12]; 12];
        for r in i..end {
            let resp = flat(&rows[r].response());
            let jr = flat(&rows[r].jacobian());
            // Row r of G⁻¹J: J_r/g_r, less e_r/(g_r g_n)·J_n for friction.
            let mut q = [0.0f64; 12];
            let inv = 1.0 / g[r];
            let cross = if r == i { 0.0 } else { -e[r] * inv / g[i] };
            for c in 0..12 {
                q[c] = jr[c] * inv + cross * jn[c];
            }
            for (row, &f) in block.iter_mut().zip(&resp) {
                if f != 0.0 {
                    for c in 0..12 {
                        row[c] += f * q[c];
                    }
                }
            }
        }
        for (sr, br) in [(0, a), (1, b)] {
            if slot[br] == usize::MAX {
                continue;
            }
            for (sq, bq) in [(0, a), (1, b)] {
                if slot[bq] == usize::MAX {
                    continue;
                }
                let target = k.block_mut(slot[br], slot[bq]);
                for x in 0..6 {
                    for y in 0..6 {
                        target[6 * x + y] += block[6 * sr + x][6 * sq + y];
                    }
                }
            }
        }
        i = end;
    }
    k
}

fn flat(sides: &[[f64; 6]; 2]) -> [f64; 12] {
    let mut f = [0.0; 12];
    f[..6].copy_from_slice(&sides[0]);
    f[6..].copy_from_slice(&sides[1]);
    f
}

fn state_of(system: &IterativeSystem, p: &[f64], bodies: usize) -> IterativeState {
    let mut state = IterativeState {
        p: p.to_vec(),
        dv: vec![Vector3::zeros(); bodies],
        dw: vec![Vector3::zeros(); bodies],
    };
    for (row, &x) in system.rows.iter().zip(p) {
        if x != 0.0 {
            row.change_velocities(x, &mut state.dv, &mut state.dw);
        }
    }
    state
}

/// Puts each row on the bound its complementarity points at, then solves
/// the rows left free together (the subspace step) until the answer meets
/// the conditions or a step no longer helps.
fn finish(
    system: &IterativeSystem,
    p: &[f64],
    bodies: usize,
    last: bool,
    polish: bool,
) -> InteriorAnswer {
    // A dead row's p stays 0: no step moves it (`ginv`).
    let mut state = state_of(system, p, bodies);
    // Only where a subspace step may be taken.
    let by_body = (last || polish).then(|| subspace::rows_by_body(system.rows, bodies));
    let rounds = if last {
        4
    } else if polish {
        2
    } else {
        1
    };
    for _ in 0..rounds {
        snap_to_bounds(system, &mut state);
        if system.met(&state) {
            return InteriorAnswer {
                p: state.p,
                met: true,
                steps: 0,
            };
        }
        let Some(by_body) = &by_body else {
            break;
        };
        match subspace::step(system, by_body, &mut state) {
            Step::Kept => {}
            _ => break,
        }
    }
    snap_to_bounds(system, &mut state);
    let met = system.met(&state);
    InteriorAnswer {
        p: state.p,
        met,
        steps: 0,
    }
}

/// One projected Jacobi step on the rows it puts on a bound: a row whose
/// p − w/A_ii lies beyond a bound goes there (an interior iterate's p on
/// a row that is done pushing is tiny but not zero, and the conditions
/// ask w = 0 of every row strictly inside its bounds). The w are those
/// before the step; a friction row's bounds follow its normal row's new p.
fn snap_to_bounds(system: &IterativeSystem, state: &mut IterativeState) {
    let w: Vec<f64> = (0..state.p.len())
        .map(|i| system.velocity(i, state))
        .collect();
    for (i, row) in system.rows.iter().enumerate() {
        if system.diag[i] <= NO_RESPONSE {
            continue;
        }
        let (l, h) = system.bounds(i, &state.p);
        let target = (state.p[i] - w[i] / system.diag[i]).clamp(l, h);
        let to = if target <= l {
            l
        } else if target >= h {
            h
        } else {
            // Inside: keep p, but within the (possibly moved) bounds.
            state.p[i].clamp(l, h)
        };
        let delta = to - state.p[i];
        if delta != 0.0 && delta.is_finite() {
            state.p[i] = to;
            row.change_velocities(delta, &mut state.dv, &mut state.dw);
        }
    }
}
