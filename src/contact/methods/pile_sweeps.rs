//! The large-island method: projected Gauss–Seidel sweeps over the rows of
//! an island of many moving bodies (a pile), warm-started from the impulses
//! its contacts held in their last solve, within a fixed budget of sweeps.
//! Its work grows with the rows times the sweeps. It stops early where its
//! answer meets the LCP's conditions, and once the sweeps have found which
//! rows push (the same free rows at two checks in a row, or a warm start
//! already that close) it tries the subspace step, which carries a resting
//! stack's load through those rows at once.
//!
//! A settling pile's island does not meet the conditions in any affordable
//! number of sweeps, nor by the interior point (it missed 31 of 32 solves
//! of the bin's 4 300-row islands, at 0.1–0.3 s each); this method ends
//! such a solve at its budget, missing the conditions by millimetres a
//! second on a few rows, which the next step's overlap recovery mends.

use super::block_sweeps::BlockSweeps;
use super::subspace;
use crate::contact::system::{IterativeState, IterativeSystem, Step};

/// The large-island method's settings.
#[derive(Clone, Copy, Debug)]
pub struct PileSweepSettings {
    /// Sweeps at most: 200 keep a settling bin's 2 400-row solve near
    /// 7 ms and leave its parts still enough to come to rest.
    pub max_sweeps: usize,
    /// Sweeps between checks of the conditions (a check costs about a
    /// sweep).
    pub check_every: usize,
    /// How far (m/s) a warm start may miss the conditions for the subspace
    /// step to be tried before any sweep: a standing stack's last impulses
    /// miss by less, a settling pile's by far more.
    pub warm_within: f64,
    /// Subspace steps per solve at most, and rejected steps in a row after
    /// which the solve goes on with sweeps alone (each costs a sparse
    /// factorisation of the free rows).
    pub subspace_steps: usize,
    pub subspace_rejections: usize,
}

impl Default for PileSweepSettings {
    fn default() -> Self {
        PileSweepSettings {
            max_sweeps: 200,
            check_every: 10,
            warm_within: 1e-4,
            subspace_steps: 32,
            subspace_rejections: 3,
        }
    }
}

/// What a solve by this method gave: the impulses, whether they meet the
/// conditions, the sweeps taken.
pub(crate) struct PileAnswer {
    pub(crate) p: Vec<f64>,
    pub(crate) met: bool,
    pub(crate) sweeps: u32,
}

/// How the method sweeps: the island's rows in order, or by blocks that
/// ranks may share (`block_sweeps`).
pub(crate) enum Sweeping<'r> {
    Whole,
    Blocks(BlockSweeps<'r>),
}

impl Sweeping<'_> {
    fn sweep(&mut self, system: &IterativeSystem, state: &mut IterativeState, sweeps: usize) {
        match self {
            Sweeping::Whole => {
                for _ in 0..sweeps {
                    system.sweep(state);
                }
            }
            Sweeping::Blocks(blocks) => blocks.sweep(system, state, sweeps),
        }
    }
}

/// Solves `system` by sweeps from `warm` (`bodies`: the island's bodies).
pub(crate) fn solve(
    system: &IterativeSystem,
    warm: &[f64],
    bodies: usize,
    settings: &PileSweepSettings,
    mut sweeping: Sweeping,
) -> PileAnswer {
    let mut state = system.warm_state(warm, bodies);
    let by_body = subspace::rows_by_body(system.rows, bodies);
    let mut subspace_tries =
        subspace::Tries::new(settings.subspace_steps, settings.subspace_rejections);
    let mut last_free = None;
    let mut sweep = 0;
    loop {
        if sweep % settings.check_every == 0 {
            let miss = system.worst_miss(&state);
            if miss <= system.tolerance {
                return PileAnswer {
                    p: state.p,
                    met: true,
                    sweeps: sweep as u32,
                };
            }
            let free = free_rows(system, &state);
            let found = last_free.as_ref() == Some(&free) && free.iter().any(|&f| f);
            let warm_close = sweep == 0 && miss <= settings.warm_within;
            last_free = Some(free);
            if (found || warm_close) && subspace_tries.may_try() {
                let step = subspace::step(system, &by_body, &mut state);
                let kept = matches!(step, Step::Kept);
                if kept && system.met(&state) {
                    return PileAnswer {
                        p: state.p,
                        met: true,
                        sweeps: sweep as u32,
                    };
                }
                subspace_tries.record(&step);
            }
        }
        if sweep >= settings.max_sweeps {
            break;
        }
        // Up to the next check, or the budget.
        let to_check = settings.check_every - sweep % settings.check_every;
        let sweeps = to_check.min(settings.max_sweeps - sweep);
        sweeping.sweep(system, &mut state, sweeps);
        sweep += sweeps;
    }
    PileAnswer {
        p: state.p,
        met: false,
        sweeps: settings.max_sweeps as u32,
    }
}

/// Which rows are free (`IterativeSystem::is_free`): the rows the
/// subspace step solves together.
fn free_rows(system: &IterativeSystem, s: &IterativeState) -> Vec<bool> {
    (0..system.rows.len())
        .map(|i| system.is_free(i, s))
        .collect()
}
