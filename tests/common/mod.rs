//! Shared helpers for the tests: scenes from TOML text, stepping, the
//! bundled scenes and the binary run directly.
#![allow(dead_code)]

use rigidsim::contact::lcp::{LcpProblem, LcpSolution};
use rigidsim::scene;
use rigidsim::step::{Inline, World};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

pub fn world(toml: &str) -> World {
    let scene = scene::from_str(toml, Path::new("test.toml"), Path::new("."))
        .unwrap_or_else(|e| panic!("{e}"));
    World::new(scene)
}

/// Steps until `time` (seconds) has been reached.
pub fn run_until(w: &mut World, exec: &mut Inline, time: f64) {
    while w.time() < time - 1e-9 {
        w.step(exec).unwrap_or_else(|e| panic!("{e}"));
    }
}

pub const FLOOR: &str = r#"
[objects.floor]
shape = { box = { half_extents = [5.0, 5.0, 0.1] } }
mass = 1.0
restitution = 1.0
friction = 0.0

[[bodies]]
object = "floor"
position = [0.0, 0.0, -0.1]
fixed = true
"#;

/// Independent check of an LCP solution (tests/lcp.rs, tests/fuzz_input.rs):
/// w = A x + b,
/// bounds (friction bounds from x), and the complementarity conditions,
/// each scaled by σ_i = |b_i| + Σ_j |A_ij x_j| and X = max |x|.
pub fn lcp_violation(p: &LcpProblem, sol: &LcpSolution) -> Result<f64, String> {
    let n = p.size();
    if sol.x.len() != n || sol.w.len() != n {
        return Err("wrong solution size".into());
    }
    if !sol.x.iter().chain(&sol.w).all(|v| v.is_finite()) {
        return Err("NaN or infinity in the solution".into());
    }
    let xs = sol.x.iter().fold(f64::MIN_POSITIVE, |m, v| m.max(v.abs()));
    let mut worst = 0.0f64;
    for i in 0..n {
        let mut w = p.b[i];
        let mut s = p.b[i].abs();
        for j in 0..n {
            w += p.a[i * n + j] * sol.x[j];
            s += (p.a[i * n + j] * sol.x[j]).abs();
        }
        if (w - sol.w[i]).abs() > 1e-12 * s {
            return Err(format!("w[{i}] = {} but A x + b = {w}", sol.w[i]));
        }
        let (mut lo, mut hi) = (
            p.lo.get(i).copied().unwrap_or(0.0),
            p.hi.get(i).copied().unwrap_or(f64::INFINITY),
        );
        if let Some(Some(j)) = p.findex.get(i) {
            lo *= sol.x[*j].abs();
            hi *= sol.x[*j].abs();
        }
        let x = sol.x[i];
        worst = worst.max((lo - x).max(x - hi).max(0.0) / xs);
        if lo < hi && w != 0.0 {
            let c = if w > 0.0 {
                (w / s).min((x - lo) / xs)
            } else {
                (-w / s).min((hi - x) / xs)
            };
            worst = worst.max(c);
        }
    }
    Ok(worst)
}

/// A scene of `scenes/`.
pub fn bundled(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("scenes")
        .join(name)
}

/// The binary run directly, without mpirun, no standard input.
pub fn rigidsim(args: &[&str]) -> Output {
    command(env!("CARGO_BIN_EXE_rigidsim"))
        .args(args)
        .output()
        .expect("cannot start rigidsim")
}

/// `program` (the binary, or a launcher of it) as the tests start it: no
/// standard input, and Open MPI's consent to root. `run` initialises MPI
/// even alone, and Open MPI refuses root without these two variables.
pub fn command(program: &str) -> Command {
    let mut cmd = Command::new(program);
    cmd.env("OMPI_ALLOW_RUN_AS_ROOT", "1")
        .env("OMPI_ALLOW_RUN_AS_ROOT_CONFIRM", "1")
        .stdin(Stdio::null());
    cmd
}
