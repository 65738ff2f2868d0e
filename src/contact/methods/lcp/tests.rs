use super::factor::{Factor, Mat, dot};

fn random_spd(n: usize, seed: u64) -> Vec<f64> {
    let mut state = seed;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 11) as f64 / (1u64 << 53) as f64) - 0.5
    };
    let g: Vec<f64> = (0..n * n).map(|_| next()).collect();
    let mut a = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..n {
            a[i * n + j] = (0..n).map(|k| g[k * n + i] * g[k * n + j]).sum::<f64>()
                + if i == j { 0.1 } else { 0.0 };
        }
    }
    a
}

/// L D Lᵀ of the factor, compared with A_CC.
fn reconstruct_error(f: &Factor, a: &[f64], n: usize, c: &[usize]) -> f64 {
    let m = f.m;
    let l = |i: usize, j: usize| {
        if i == j {
            1.0
        } else if i > j {
            f.ld[j * f.cap + i]
        } else {
            0.0
        }
    };
    let mut err = 0.0f64;
    for i in 0..m {
        for j in 0..m {
            let v: f64 = (0..m).map(|k| l(i, k) * f.d(k) * l(j, k)).sum();
            err = err.max((v - a[c[i] * n + c[j]]).abs());
        }
    }
    err
}

#[test]
fn ldlt_append_and_remove_match_a_fresh_factor() {
    for faer_min in [usize::MAX, 1] {
        let n = 12;
        let a = random_spd(n, 7);
        let mat = Mat { a: &a, n };
        let mut f = Factor::new();
        f.reserve(n, faer_min);
        let mut c: Vec<usize> = Vec::new();
        for k in [3, 0, 7, 11, 5, 2, 9, 1] {
            let m = c.len();
            let mut y: Vec<f64> = c.iter().map(|&j| a[k * n + j]).collect();
            y.resize(n, 0.0);
            f.forward(&mut y);
            let z: Vec<f64> = (0..m).map(|r| y[r] / f.d(r)).collect();
            let pivot = a[k * n + k] - dot(&y[..m], &z);
            f.append(&z, pivot);
            c.push(k);
        }
        assert!(reconstruct_error(&f, &a, n, &c) < 1e-12);
        for p in [2, 0, 4] {
            assert!(f.remove(p, 1e-300));
            c.remove(p);
            assert!(
                reconstruct_error(&f, &a, n, &c) < 1e-12,
                "faer_min {faer_min}"
            );
        }
        let mut g = Factor::new();
        g.reserve(n, faer_min);
        g.refactor(mat, &c, true, faer_min, 1e-300).unwrap();
        assert!(reconstruct_error(&g, &a, n, &c) < 1e-12);
    }
}

#[test]
fn lu_refactor_solves_a_non_symmetric_block() {
    let n = 5;
    let mut a = random_spd(n, 3);
    a[1] += 0.7;
    a[n + 3] -= 0.4;
    let c = [4, 1, 3, 0];
    let mut f = Factor::new();
    f.reserve(n, usize::MAX);
    f.refactor(Mat { a: &a, n }, &c, false, usize::MAX, 0.0)
        .unwrap();
    let rhs = [1.0, -2.0, 0.5, 3.0];
    let mut v: Vec<f64> = (0..4).map(|r| rhs[f.perm[r]]).collect();
    f.forward(&mut v);
    f.backward_upper(&mut v);
    for (i, &ci) in c.iter().enumerate() {
        let s: f64 = c
            .iter()
            .enumerate()
            .map(|(j, &cj)| a[ci * n + cj] * v[j])
            .sum();
        assert!((s - rhs[i]).abs() < 1e-12);
    }
}
