//! Solve time of the Dantzig LCP solver on random contact-like problems.
//!
//! For each size n, 20 problems A = J M⁻¹ Jᵀ, b = J v are built from random
//! cubes (one body per three contacts, masses 0.5–5 kg) touching each other or
//! the fixed floor at random points with random normals, velocities approaching.
//! The table gives the time per solve for the incremental LDLᵀ and for
//! refactor-each-pivot (hand-rolled, and with faer's LDLᵀ from 64 clamped rows);
//! the speed-up is the better refactor over incremental.
//!
//! Run: `cargo bench --bench lcp` (a `harness = false` main; prints a table).

use std::hint::black_box;
use std::time::{Duration, Instant};

use rigidsim::contact::lcp::{
    FAER_MIN_CLAMPED, Factorization, LcpOptions, LcpProblem, LcpWorkspace,
};

/// SplitMix64: fixed seeds, so every run times the same problems.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// A contact-like problem of n rows (row-major A, b).
fn contact_problem(n: usize, rng: &mut Rng) -> (Vec<f64>, Vec<f64>) {
    let bodies = n.div_ceil(3).max(1);
    // Per body: inverse mass, inverse inertia (cube of side 1: 6/m), velocity, spin.
    let inv_mass: Vec<f64> = (0..bodies).map(|_| 1.0 / rng.range(0.5, 5.0)).collect();
    let vel: Vec<[f64; 6]> = (0..bodies)
        .map(|_| std::array::from_fn(|_| rng.range(-1.0, 1.0)))
        .collect();
    // Jacobian rows: for each of the (up to two) bodies, [n, r × n] with sign.
    let mut j = vec![[0.0; 6]; 2 * n];
    let mut who = vec![[usize::MAX; 2]; n];
    for i in 0..n {
        let a = (rng.next() * bodies as f64) as usize % bodies;
        let b = if rng.next() < 0.3 || bodies == 1 {
            usize::MAX
        } else {
            (a + 1 + (rng.next() * (bodies - 1) as f64) as usize) % bodies
        };
        let mut normal = [rng.range(-0.3, 0.3), rng.range(-0.3, 0.3), 1.0];
        let len = normal.iter().map(|v| v * v).sum::<f64>().sqrt();
        normal.iter_mut().for_each(|v| *v /= len);
        let arm_a = [rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), -0.5];
        let arm_b = [rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), 0.5];
        let ra = cross(arm_a, normal);
        let rb = cross(arm_b, normal);
        j[2 * i] = [normal[0], normal[1], normal[2], ra[0], ra[1], ra[2]];
        j[2 * i + 1] = [-normal[0], -normal[1], -normal[2], -rb[0], -rb[1], -rb[2]];
        who[i] = [a, b];
    }
    let mut a = vec![0.0; n * n];
    let mut rhs = vec![0.0; n];
    for r in 0..n {
        for s in 0..n {
            let mut v = 0.0;
            for (p, &br) in who[r].iter().enumerate() {
                for (q, &bs) in who[s].iter().enumerate() {
                    if br != usize::MAX && br == bs {
                        let (jr, js) = (&j[2 * r + p], &j[2 * s + q]);
                        let lin: f64 = (0..3).map(|k| jr[k] * js[k]).sum();
                        let ang: f64 = (3..6).map(|k| jr[k] * js[k]).sum();
                        v += inv_mass[br] * (lin + 6.0 * ang);
                    }
                }
            }
            a[r * n + s] = v;
        }
        let mut vn = 0.0;
        for (p, &br) in who[r].iter().enumerate() {
            if br != usize::MAX {
                vn += (0..6).map(|k| j[2 * r + p][k] * vel[br][k]).sum::<f64>();
            }
        }
        // Mostly approaching contacts, as after a collision step.
        rhs[r] = vn - 0.5;
    }
    (a, rhs)
}

/// Seconds per solve over `problems` (the best of five rounds of at least
/// 40 ms each, to shrug off other work on a shared machine), and mean pivots.
fn time(problems: &[(Vec<f64>, Vec<f64>)], opts: &LcpOptions) -> (f64, f64) {
    let mut ws = LcpWorkspace::new();
    let mut best = f64::INFINITY;
    let mut pivots = 0.0;
    for _ in 0..5 {
        let start = Instant::now();
        let (mut solves, mut steps) = (0usize, 0usize);
        while solves < problems.len() || start.elapsed() < Duration::from_millis(40) {
            for (a, b) in problems {
                let p = LcpProblem::standard(a, b);
                match ws.solve(black_box(&p), opts) {
                    Ok(sol) => steps += sol.pivots,
                    Err(e) => panic!("benchmark problem failed: {e}"),
                }
                solves += 1;
            }
        }
        best = best.min(start.elapsed().as_secs_f64() / solves as f64);
        pivots = steps as f64 / solves as f64;
    }
    (best, pivots)
}

fn main() {
    let incremental = LcpOptions::default();
    let refactor = LcpOptions {
        factorization: Factorization::Refactor,
        faer_min_clamped: usize::MAX,
        ..incremental
    };
    let refactor_faer = LcpOptions {
        faer_min_clamped: FAER_MIN_CLAMPED,
        ..refactor
    };
    println!("Dantzig LCP, random contact-like problems (20 per size), time per solve");
    println!();
    println!(
        "| {:>4} | {:>7} | {:>16} | {:>16} | {:>20} | {:>8} |",
        "n", "pivots", "incremental (µs)", "refactor (µs)", "refactor, faer (µs)", "speed-up"
    );
    println!(
        "|{:-<6}|{:-<9}|{:-<18}|{:-<18}|{:-<22}|{:-<10}|",
        "", "", "", "", "", ""
    );
    for n in [4, 8, 16, 32, 64, 128] {
        let mut rng = Rng(n as u64);
        let problems: Vec<_> = (0..20).map(|_| contact_problem(n, &mut rng)).collect();
        let (t_inc, pivots) = time(&problems, &incremental);
        let (t_ref, _) = time(&problems, &refactor);
        let (t_faer, _) = time(&problems, &refactor_faer);
        println!(
            "| {:>4} | {:>7.1} | {:>16.2} | {:>16.2} | {:>20.2} | {:>7.1}× |",
            n,
            pivots,
            t_inc * 1e6,
            t_ref * 1e6,
            t_faer * 1e6,
            t_ref.min(t_faer) / t_inc
        );
    }
}
