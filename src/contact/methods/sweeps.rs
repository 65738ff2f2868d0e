//! Projected Gauss–Seidel on a contact system: the sequential impulses on
//! its rows (with the subspace step), and the last resort on its dense
//! matrix.

use super::subspace;
use crate::contact::system::NO_RESPONSE;
use crate::contact::system::{IterativeSystem, Step};

/// How the sequential impulses check their answer and take the subspace
/// step (`sequential_impulses`).
#[derive(Clone, Copy, Debug)]
pub struct SweepSettings {
    /// Sweeps between checks of the conditions, each check followed by a
    /// subspace step where one is left, as a check costs about one sweep.
    pub check_every: usize,
    /// Subspace steps per solve at most, as each costs a sparse
    /// factorisation of the free rows.
    pub subspace_steps: usize,
    /// Rejected subspace steps in a row after which the solve goes on with
    /// sweeps alone, as where the pushing set keeps changing (friction in a
    /// settling pile) every step is rejected.
    pub subspace_rejections: usize,
}

impl Default for SweepSettings {
    fn default() -> Self {
        SweepSettings {
            check_every: 8,
            subspace_steps: 32,
            subspace_rejections: 3,
        }
    }
}

/// Projected Gauss–Seidel on w = (A + c·diag) p + b without forming A
/// (Erleben's "sequential impulses", Box2D's and Bullet's solver): each row
/// in turn takes the impulse that zeroes its w, clamped to its bounds (a
/// friction row's to ± its coefficient times its normal row's impulse), and
/// the bodies' velocity changes carry it to the other rows. O(rows) a sweep.
/// After every `check_every` sweeps (`settings`) that did not meet the
/// conditions, the subspace step (`subspace`) solves the rows strictly
/// inside their bounds together; the sweeps find which rows push, the step
/// carries the load through them at once.
///
/// It starts from `warm` (clamped to the bounds): the impulses the same
/// contacts took in their last solve. A pile or a stack at rest needs
/// nearly the same impulses every step, so the sweeps start with the right
/// rows pushing. Returns the impulses and whether they meet the LCP's
/// conditions to the system's tolerance (`IterativeSystem::tolerance`),
/// and the sweeps it took.
pub(crate) fn sequential_impulses(
    system: &IterativeSystem,
    warm: &[f64],
    bodies: usize,
    max_sweeps: usize,
    settings: &SweepSettings,
) -> (Vec<f64>, bool, u32) {
    let mut state = system.warm_state(warm, bodies);
    let by_body = subspace::rows_by_body(system.rows, bodies);
    // A warm start already frees the rows that pushed in the last solve:
    // the subspace step comes first, before any sweep. A stack at rest then
    // meets the conditions at once, where eight sweeps first only re-found
    // the free rows it had (the stack of 50: half the sweeps, half the
    // solve time). Without one (an impact), the sweeps find them first.
    let warm_started = state.p.iter().any(|&x| x != 0.0);
    let mut tries = subspace::Tries::new(settings.subspace_steps, settings.subspace_rejections);
    for sweep in 0..max_sweeps {
        if sweep % settings.check_every == 0 {
            if system.met(&state) {
                return (state.p, true, sweep as u32);
            }
            let may_step = sweep > 0 || warm_started;
            if may_step && tries.may_try() {
                let step = subspace::step(system, &by_body, &mut state);
                if matches!(step, Step::Kept) && system.met(&state) {
                    return (state.p, true, sweep as u32);
                }
                tries.record(&step);
            }
        }
        system.sweep(&mut state);
    }
    let met = system.met(&state);
    (state.p, met, max_sweeps as u32)
}

/// Last-resort fallback: projected Gauss–Seidel on the boxed LCP.
/// Converges for positive semidefinite A; used only after a reported failure.
pub fn projected_gauss_seidel(
    a: &[f64],
    m: usize,
    b: &[f64],
    lo: &[f64],
    hi: &[f64],
    findex: &[Option<usize>],
) -> Vec<f64> {
    let mut x = vec![0.0; m];
    for _ in 0..200 {
        for i in 0..m {
            let aii = a[i * m + i];
            if aii <= NO_RESPONSE {
                continue;
            }
            let r: f64 = b[i] + (0..m).map(|j| a[i * m + j] * x[j]).sum::<f64>();
            let mut xi = x[i] - r / aii;
            xi = match findex[i] {
                None => xi.clamp(lo[i], hi[i]),
                Some(k) => xi.clamp(lo[i] * x[k].abs(), hi[i] * x[k].abs()),
            };
            x[i] = if xi.is_finite() { xi } else { 0.0 };
        }
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contact::system::{ITERATIVE_COMPLIANCE, Row};
    use crate::contact::task::{fixed_body, stacked_cube};
    use nalgebra::Vector3;

    /// A frictionless stack of `n` 1 kg bodies on a fixed floor in the
    /// resting phase (every body about to fall g·h), solved by sequential
    /// impulses from `warm` (a share of the exact answer). Returns the
    /// impulses, whether they met the conditions, and the exact answer: the
    /// impulse under the k-th body from the top is k·m·g·h.
    fn stack(n: usize, warm: f64) -> (Vec<f64>, bool, Vec<f64>, Vec<f64>) {
        let (g, h) = (9.81, 0.01);
        let mut bodies = vec![fixed_body(Vector3::zeros())];
        for k in 1..=n {
            bodies.push(stacked_cube(k, Vector3::new(0.0, 0.0, -g * h)));
        }
        // Contact k joins body k + 1 (above, A) to body k (below, B).
        let rows: Vec<Row> = (0..n)
            .map(|k| {
                let point = Vector3::new(0.0, 0.0, k as f64);
                Row::new(&bodies, k + 1, k, &point, Vector3::z())
            })
            .collect();
        let v: Vec<Vector3<f64>> = bodies.iter().map(|b| b.velocity).collect();
        let w = vec![Vector3::zeros(); bodies.len()];
        let b: Vec<f64> = rows.iter().map(|r| r.velocity(&v, &w)).collect();
        let diag: Vec<f64> = rows.iter().map(|r| r.coupling(r)).collect();
        let exact: Vec<f64> = (0..n).map(|k| (n - k) as f64 * g * h).collect();
        let start: Vec<f64> = exact.iter().map(|x| x * warm).collect();
        // The answer of the compliant system the solve meets, with every
        // contact pushing: (A + c·diag) p = −b.
        let compliant = nalgebra::DMatrix::from_fn(n, n, |i, j| {
            rows[i].coupling(&rows[j])
                + if i == j {
                    ITERATIVE_COMPLIANCE * diag[i]
                } else {
                    0.0
                }
        });
        let compliant: Vec<f64> = compliant
            .lu()
            .solve(&-nalgebra::DVector::from_column_slice(&b))
            .expect("a compliant stack is regular")
            .iter()
            .copied()
            .collect();
        let (lo, hi, findex) = (vec![0.0; n], vec![f64::INFINITY; n], vec![None; n]);
        let system = IterativeSystem::new(&rows, &diag, &b, &lo, &hi, &findex);
        // The chain's budget for a solve from the last impulses
        // (`SolverSettings::iterative_sweeps`).
        let (p, met, _) = sequential_impulses(
            &system,
            &start,
            bodies.len(),
            1000,
            &SweepSettings::default(),
        );
        (p, met, exact, compliant)
    }

    /// From zero, five bodies: the answer meets the conditions (it stops
    /// there) and every impulse is right to 1e-5.
    #[test]
    fn sequential_impulses_hold_a_stack_exactly() {
        let (p, met, exact, _) = stack(5, 0.0);
        for (k, (pk, ek)) in p.iter().zip(&exact).enumerate() {
            assert!((pk - ek).abs() <= 1e-5 * ek, "contact {k}: {pk} vs {ek}");
        }
        assert!(met);
    }

    /// A stack of 100, from zero, from the exact answer and from 0.1 % short
    /// of it. Sweeps alone pass a load one contact per sweep (the bottom
    /// impulse was still far from 100·m·g·h after 1000 sweeps from zero);
    /// with the subspace step the rows that push are solved together: every
    /// start meets the conditions within 1e-5 of k·m·g·h, and the start
    /// from zero ends at the compliant system's answer to 1e-9 (the exact
    /// start already meets the conditions and is kept). The compliance
    /// costs the answer up to 1e-5 of k·m·g·h: a
    /// 100-body chain's smallest eigenvalue is about 2.5e-4 of its diagonal,
    /// so c = 1e-9 moves the load by c / 2.5e-4 ≈ 4e-6.
    #[test]
    fn subspace_step_carries_a_tall_stack_from_any_start() {
        for warm in [0.0, 1.0, 0.999] {
            let (p, met, exact, compliant) = stack(100, warm);
            assert!(met, "start {warm}: bottom {} of {}", p[0], exact[0]);
            for k in 0..100 {
                let (pk, ck, ek) = (p[k], compliant[k], exact[k]);
                assert!(
                    (pk - ek).abs() <= 1e-5 * ek,
                    "start {warm}, contact {k}: {pk} vs {ek}"
                );
                if warm == 0.0 {
                    assert!((pk - ck).abs() <= 1e-9 * ck, "contact {k}: {pk} vs {ck}");
                }
            }
        }
    }
}
