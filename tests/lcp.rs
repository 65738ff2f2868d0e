//! Tests of the Dantzig LCP solver (`contact::lcp`): the classic small LCPs,
//! redundant contact systems built from J M⁻¹ Jᵀ, friction rows, infeasible and
//! malformed input, and seeded random problems checked against clarabel's
//! convex QP optimum (for PSD A, the LCP w = A x + b ≥ 0, x ≥ 0, xᵀw = 0 is the
//! KKT system of min ½xᵀAx + bᵀx s.t. x ≥ 0, so the objectives must agree).

mod common;

use nalgebra::{DMatrix, Matrix3, Vector3};
use proptest::prelude::*;
use rigidsim::contact::lcp::{
    self, Factorization, LcpError, LcpOptions, LcpProblem, LcpSolution, LcpWorkspace,
};

/// SplitMix64: a seeded generator, so failures reproduce.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }
    /// Standard normal (Box–Muller).
    fn normal(&mut self) -> f64 {
        let u = self.uniform().max(1e-300);
        let v = self.uniform();
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

/// Row-major copy of a (possibly non-symmetric) nalgebra matrix.
fn row_major(m: &DMatrix<f64>) -> Vec<f64> {
    m.transpose().as_slice().to_vec()
}

/// Independent check of a solution: bounds (friction bounds from x), w = A x + b
/// and the three complementarity conditions, each scaled as documented in the
/// module (σ_i = |b_i| + Σ|A_ij x_j|, X = max|x|). Returns the worst violation.
fn violation(p: &LcpProblem, sol: &LcpSolution) -> f64 {
    common::lcp_violation(p, sol).unwrap_or_else(|e| panic!("{e}"))
}

fn assert_valid(p: &LcpProblem, sol: &LcpSolution) {
    let v = violation(p, sol);
    assert!(
        v <= 1e-9,
        "violation {v:e} (solver said {:e})",
        sol.max_violation
    );
    assert!(sol.max_violation <= 1e-9);
}

fn objective(a: &[f64], b: &[f64], x: &[f64]) -> f64 {
    let n = b.len();
    let mut f = 0.0;
    for i in 0..n {
        let ax: f64 = (0..n).map(|j| a[i * n + j] * x[j]).sum();
        f += 0.5 * x[i] * ax + b[i] * x[i];
    }
    f
}

#[test]
fn diagonal_one_to_nine_gives_reciprocals() {
    let n = 9;
    let mut a = vec![0.0; n * n];
    for i in 0..n {
        a[i * n + i] = (i + 1) as f64;
    }
    let b = vec![-1.0; n];
    let sol = lcp::solve_standard(&a, &b).unwrap();
    for i in 0..n {
        assert!(
            (sol.x[i] - 1.0 / (i + 1) as f64).abs() <= 1e-12,
            "x[{i}] = {}",
            sol.x[i]
        );
        assert!(sol.w[i].abs() <= 1e-12);
    }
    assert_valid(&LcpProblem::standard(&a, &b), &sol);
}

/// Murty's example: 1 on the diagonal, 2 strictly below, 0 above, b = −1. A is a
/// non-symmetric P-matrix (so the LU path is used); the solution is e₁. The
/// transposed variant (2 above) has solution e_n.
#[test]
fn murty_exponential_example_is_solved() {
    for n in 6..=10 {
        for lower in [true, false] {
            let mut a = vec![0.0; n * n];
            for i in 0..n {
                for j in 0..n {
                    a[i * n + j] = match (i == j, (i > j) == lower) {
                        (true, _) => 1.0,
                        (false, true) => 2.0,
                        (false, false) => 0.0,
                    };
                }
            }
            let b = vec![-1.0; n];
            let sol = lcp::solve_standard(&a, &b).unwrap();
            let one = if lower { 0 } else { n - 1 };
            for i in 0..n {
                let expect = if i == one { 1.0 } else { 0.0 };
                assert!(
                    (sol.x[i] - expect).abs() <= 1e-12,
                    "n {n} lower {lower}: {:?}",
                    sol.x
                );
            }
            assert_valid(&LcpProblem::standard(&a, &b), &sol);
        }
    }
}

/// Drake's degenerate case: A = ones(2,2), b = −1 has the solutions x₁ + x₂ = 1.
#[test]
fn drake_degenerate_ones_has_a_valid_solution() {
    let a = vec![1.0; 4];
    let b = vec![-1.0; 2];
    let sol = lcp::solve_standard(&a, &b).unwrap();
    assert!((sol.x[0] + sol.x[1] - 1.0).abs() <= 1e-12);
    assert!(sol.x.iter().all(|v| *v >= 0.0));
    assert!(sol.w.iter().all(|v| v.abs() <= 1e-12));
}

// ---------------------------------------------------------------- contact systems

/// A rigid body for building A = J M⁻¹ Jᵀ.
struct Body {
    inv_mass: f64,
    inv_inertia: Matrix3<f64>,
    centre: Vector3<f64>,
    velocity: Vector3<f64>,
    spin: Vector3<f64>,
}

/// A cube of side 1 and mass m (inertia m/6 · I) at `centre`.
fn cube(m: f64, centre: Vector3<f64>, velocity: Vector3<f64>, spin: Vector3<f64>) -> Body {
    Body {
        inv_mass: 1.0 / m,
        inv_inertia: Matrix3::identity() * (6.0 / m),
        centre,
        velocity,
        spin,
    }
}

/// One LCP row of a contact between body `a` and body `b` (None: the fixed
/// floor) at point p; `dir` is the unit normal (out of b towards a) for a normal
/// row, or a tangent for a friction row.
struct Row {
    a: usize,
    b: Option<usize>,
    p: Vector3<f64>,
    dir: Vector3<f64>,
}

/// A = J M⁻¹ Jᵀ and b = (1+e) J v for the given rows (SPEC eq. 3.9–3.15): A_ij is
/// the effect of a unit impulse along row j on the relative velocity along row i.
fn contact_system(bodies: &[Body], rows: &[Row], e: f64) -> (Vec<f64>, Vec<f64>) {
    let n = rows.len();
    let nb = bodies.len();
    let mut j = DMatrix::<f64>::zeros(n, 6 * nb);
    for (i, r) in rows.iter().enumerate() {
        for (body, sign) in [(Some(r.a), 1.0), (r.b, -1.0)] {
            if let Some(k) = body {
                let arm = (r.p - bodies[k].centre).cross(&r.dir);
                for c in 0..3 {
                    j[(i, 6 * k + c)] += sign * r.dir[c];
                    j[(i, 6 * k + 3 + c)] += sign * arm[c];
                }
            }
        }
    }
    let mut minv = DMatrix::<f64>::zeros(6 * nb, 6 * nb);
    let mut v = nalgebra::DVector::<f64>::zeros(6 * nb);
    for (k, body) in bodies.iter().enumerate() {
        for c in 0..3 {
            minv[(6 * k + c, 6 * k + c)] = body.inv_mass;
            v[6 * k + c] = body.velocity[c];
            v[6 * k + 3 + c] = body.spin[c];
            for d in 0..3 {
                minv[(6 * k + 3 + c, 6 * k + 3 + d)] = body.inv_inertia[(c, d)];
            }
        }
    }
    let a = &j * &minv * j.transpose();
    let a = (&a + a.transpose()) * 0.5;
    let b = (&j * v) * (1.0 + e);
    (row_major(&a), b.as_slice().to_vec())
}

/// The four bottom corners of a unit cube centred at c, as normal (+z) rows.
fn bottom_corners(a: usize, b: Option<usize>, c: Vector3<f64>) -> Vec<Row> {
    [(-0.5, -0.5), (0.5, -0.5), (-0.5, 0.5), (0.5, 0.5)]
        .iter()
        .map(|&(x, y)| Row {
            a,
            b,
            p: c + Vector3::new(x, y, -0.5),
            dir: Vector3::z(),
        })
        .collect()
}

#[test]
fn box_face_on_floor_takes_total_impulse_m_v_one_plus_e() {
    let (m, v, e) = (2.5, 3.0, 0.8);
    let bodies = [cube(
        m,
        Vector3::new(0.0, 0.0, 0.5),
        Vector3::new(0.0, 0.0, -v),
        Vector3::zeros(),
    )];
    for copies in [1, 2] {
        let rows: Vec<Row> = (0..copies)
            .flat_map(|_| bottom_corners(0, None, bodies[0].centre))
            .collect();
        let (a, b) = contact_system(&bodies, &rows, e);
        for factorization in [Factorization::Incremental, Factorization::Refactor] {
            let opts = LcpOptions {
                factorization,
                ..LcpOptions::default()
            };
            let p = LcpProblem::standard(&a, &b);
            let sol = LcpWorkspace::new().solve(&p, &opts).unwrap();
            let total: f64 = sol.x.iter().sum();
            let expect = m * v * (1.0 + e);
            assert!(
                (total - expect).abs() <= 1e-12 * expect,
                "{copies}×4 contacts: {total}"
            );
            assert!(sol.x.iter().all(|x| *x >= 0.0));
            assert!(sol.w.iter().all(|w| w.abs() <= 1e-12 * v));
            assert_valid(&p, &sol);
        }
    }
}

/// A spinning box lands on one edge: the impulse must remove the approach at
/// the low corners only; checked against the QP optimum.
#[test]
fn tumbling_box_on_floor_matches_qp_optimum() {
    let bodies = [cube(
        1.0,
        Vector3::new(0.0, 0.0, 0.5),
        Vector3::new(0.3, 0.0, -2.0),
        Vector3::new(0.0, 1.5, 0.2),
    )];
    let rows = bottom_corners(0, None, bodies[0].centre);
    let (a, b) = contact_system(&bodies, &rows, 0.5);
    let p = LcpProblem::standard(&a, &b);
    let sol = lcp::solve(&p).unwrap();
    assert_valid(&p, &sol);
    let Qp::Optimum(qp) = clarabel_qp(&a, &b) else {
        panic!("QP not solved")
    };
    let f = objective(&a, &b, &sol.x);
    assert!((f - qp).abs() <= 1e-6 * f.abs(), "{f} vs {qp}");
}

/// Ten unit boxes stacked on the floor, all falling at v: 40 contacts, rank 30.
/// The only solution stops the stack as one body, so the floor takes
/// 10 m v (1+e) and the interface under box k carries (10 − k) m v (1+e).
#[test]
fn stack_of_ten_boxes_takes_the_whole_stack_impulse() {
    let (m, v, e) = (1.5, 2.0, 0.3);
    let bodies: Vec<Body> = (0..10)
        .map(|k| {
            cube(
                m,
                Vector3::new(0.0, 0.0, 0.5 + k as f64),
                Vector3::new(0.0, 0.0, -v),
                Vector3::zeros(),
            )
        })
        .collect();
    let mut rows = bottom_corners(0, None, bodies[0].centre);
    for (k, body) in bodies.iter().enumerate().skip(1) {
        rows.extend(bottom_corners(k, Some(k - 1), body.centre));
    }
    let (a, b) = contact_system(&bodies, &rows, e);
    for faer_min_clamped in [lcp::FAER_MIN_CLAMPED, 1] {
        for factorization in [Factorization::Incremental, Factorization::Refactor] {
            let opts = LcpOptions {
                factorization,
                faer_min_clamped,
                ..LcpOptions::default()
            };
            let p = LcpProblem::standard(&a, &b);
            let sol = LcpWorkspace::new().solve(&p, &opts).unwrap();
            assert_valid(&p, &sol);
            assert!(sol.x.iter().all(|x| *x >= 0.0));
            for k in 0..10 {
                let level: f64 = sol.x[4 * k..4 * k + 4].iter().sum();
                let expect = (10 - k) as f64 * m * v * (1.0 + e);
                assert!(
                    (level - expect).abs() <= 1e-12 * expect,
                    "level {k}: {level} vs {expect} ({factorization:?}, faer from {faer_min_clamped})"
                );
            }
        }
    }
}

/// The same stack hit from the side and spinning: heavy degeneracy with an
/// uneven load; checked against the QP optimum.
#[test]
fn tumbling_stack_matches_qp_optimum() {
    let mut rng = Rng(99);
    let bodies: Vec<Body> = (0..10)
        .map(|k| {
            let vel = Vector3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-3.0, 0.0),
            );
            let spin = Vector3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            cube(
                rng.range(0.5, 5.0),
                Vector3::new(0.0, 0.0, 0.5 + k as f64),
                vel,
                spin,
            )
        })
        .collect();
    let mut rows = bottom_corners(0, None, bodies[0].centre);
    for (k, body) in bodies.iter().enumerate().skip(1) {
        rows.extend(bottom_corners(k, Some(k - 1), body.centre));
    }
    let (a, b) = contact_system(&bodies, &rows, 0.5);
    let p = LcpProblem::standard(&a, &b);
    let sol = lcp::solve(&p).unwrap();
    assert_valid(&p, &sol);
    let Qp::Optimum(qp) = clarabel_qp(&a, &b) else {
        panic!("QP not solved")
    };
    let f = objective(&a, &b, &sol.x);
    assert!((f - qp).abs() <= 1e-6 * f.abs(), "{f} vs {qp}");
}

// ---------------------------------------------------------------- boxed and friction rows

#[test]
fn one_dimensional_box_clamps_at_its_bounds() {
    let a = [2.0];
    for (b, x) in [
        (-1.0, 0.5),
        (1.0, -0.5),
        (-4.0, 1.0),
        (4.0, -1.0),
        (0.0, 0.0),
        (-2.0, 1.0),
    ] {
        let p = LcpProblem::boxed(&a, std::slice::from_ref(&b), &[-1.0], &[1.0]);
        let sol = lcp::solve(&p).unwrap();
        assert!((sol.x[0] - x).abs() <= 1e-15, "b = {b}: x = {}", sol.x[0]);
        assert_valid(&p, &sol);
    }
    // A singular 1-D box: w = b whatever x, so x goes to the bound w points away from.
    for (b, x) in [(-1.0, 1.0), (1.0, -1.0)] {
        let p = LcpProblem::boxed(&[0.0], std::slice::from_ref(&b), &[-1.0], &[1.0]);
        let sol = lcp::solve(&p).unwrap();
        assert_eq!(sol.x[0], x);
    }
}

/// A particle of mass m landing while sliding: one normal row, two friction rows
/// bounded by ±mu · normal impulse.
fn particle_friction(m: f64, mu: f64, v: Vector3<f64>) -> LcpSolution {
    let a = [1.0 / m, 0.0, 0.0, 0.0, 1.0 / m, 0.0, 0.0, 0.0, 1.0 / m];
    let b = [v.z, v.x, v.y];
    let lo = [0.0, -mu, -mu];
    let hi = [f64::INFINITY, mu, mu];
    let findex = [None, Some(0), Some(0)];
    let p = LcpProblem::boxed(&a, &b, &lo, &hi).with_friction(&findex);
    let sol = lcp::solve(&p).unwrap();
    assert_valid(&p, &sol);
    sol
}

#[test]
fn sliding_contact_friction_is_mu_normal_against_the_motion() {
    let (m, mu) = (2.0, 0.4);
    let sol = particle_friction(m, mu, Vector3::new(3.0, -2.0, -1.0));
    assert!((sol.x[0] - m * 1.0).abs() <= 1e-12);
    assert!(
        (sol.x[1] + mu * sol.x[0]).abs() <= 1e-12,
        "friction x {}",
        sol.x[1]
    );
    assert!(
        (sol.x[2] - mu * sol.x[0]).abs() <= 1e-12,
        "friction y {}",
        sol.x[2]
    );
    assert!(
        sol.w[1] > 0.0 && sol.w[2] < 0.0,
        "still sliding: {:?}",
        sol.w
    );
}

#[test]
fn sticking_contact_friction_stops_the_tangential_motion() {
    let (m, mu) = (2.0, 0.8);
    let sol = particle_friction(m, mu, Vector3::new(0.3, -0.2, -1.0));
    assert!((sol.x[1] + m * 0.3).abs() <= 1e-12);
    assert!((sol.x[2] - m * 0.2).abs() <= 1e-12);
    assert!(sol.w[1].abs() <= 1e-12 && sol.w[2].abs() <= 1e-12);
}

/// A box landing while sliding, four corners with two friction rows each: the
/// friction torque shifts load between the corners, so the normal impulses the
/// friction bounds depend on change while friction rows are driven, and the
/// solver must iterate to bounds consistent with the final normal impulses.
#[test]
fn sliding_box_friction_bounds_follow_the_final_normal_impulses() {
    let m = 3.0;
    for (mu, vx, sliding) in [(0.3, 4.0, true), (0.9, 0.2, false)] {
        let bodies = [cube(
            m,
            Vector3::new(0.0, 0.0, 0.5),
            Vector3::new(vx, 0.0, -1.0),
            Vector3::zeros(),
        )];
        let mut rows = bottom_corners(0, None, bodies[0].centre);
        let mut findex = vec![None; 4];
        for c in 0..4 {
            for t in [Vector3::x(), Vector3::y()] {
                rows.push(Row {
                    a: 0,
                    b: None,
                    p: rows[c].p,
                    dir: t,
                });
                findex.push(Some(c));
            }
        }
        let (a, b) = contact_system(&bodies, &rows, 0.0);
        let n = rows.len();
        let lo: Vec<f64> = (0..n).map(|i| if i < 4 { 0.0 } else { -mu }).collect();
        let hi: Vec<f64> = (0..n)
            .map(|i| if i < 4 { f64::INFINITY } else { mu })
            .collect();
        let p = LcpProblem::boxed(&a, &b, &lo, &hi).with_friction(&findex);
        let sol = lcp::solve(&p).unwrap();
        assert_valid(&p, &sol);
        let normal: f64 = sol.x[..4].iter().sum();
        let friction_x: f64 = (0..4).map(|c| sol.x[4 + 2 * c]).sum();
        if sliding {
            assert!(
                (friction_x + mu * normal).abs() <= 1e-9 * normal,
                "{friction_x} vs {normal}"
            );
        } else {
            assert!(
                (friction_x + m * vx).abs() <= 1e-9 * m * vx,
                "stopped: {friction_x}"
            );
        }
    }
}

/// A start (`LcpProblem::start`) changes the work, not the answer: on
/// the sliding and the sticking box with friction (12 rows, one corner
/// redundant), from the answer itself the first pass takes no pivot and
/// every row ends with the velocity of the answer from nothing; from the
/// answer of a box 10 % heavier (last step's, so to speak) the answer
/// verifies with fewer pivots than from nothing.
#[test]
fn a_start_changes_the_pivots_not_the_answer() {
    let m = 3.0;
    for (mu, vx) in [(0.3, 4.0), (0.9, 0.2)] {
        let system = |m: f64| {
            let bodies = [cube(
                m,
                Vector3::new(0.0, 0.0, 0.5),
                Vector3::new(vx, 0.0, -1.0),
                Vector3::new(0.0, 0.3, 0.0),
            )];
            let mut rows = bottom_corners(0, None, bodies[0].centre);
            let mut findex = vec![None; 4];
            for c in 0..4 {
                for t in [Vector3::x(), Vector3::y()] {
                    rows.push(Row {
                        a: 0,
                        b: None,
                        p: rows[c].p,
                        dir: t,
                    });
                    findex.push(Some(c));
                }
            }
            let (a, b) = contact_system(&bodies, &rows, 0.0);
            (a, b, findex)
        };
        let (a, b, findex) = system(m);
        let n = b.len();
        let lo: Vec<f64> = (0..n).map(|i| if i < 4 { 0.0 } else { -mu }).collect();
        let hi: Vec<f64> = (0..n)
            .map(|i| if i < 4 { f64::INFINITY } else { mu })
            .collect();
        let p = LcpProblem::boxed(&a, &b, &lo, &hi).with_friction(&findex);
        let fresh = lcp::solve(&p).unwrap();
        assert_valid(&p, &fresh);
        let started = lcp::solve(&p.with_start(&fresh.x)).unwrap();
        assert_valid(&p, &started);
        assert_eq!(started.pivots, 0, "mu {mu}: from the answer");
        for (i, (w0, w1)) in fresh.w.iter().zip(&started.w).enumerate() {
            assert!((w0 - w1).abs() <= 1e-12, "mu {mu}, row {i}: w {w0} vs {w1}");
        }
        let (a2, b2, _) = system(1.1 * m);
        let heavier =
            lcp::solve(&LcpProblem::boxed(&a2, &b2, &lo, &hi).with_friction(&findex)).unwrap();
        let near = lcp::solve(&p.with_start(&heavier.x)).unwrap();
        assert_valid(&p, &near);
        assert!(
            near.pivots < fresh.pivots,
            "mu {mu}: {} pivots from a near start, {} from nothing",
            near.pivots,
            fresh.pivots
        );
    }
}

// ---------------------------------------------------------------- errors

#[test]
fn negative_one_by_one_is_infeasible() {
    let err = lcp::solve_standard(&[-1.0], &[-1.0]).unwrap_err();
    assert_eq!(err, LcpError::Infeasible { size: 1, row: 0 });
    // w₀ = b₀ whatever x: unbounded ray, no solution.
    assert!(matches!(
        lcp::solve_standard(&[0.0, 0.0, 0.0, 1.0], &[-1.0, -1.0]),
        Err(LcpError::Infeasible { size: 2, row: 0 })
    ));
}

#[test]
fn non_finite_and_malformed_input_is_an_error() {
    let b = [-1.0, -1.0];
    let a = [1.0, 0.0, f64::NAN, 1.0];
    assert!(matches!(
        lcp::solve_standard(&a, &b),
        Err(LcpError::NonFinite {
            size: 2,
            what: "a",
            index: 2
        })
    ));
    let a = [1.0, 0.0, 0.0, 1.0];
    assert!(matches!(
        lcp::solve_standard(&a, &[f64::INFINITY, 0.0]),
        Err(LcpError::NonFinite { what: "b", .. })
    ));
    let bad_lo = LcpProblem::boxed(&a, &b, &[f64::NAN, 0.0], &[]);
    assert!(matches!(
        lcp::solve(&bad_lo),
        Err(LcpError::NonFinite { what: "lo", .. })
    ));
    let positive_lo = LcpProblem::boxed(&a, &b, &[0.5, 0.0], &[]);
    assert!(matches!(
        lcp::solve(&positive_lo),
        Err(LcpError::InvalidInput { .. })
    ));
    assert!(matches!(
        lcp::solve_standard(&a[..3], &b),
        Err(LcpError::InvalidInput { .. })
    ));
    let chain = [None, Some(1)];
    let p = LcpProblem::boxed(&a, &b, &[0.0, -0.5], &[1.0, 0.5]).with_friction(&chain);
    assert!(matches!(lcp::solve(&p), Err(LcpError::InvalidInput { .. })));
    let msg = LcpError::IterationLimit { size: 7, pivots: 3 }.to_string();
    assert!(msg.contains("7 rows"), "{msg}");
}

#[test]
fn pivot_limit_is_reported_not_looped() {
    let n = 8;
    let mut a = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            a[i * n + j] = if i == j {
                1.0
            } else if j > i {
                2.0
            } else {
                0.0
            };
        }
    }
    let b = vec![-1.0; n];
    let opts = LcpOptions {
        max_pivots: Some(3),
        ..LcpOptions::default()
    };
    let err = LcpWorkspace::new()
        .solve(&LcpProblem::standard(&a, &b), &opts)
        .unwrap_err();
    assert!(
        matches!(err, LcpError::IterationLimit { size: 8, .. }),
        "{err:?}"
    );
}

#[test]
fn empty_problem_is_solved() {
    let sol = lcp::solve_standard(&[], &[]).unwrap();
    assert!(sol.x.is_empty() && sol.w.is_empty());
}

// ---------------------------------------------------------------- random PSD vs clarabel

/// What clarabel says about min ½xᵀAx + bᵀx s.t. x ≥ 0.
#[derive(Debug)]
enum Qp {
    Optimum(f64),
    /// Unbounded below: then the LCP has no solution.
    Unbounded,
    /// Clarabel gave up (numerical error, iteration limit).
    Unresolved,
}

/// Solves the QP by clarabel's interior point method, first with tight
/// tolerances, then with its defaults if those stall.
fn clarabel_qp(a: &[f64], b: &[f64]) -> Qp {
    use clarabel::algebra::CscMatrix;
    use clarabel::solver::{
        DefaultSettingsBuilder, DefaultSolver, IPSolver, NonnegativeConeT, SolverStatus,
    };
    let n = b.len();
    let dense: Vec<Vec<f64>> = (0..n).map(|i| a[i * n..(i + 1) * n].to_vec()).collect();
    let p = CscMatrix::from(&dense);
    let neg_eye: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| if i == j { -1.0 } else { 0.0 }).collect())
        .collect();
    let cons = CscMatrix::from(&neg_eye);
    // Solve with b scaled to max|b| = 1 (x scales by 1/s, the objective by 1/s²),
    // so that clarabel's absolute gap tolerance means the same for every case.
    let s = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if s == 0.0 {
        return Qp::Optimum(0.0);
    }
    let q: Vec<f64> = b.iter().map(|v| v / s).collect();
    for tight in [true, false] {
        let mut settings = DefaultSettingsBuilder::default();
        settings.verbose(false).max_iter(400);
        if tight {
            settings
                .tol_gap_abs(1e-12)
                .tol_gap_rel(1e-11)
                .tol_feas(1e-11);
        }
        let settings = settings.build().unwrap();
        let mut solver = DefaultSolver::new(
            &p,
            &q,
            &cons,
            &vec![0.0; n],
            &[NonnegativeConeT(n)],
            settings,
        )
        .unwrap();
        solver.solve();
        match solver.solution.status {
            SolverStatus::Solved => return Qp::Optimum(solver.solution.obj_val * s * s),
            SolverStatus::DualInfeasible => return Qp::Unbounded,
            _ => {}
        }
    }
    Qp::Unresolved
}

#[derive(Clone, Copy, Debug)]
enum Family {
    FullRank,
    RankDeficient,
    Condition1e12,
    ZeroRows,
    Contacts,
}

/// A random symmetric PSD problem (n = 2..20) of the given family.
fn random_psd(rng: &mut Rng, family: Family) -> (Vec<f64>, Vec<f64>) {
    let n = 2 + rng.below(19);
    let gram = |rng: &mut Rng, k: usize| {
        let g = DMatrix::from_fn(k, n, |_, _| rng.normal());
        g.transpose() * g
    };
    let mut a = match family {
        Family::FullRank | Family::ZeroRows => gram(rng, n + 2),
        Family::RankDeficient => {
            let k = 1 + rng.below(n - 1);
            gram(rng, k)
        }
        Family::Condition1e12 => {
            let q = DMatrix::from_fn(n, n, |_, _| rng.normal()).qr().q();
            let l = DMatrix::from_diagonal(&nalgebra::DVector::from_fn(n, |i, _| {
                10f64.powf(-12.0 * i as f64 / (n - 1) as f64)
            }));
            &q * l * q.transpose()
        }
        Family::Contacts => {
            let nb = 1 + rng.below(4);
            let bodies: Vec<Body> = (0..nb)
                .map(|k| {
                    let vel = Vector3::from_fn(|_, _| rng.range(-1.0, 1.0));
                    let spin = Vector3::from_fn(|_, _| rng.range(-1.0, 1.0));
                    cube(
                        rng.range(0.2, 20.0),
                        Vector3::new(k as f64, 0.0, 0.0),
                        vel,
                        spin,
                    )
                })
                .collect();
            let rows: Vec<Row> = (0..n)
                .map(|_| {
                    let a = rng.below(nb);
                    let b = if rng.uniform() < 0.3 || nb == 1 {
                        None
                    } else {
                        Some((a + 1) % nb)
                    };
                    let dir = Vector3::from_fn(|_, _| rng.normal()).normalize();
                    let p = bodies[a].centre + Vector3::from_fn(|_, _| rng.range(-0.5, 0.5));
                    Row { a, b, p, dir }
                })
                .collect();
            let e = rng.uniform();
            return contact_system(&bodies, &rows, e);
        }
    };
    if let Family::ZeroRows = family {
        for _ in 0..1 + rng.below(n / 2 + 1) {
            let k = rng.below(n);
            a.row_mut(k).fill(0.0);
            a.column_mut(k).fill(0.0);
        }
    }
    let a = (&a + a.transpose()) * 0.5;
    let scale = 10f64.powf(rng.range(-3.0, 3.0));
    let b: Vec<f64> = if let Family::Condition1e12 = family {
        // A planted solution x* ⟂ w* ≥ 0 and b = w* − A x*: a random b would put
        // x near 1e12 |b| along the weak eigenvectors, where clarabel's own
        // tolerances (not the LCP) decide the answer.
        let planted = nalgebra::DVector::from_fn(n, |_, _| {
            if rng.uniform() < 0.5 {
                rng.uniform() * scale
            } else {
                0.0
            }
        });
        let ax = &a * &planted;
        (0..n)
            .map(|i| {
                let w = if planted[i] > 0.0 {
                    0.0
                } else {
                    rng.uniform() * scale
                };
                w - ax[i]
            })
            .collect()
    } else {
        (0..n).map(|_| rng.normal() * scale).collect()
    };
    (row_major(&a), b)
}

/// 700 seeded random PSD problems (n = 2..20): every solution satisfies the
/// conditions to 1e-9 and its objective matches clarabel's optimum to 1e-6
/// relative; the solver calls a problem infeasible exactly when clarabel finds
/// the QP unbounded below. At least 500 cases must be compared.
#[test]
fn random_psd_problems_match_the_qp_optimum() {
    let families = [
        Family::FullRank,
        Family::RankDeficient,
        Family::Condition1e12,
        Family::ZeroRows,
        Family::Contacts,
    ];
    let mut rng = Rng(2024);
    let mut ws = LcpWorkspace::new();
    let (mut solved, mut infeasible, mut unresolved) = (0, 0, 0);
    for case in 0..700 {
        let family = families[case % families.len()];
        let (a, b) = random_psd(&mut rng, family);
        let p = LcpProblem::standard(&a, &b);
        let result = ws.solve(&p, &LcpOptions::default());
        match (result, clarabel_qp(&a, &b)) {
            (Ok(sol), Qp::Optimum(f_qp)) => {
                assert_valid(&p, &sol);
                let f = objective(&a, &b, &sol.x);
                // 1e-6 relative, with an absolute floor for optima near 0 at the
                // size clarabel's own gap tolerance leaves: 1e-9 · |b|² / max|A|.
                let amax = a.iter().fold(1e-300f64, |m, v| m.max(v.abs()));
                let floor = 1e-9 * b.iter().map(|v| v * v).sum::<f64>() / amax;
                assert!(
                    (f - f_qp).abs() <= 1e-6 * f.abs().max(f_qp.abs()) + floor,
                    "case {case} ({family:?}, n = {}): LCP {f} vs QP {f_qp}",
                    b.len()
                );
                solved += 1;
            }
            (Err(LcpError::Infeasible { .. }), Qp::Unbounded) => infeasible += 1,
            (Ok(sol), Qp::Unresolved) => {
                assert_valid(&p, &sol);
                unresolved += 1;
            }
            (got, qp) => panic!(
                "case {case} ({family:?}, n = {}): {got:?} vs QP {qp:?}",
                b.len()
            ),
        }
    }
    println!("solved {solved}, infeasible {infeasible}, clarabel unresolved {unresolved}");
    assert!(
        solved + infeasible >= 500,
        "solved {solved} infeasible {infeasible}"
    );
    assert!(
        unresolved <= 14,
        "clarabel unresolved on {unresolved} cases"
    );
}

/// Incremental LDLᵀ, refactor-each-pivot and the faer kernels follow the same
/// pivots: the same solution to rounding.
#[test]
fn factorisation_strategies_agree() {
    let mut rng = Rng(7);
    let mut ws = LcpWorkspace::new();
    for case in 0..100 {
        let family = if case % 2 == 0 {
            Family::FullRank
        } else {
            Family::Contacts
        };
        let (a, b) = random_psd(&mut rng, family);
        let p = LcpProblem::standard(&a, &b);
        let Ok(base) = ws.solve(&p, &LcpOptions::default()) else {
            continue;
        };
        for (factorization, faer_min_clamped) in [
            (Factorization::Refactor, 64),
            (Factorization::Incremental, 1),
            (Factorization::Refactor, 1),
        ] {
            let opts = LcpOptions {
                factorization,
                faer_min_clamped,
                ..LcpOptions::default()
            };
            let sol = ws.solve(&p, &opts).unwrap();
            assert_valid(&p, &sol);
            let f0 = objective(&a, &b, &base.x);
            let f1 = objective(&a, &b, &sol.x);
            assert!(
                (f0 - f1).abs() <= 1e-9 * f0.abs().max(1e-300),
                "case {case}: {f0} vs {f1}"
            );
        }
    }
}

#[test]
fn large_problems_use_faer_and_verify() {
    let mut rng = Rng(11);
    let mut ws = LcpWorkspace::new();
    for n in [64, 100, 128] {
        let g = DMatrix::from_fn(n + 10, n, |_, _| rng.normal());
        let a = row_major(&(g.transpose() * g));
        let b: Vec<f64> = (0..n).map(|_| rng.normal() - 0.5).collect();
        let p = LcpProblem::standard(&a, &b);
        let sol = ws.solve(&p, &LcpOptions::default()).unwrap();
        assert_valid(&p, &sol);
        let Qp::Optimum(f_qp) = clarabel_qp(&a, &b) else {
            panic!("QP not solved")
        };
        let f = objective(&a, &b, &sol.x);
        assert!((f - f_qp).abs() <= 1e-6 * f.abs(), "n {n}: {f} vs {f_qp}");
    }
}

// ---------------------------------------------------------------- fuzz: never NaN, never panic

/// Random matrices of every kind (PSD, rank-deficient with duplicate rows,
/// symmetric indefinite, non-symmetric, zero rows, sparse integer), random
/// bounds and friction rows: the solver either returns a solution that passes
/// the independent check or an error; it never panics and never returns NaN.
fn fuzz_case(seed: u64) {
    let mut rng = Rng(seed);
    let n = 1 + rng.below(12);
    let kind = rng.below(6);
    let mut a = DMatrix::from_fn(n, n, |_, _| rng.normal());
    match kind {
        0 => a = a.transpose() * &a,
        1 => {
            let k = 1 + rng.below(n);
            let g = DMatrix::from_fn(k, n, |_, _| rng.normal());
            a = g.transpose() * g;
            if n > 1 {
                let (i, j) = (rng.below(n), rng.below(n));
                let ri = a.row(i).clone_owned();
                a.set_row(j, &ri);
                let ci = a.column(i).clone_owned();
                a.set_column(j, &ci);
            }
        }
        2 => a = (&a + a.transpose()) * 0.5,
        3 => {}
        4 => {
            a = a.transpose() * &a;
            let k = rng.below(n);
            a.row_mut(k).fill(0.0);
            a.column_mut(k).fill(0.0);
        }
        _ => a = a.map(|v| if v.abs() < 0.8 { 0.0 } else { v.round() }),
    }
    let a = row_major(&a);
    let b: Vec<f64> = (0..n)
        .map(|_| {
            if rng.uniform() < 0.2 {
                0.0
            } else {
                rng.normal()
            }
        })
        .collect();
    let mut lo = vec![0.0; n];
    let mut hi = vec![f64::INFINITY; n];
    let mut findex = vec![None; n];
    for i in 0..n {
        match rng.below(5) {
            0 => {
                lo[i] = -rng.range(0.0, 2.0);
                hi[i] = rng.range(0.0, 2.0);
            }
            1 => lo[i] = f64::NEG_INFINITY,
            2 if i > 0 => {
                let mu = rng.range(0.0, 1.5);
                lo[i] = -mu;
                hi[i] = mu;
                findex[i] = Some(rng.below(i));
            }
            _ => {}
        }
    }
    // Friction rows may not point at friction rows.
    for i in 0..n {
        if findex[i].is_some_and(|j| findex[j].is_some()) {
            findex[i] = None;
            lo[i] = 0.0;
            hi[i] = f64::INFINITY;
        }
    }
    let p = LcpProblem::boxed(&a, &b, &lo, &hi).with_friction(&findex);
    let answer = match lcp::solve(&p) {
        Ok(sol) => {
            assert_valid(&p, &sol);
            Some(sol.x)
        }
        Err(e) => {
            assert!(!e.to_string().is_empty());
            None
        }
    };
    // From a start (`LcpProblem::start`): a random guess, and the answer
    // itself. Either a valid answer or an error, as from nothing.
    let guess: Vec<f64> = (0..n)
        .map(|_| {
            if rng.uniform() < 0.3 {
                0.0
            } else {
                rng.normal()
            }
        })
        .collect();
    for start in [Some(guess), answer].into_iter().flatten() {
        let p = p.with_start(&start);
        match lcp::solve(&p) {
            Ok(sol) => assert_valid(&p, &sol),
            Err(e) => assert!(!e.to_string().is_empty()),
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 2000, ..ProptestConfig::default() })]
    #[test]
    fn fuzzed_problems_never_panic_or_return_nan(seed in any::<u64>()) {
        fuzz_case(seed);
    }
}

/// Reusing one workspace across sizes gives the same answers as fresh ones.
#[test]
fn workspace_reuse_across_sizes_is_clean() {
    let mut rng = Rng(5);
    let mut ws = LcpWorkspace::new();
    let mut out = LcpSolution::default();
    for case in 0..60 {
        let (a, b) = random_psd(&mut rng, Family::FullRank);
        let p = LcpProblem::standard(&a, &b);
        ws.solve_into(&p, &LcpOptions::default(), &mut out).unwrap();
        let fresh = lcp::solve(&p).unwrap();
        assert_eq!(out.x, fresh.x, "case {case}");
    }
}
