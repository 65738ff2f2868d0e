//! What every answer of a contact system passes before it is applied: how
//! far it misses the system's conditions is noted
//! (`SolveStats::worst_violation`), and the energy guard replaces an
//! answer that adds kinetic energy with a safe one.

use super::methods::dantzig::solve_normal_rows;
use super::methods::lcp;
use super::methods::sweeps::sequential_impulses;
use super::policy::SolverSettings;
use super::system::{IterativeSystem, PhaseSystem, Row};
use super::task::SolveStats;
use nalgebra::Vector3;

/// Records in `stats.worst_violation` how far `p` misses the LCP
/// conditions of `system` (`violation`); `bodies`: the island's bodies.
pub(super) fn note_violation(
    system: &PhaseSystem,
    p: &[f64],
    bodies: usize,
    stats: &mut SolveStats,
) {
    let v = violation(
        &system.rows,
        &system.rhs,
        &system.lo,
        &system.hi,
        &system.findex,
        p,
        bodies,
    );
    stats.worst_violation = stats.worst_violation.max(v);
}

/// How far impulses `p` miss the conditions of the system w = A p + b
/// (friction bounds ±μ times the normal row's impulse), in m/s: per row,
/// the velocity on the side its bound does not allow (w < 0 at a lower
/// bound, w > 0 at an upper one), and between its bounds the smaller of
/// |w| and the velocity change A_ii·(p − bound) that would take it to the
/// bound where its w is allowed (a friction row whose normal impulse is
/// 1e-13 has bounds that close: it may slip); a bound overstepped counts
/// times A_ii. Computed through the bodies' velocity change, independent of
/// the method that found p. Zero for an exact answer up to rounding.
fn violation(
    rows: &[Row],
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    findex: &[Option<usize>],
    p: &[f64],
    bodies: usize,
) -> f64 {
    let (mut dv, mut dw) = (
        vec![Vector3::zeros(); bodies],
        vec![Vector3::zeros(); bodies],
    );
    for (row, &pi) in rows.iter().zip(p) {
        row.change_velocities(pi, &mut dv, &mut dw);
    }
    let mut worst = 0.0f64;
    for (i, row) in rows.iter().enumerate() {
        let (l, h) = match findex[i] {
            None => (lo[i], hi[i]),
            Some(j) => (lo[i] * p[j].abs(), hi[i] * p[j].abs()),
        };
        let w = b[i] + row.velocity(&dv, &dw);
        let a_ii = row.coupling(row);
        let side = match (p[i] <= l, p[i] >= h) {
            (true, true) => 0.0,
            (true, false) => (-w).max(0.0),
            (false, true) => w.max(0.0),
            (false, false) if w > 0.0 => w.min(a_ii * (p[i] - l)),
            (false, false) => (-w).min(a_ii * (h - p[i])),
        };
        let outside = (l - p[i]).max(p[i] - h).max(0.0) * a_ii;
        worst = worst.max(side).max(outside);
    }
    worst
}

/// Answers to a contact system that add no energy, for the energy guard,
/// best first; `vel` is each row's own velocity (its target with no
/// restitution, overlap mending or separation allowance).
///
/// With e = 0 the LCP w = A p + vel, friction bounds included, cannot add
/// energy: ΔKE = pᵀvel + ½pᵀAp = pᵀw − ½pᵀAp, where pᵀw is zero on normal
/// rows and ≤ 0 on friction rows at their bounds. Newton's restitution
/// (target −e·v_N) with friction can (Kane and Levinson's paradox): in the
/// 200-body pours every guard rejection was a nut's single contact with
/// friction at impact. So, in turn:
/// 1. Poisson's restitution: that inelastic answer (the compression),
///    then each contact's normal impulse again times its e (a rebound with
///    no friction);
/// 2. the inelastic answer itself;
/// 3. the frictionless, inelastic LCP on the normal rows.
fn safe_answers(
    a: &[f64],
    m: usize,
    vel: &[f64],
    lo: &[f64],
    hi: &[f64],
    findex: &[Option<usize>],
    restitution: &[f64],
) -> Vec<(&'static str, Vec<f64>)> {
    let mut out = Vec::new();
    let inelastic = lcp::LcpProblem {
        a,
        b: vel,
        lo,
        hi,
        findex,
        factors: None,
        start: None,
    };
    if let Ok(sol) = lcp::solve(&inelastic) {
        if restitution.iter().any(|&e| e > 0.0) {
            // `restitution` is zero on friction rows.
            let rebound: Vec<f64> = sol
                .x
                .iter()
                .zip(restitution)
                .map(|(p, e)| p * (1.0 + e))
                .collect();
            out.push(("Poisson's restitution", rebound));
        }
        out.push(("the inelastic answer with friction", sol.x));
    }
    if let Some(p) = solve_normal_rows(a, m, vel, findex) {
        out.push(("the frictionless inelastic answer", p));
    }
    out
}

/// The energy guard of an answer of the iterative system (before Dantzig's
/// method set up the dense one); its safe answer is the frictionless,
/// inelastic solve by the sweeps: coordinate descent on the energy from
/// p = 0, so it cannot add any.
pub(super) fn guard_iterative(
    system: &PhaseSystem,
    (v, w): (&[Vector3<f64>], &[Vector3<f64>]),
    p: Vec<f64>,
    stats: &mut SolveStats,
    settings: &SolverSettings,
) -> Vec<f64> {
    let (rows, diag, findex) = (&system.rows, &system.diag, &system.findex);
    let m = rows.len();
    let bodies = v.len();
    let velocities = (v, w, &system.bias[..], system.deferred);
    energy_guard(diag, rows, velocities, p, stats, |vel| {
        let normal_hi: Vec<f64> = findex
            .iter()
            .map(|f| if f.is_none() { f64::INFINITY } else { 0.0 })
            .collect();
        let zero = vec![0.0; m];
        let frictionless = IterativeSystem::new(rows, diag, vel, &zero, &normal_hi, findex);
        let (p, _, _) = sequential_impulses(
            &frictionless,
            &zero,
            bodies,
            settings.iterative_sweeps,
            &settings.sweeps,
        );
        vec![("the frictionless inelastic answer", p)]
    })
}

/// The energy guard of an answer found once Dantzig's method set up the
/// dense matrix `a`: its safe answers are the dense ones (`safe_answers`).
pub(super) fn guard_dense(
    system: &PhaseSystem,
    a: &[f64],
    (v, w): (&[Vector3<f64>], &[Vector3<f64>]),
    p: Vec<f64>,
    stats: &mut SolveStats,
) -> Vec<f64> {
    let velocities = (v, w, &system.bias[..], system.deferred);
    let m = system.rows.len();
    energy_guard(&system.diag, &system.rows, velocities, p, stats, |vel| {
        safe_answers(
            a,
            m,
            vel,
            &system.lo,
            &system.hi,
            &system.findex,
            &system.restitution,
        )
    })
}

/// The body velocities a solve acts on, each row's bias, and the kinetic
/// energy (J) deferred bounces may give back (see `energy_guard`).
type Velocities<'a> = (&'a [Vector3<f64>], &'a [Vector3<f64>], &'a [f64], f64);

/// Share of the contacts' kinetic energy a solve may add before it is
/// rejected. Simultaneous restitution can add a little (Stronge's examples);
/// a solve that adds more is numerically wrong (a near-singular system), and
/// once applied it can fling a body at hundreds of m/s.
const ENERGY_GAIN_ALLOWED: f64 = 0.01;

/// Rejects a solution that adds kinetic energy. The change is
/// ΔKE = pᵀJv + ½ pᵀAp, summed here body by body (P·v + ½ P·ΔV with P the
/// impulse a body receives and ΔV = M⁻¹P): on a near-singular system a
/// wrong answer can hold impulses of 1e14 whose effects almost cancel in
/// the rows, and the quadratic form in A loses that to rounding while the
/// bodies still fly off. The frictionless, inelastic LCP on the same rows
/// (w = A_N p + J_N v ≥ 0, p ≥ 0) is the minimiser of that quadratic over
/// p ≥ 0, and p = 0 is feasible, so it can never add energy: it replaces a
/// rejected solution (reported as a failure with the system size).
///
/// A row's `bias` (the gap's curvature over the interval, `gap_curvature`)
/// counts as velocity it already has: an impulse that holds a curving gap
/// open does no work on the real motion, though the linear prediction of
/// the velocities says it does. A bounce a speculative contact deferred
/// (`IslandContact::approach`) gives back at most the energy its approach
/// lost then, `deferred`, which is allowed on top.
fn energy_guard(
    diag: &[f64],
    rows: &[Row],
    (v, w, bias, deferred): Velocities,
    p: Vec<f64>,
    stats: &mut SolveStats,
    safe_solves: impl FnOnce(&[f64]) -> Vec<(&'static str, Vec<f64>)>,
) -> Vec<f64> {
    let m = rows.len();
    let gain = |x: &[f64]| {
        let n = v.len();
        let (mut lin, mut ang) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
        let (mut dv, mut dw) = (vec![Vector3::zeros(); n], vec![Vector3::zeros(); n]);
        for (row, &pi) in rows.iter().zip(x) {
            row.apply(pi, &mut lin, &mut ang);
            row.change_velocities(pi, &mut dv, &mut dw);
        }
        let e: f64 = (0..n)
            .map(|i| lin[i].dot(&(v[i] + 0.5 * dv[i])) + ang[i].dot(&(w[i] + 0.5 * dw[i])))
            .sum::<f64>()
            + x.iter().zip(bias).map(|(pi, b)| pi * b).sum::<f64>();
        if e.is_finite() { e } else { f64::INFINITY }
    };
    // The kinetic energy the rows see: Σ ½ v_i² / A_ii.
    let vel: Vec<f64> = rows
        .iter()
        .zip(bias)
        .map(|(r, b)| r.velocity(v, w) + b)
        .collect();
    let scale: f64 = (0..m)
        .filter(|&i| diag[i] > 0.0)
        .map(|i| 0.5 * vel[i] * vel[i] / diag[i])
        .sum();
    let allowed = |x: &[f64]| gain(x) <= ENERGY_GAIN_ALLOWED * scale + deferred + 1e-12;
    if allowed(&p) {
        return p;
    }
    let added = gain(&p);
    // The first safe answer that passes; if none does (rounding), nothing
    // is applied this step.
    let (name, safe) = safe_solves(&vel)
        .into_iter()
        .find(|(_, x)| allowed(x))
        .unwrap_or(("nothing", vec![0.0; m]));
    stats.record_failure(
        m,
        format!("solution added {added:.3e} J of kinetic energy; {name} applied instead"),
    );
    safe
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::body::BodyId;
    use crate::contact::task::IslandBody;
    use nalgebra::Matrix3;

    /// A 1 kg body falling at 1 m/s onto the ground through two identical
    /// contacts (a redundant pair, so A is singular). The answer
    /// p = (X, 3 − X) with X = 1e14 pushes the body up at 2 m/s: +1.5 J.
    /// Its quadratic form pᵀJv + ½ pᵀAp sums terms of 1e28 whose rounding
    /// hides that; the guard must still reject it.
    #[test]
    fn energy_guard_rejects_huge_cancelling_impulses() {
        let body = |inv_mass: f64, velocity: Vector3<f64>| IslandBody {
            id: BodyId(0),
            inv_mass,
            inv_inertia: Matrix3::identity() * inv_mass,
            position: Vector3::zeros(),
            velocity,
            angular_velocity: Vector3::zeros(),
            external_dv: Vector3::zeros(),
            external_dw: Vector3::zeros(),
        };
        let bodies = [body(1.0, -Vector3::z()), body(0.0, Vector3::zeros())];
        let point = Vector3::new(0.0, 0.0, -0.5);
        let rows: Vec<Row> = (0..2)
            .map(|_| Row::new(&bodies, 0, 1, &point, Vector3::z()))
            .collect();
        let m = rows.len();
        let mut a = vec![0.0; m * m];
        for i in 0..m {
            for j in 0..m {
                a[i * m + j] = rows[i].coupling(&rows[j]);
            }
        }
        let v = [bodies[0].velocity, bodies[1].velocity];
        let w = [Vector3::zeros(); 2];
        let x = 1e14;
        let mut stats = SolveStats::default();
        let diag: Vec<f64> = (0..m).map(|i| a[i * m + i]).collect();
        let unbiased = [0.0; 2];
        let velocities = (&v[..], &w[..], &unbiased[..], 0.0);
        let p = energy_guard(
            &diag,
            &rows,
            velocities,
            vec![x, 3.0 - x],
            &mut stats,
            |vel| {
                solve_normal_rows(&a, m, vel, &[None, None])
                    .map(|p| vec![("the frictionless inelastic answer", p)])
                    .unwrap_or_default()
            },
        );
        assert_eq!(stats.failed, 1, "the guard let {p:?} through");
        // The safe answer stops the body (inelastic): net impulse 1 N s.
        assert!((p[0] + p[1] - 1.0).abs() < 1e-9, "{p:?}");
    }
}
