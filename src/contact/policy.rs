//! Which methods a contact system is solved by, in which order, as data
//! (as Box2D v3 lists its solver's stages): the attempts (`Attempt`), the
//! few facts of a system they are chosen from (`SystemFacts`), the choice
//! (`attempts`), and every threshold it reads (`SolverSettings`).
//!
//! With the default settings, a system of m rows gets, in order:
//! 1. one row: the closed form, alone;
//! 2. from `iterative_min_rows` (300) rows with more than 48 moving
//!    bodies (a pile): the large-island method, alone;
//! 3. from 64 rows where the last step's impulses do not already meet its
//!    conditions (from 300 rows always): 8 warm sweeps (from 300 rows),
//!    then the interior point;
//! 4. from 300 rows: the sweeps, whose answer is kept from 400 rows;
//! 5. from 64 to 300 rows, not at rest: the start sweeps;
//! 6. below 400 rows: Dantzig's method, and where it fails the compliant
//!    retry, the sweeps' rescue (below 300 rows), the interior point's
//!    rescue (where it was not tried first), and the fallback.
//!
//! The first answer that meets the system's conditions is kept, or the
//! last attempt's whatever it is. What an attempt leaves is where later
//! ones start: the interior point's missed answer starts the sweeps, the
//! sweeps' or the start sweeps' answer starts Dantzig's method (`chain`).

use super::methods::block_sweeps::BlockSweepSettings;
use super::methods::interior;
use super::methods::pile_sweeps::PileSweepSettings;
use super::methods::sweeps::SweepSettings;
use super::system::IterativeSystem;

/// Rows from which an island is solved by sequential impulses with the
/// subspace step instead of Dantzig's method. Dantzig's cost grows with the
/// cube of the rows, and on redundant systems this large its friction
/// passes often cycle and fail. Below this the exact method stays: it has
/// no compliance and no tolerance, and small systems are cheap for it.
/// Each task carries its own (`IslandTask::iterative_min_rows`), as tests
/// lower it.
pub const ITERATIVE_MIN_ROWS: usize = 300;

/// One method tried on a contact system (`attempts` orders them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Attempt {
    /// A single frictionless contact: p = max(−b/A, 0) (SPEC eq. 3.17).
    ClosedForm,
    /// The large-island method (`pile_sweeps`) from the last impulses.
    LargeIsland,
    /// A check's worth of sweeps from the last impulses, the subspace step
    /// first: a system at rest meets its conditions in that step.
    WarmSweeps,
    /// The interior point from the last impulses, on the exact system below
    /// `iterative_min_rows`; an answer that misses is where `Sweeps` start.
    InteriorPoint,
    /// Sequential impulses with the subspace step, from the interior
    /// point's missed answer or else the last impulses; an answer that
    /// misses is Dantzig's start.
    Sweeps,
    /// Sweeps from the last impulses that only prepare: their answer is
    /// Dantzig's start, and where it met the conditions the sweeps' rescue.
    StartSweeps,
    /// Dantzig's method on the dense system, from the last answer an
    /// attempt left or else the last impulses (`methods::dantzig`).
    Dantzig,
    /// Dantzig's method again on the slightly compliant system.
    CompliantDantzig,
    /// Where Dantzig's friction passes cycled on both systems: the start
    /// sweeps' answer, or else sweeps from the last impulses, where it
    /// meets the conditions.
    SweepsRescue,
    /// The interior point on the exact system, where it was not tried
    /// first, where its answer meets the conditions.
    InteriorRescue,
    /// The answer an earlier attempt left (the sweeps', the start
    /// sweeps'), else Dantzig's method on simpler systems
    /// (`methods::dantzig::fallback`); counted as a failure.
    Fallback,
}

/// What the choice of attempts reads of a system.
#[derive(Clone, Copy, Debug)]
pub struct SystemFacts {
    /// Its rows.
    pub rows: usize,
    /// `IslandTask::iterative_min_rows`.
    pub iterative_min_rows: u32,
    /// The bodies its rows move; counted (a pass over the rows) only from
    /// `iterative_min_rows` rows, where it decides.
    pub moving_bodies: Option<usize>,
    /// Whether the last step's impulses already meet its conditions to
    /// `SolverSettings::warm_close`; asked only below `iterative_min_rows`
    /// from `factored_min_rows` rows (above, the warm sweeps tell the
    /// same).
    pub warm_is_close: bool,
}

impl SystemFacts {
    /// The facts of `system`, warm-started from `warm`.
    pub(super) fn of(
        system: &IterativeSystem,
        warm: &[f64],
        bodies: usize,
        iterative_min_rows: u32,
        settings: &SolverSettings,
    ) -> Self {
        let rows = system.rows.len();
        let iterative = rows >= iterative_min_rows as usize;
        SystemFacts {
            rows,
            iterative_min_rows,
            moving_bodies: iterative.then(|| interior::moving_count(system.rows, bodies)),
            warm_is_close: !iterative
                && rows >= settings.factored_min_rows
                && system.worst_miss(&system.warm_state(warm, bodies)) <= settings.warm_close,
        }
    }

    /// Whether the system is large enough for the iterative methods.
    pub fn iterative(&self) -> bool {
        self.rows >= self.iterative_min_rows as usize
    }

    /// Whether the interior point may be tried: `iterative_min_rows` =
    /// `u32::MAX` keeps it out (tests compare Dantzig's answers so).
    pub fn interior_allowed(&self) -> bool {
        self.iterative_min_rows != u32::MAX
    }
}

/// The attempts a system gets, in order. The last one always answers.
pub fn attempts(facts: &SystemFacts, settings: &SolverSettings) -> Vec<Attempt> {
    use Attempt::*;
    if facts.rows == 1 {
        return vec![ClosedForm];
    }
    let iterative = facts.iterative();
    if iterative
        && facts
            .moving_bodies
            .is_some_and(|n| n > settings.large_island_bodies)
    {
        return vec![LargeIsland];
    }
    let mut list = Vec::with_capacity(8);
    let interior_first = facts.rows >= settings.interior_min_rows
        && facts.interior_allowed()
        && (iterative || !facts.warm_is_close);
    if interior_first {
        if iterative {
            list.push(WarmSweeps);
        }
        list.push(InteriorPoint);
    }
    if iterative {
        list.push(Sweeps);
        if facts.rows >= settings.dantzig_max_rows {
            return list;
        }
    } else if facts.rows >= settings.factored_min_rows && !facts.warm_is_close {
        list.push(StartSweeps);
    }
    list.push(Dantzig);
    if facts.rows <= settings.compliant_retry_rows {
        list.push(CompliantDantzig);
    }
    if !iterative {
        list.push(SweepsRescue);
    }
    if !interior_first && facts.interior_allowed() {
        list.push(InteriorRescue);
    }
    list.push(Fallback);
    list
}

/// Every threshold of the choice of attempts and of the attempts' work,
/// with the settings of the methods they run. The iterative methods' row
/// threshold travels with each task (`ITERATIVE_MIN_ROWS`).
#[derive(Clone, Copy, Debug)]
pub struct SolverSettings {
    /// Rows from which Dantzig's method takes the system's factors and a
    /// warm start, as below it the dense product is cheap and a fresh start
    /// keeps the small exact cases' finer rounding.
    pub factored_min_rows: usize,
    /// Rows from which a system not at rest goes to the interior point
    /// first, whose cost grows with its rows and bodies, not with how
    /// redundant its rows are.
    pub interior_min_rows: usize,
    /// Moving bodies beyond which a system of `iterative_min_rows` rows or
    /// more goes to the large-island method alone, as the interior point's
    /// Newton systems stop being cheap there (`interior::DENSE_BODIES`).
    pub large_island_bodies: usize,
    /// Rows below which a sweeps' answer that missed the conditions is
    /// solved again by Dantzig's method, as a missed answer moves a resting
    /// stack but solving a settling pile's larger islands exactly would
    /// take most of the run.
    pub dantzig_max_rows: usize,
    /// Rows up to which Dantzig's method is retried on the compliant
    /// system, as compliance clamps every redundant row too and a larger
    /// retry takes seconds where the sweeps take milliseconds.
    pub compliant_retry_rows: usize,
    /// Sweeps at most from the last impulses (the sweeps, their rescue and
    /// the energy guard's safe answer), which stop as soon as the answer
    /// meets the conditions.
    pub iterative_sweeps: usize,
    /// Sweeps tried before the interior point from `iterative_min_rows`
    /// rows: one check's worth, enough for the warm subspace step that
    /// meets a system at rest at once.
    pub warm_sweeps: usize,
    /// Start sweeps below `iterative_min_rows`, as sweeps keep each
    /// friction row within its bound so their answer needs fewer friction
    /// passes than the last impulses, and a few sweeps get most of that.
    pub start_sweeps: usize,
    /// Sweeps at most from the interior point's missed answer, which is
    /// close where the last impulses are not, so that a fraction of
    /// `iterative_sweeps` from it ends nearer the conditions.
    pub sweeps_after_interior: usize,
    /// How far (m/s) the last impulses may miss the conditions and still
    /// start Dantzig's method without the start sweeps or the interior
    /// point, as a standing stack's impulses miss by less and a settling
    /// pile's by far more.
    pub warm_close: f64,
    /// How the sequential impulses check and take the subspace step.
    pub sweeps: SweepSettings,
    /// The large-island method's budget and checks.
    pub large_island: PileSweepSettings,
    /// How it sweeps an island cut in blocks (`IslandTask::island_blocks`).
    pub island_blocks: BlockSweepSettings,
}

impl Default for SolverSettings {
    fn default() -> Self {
        let factored_min_rows = 64;
        let compliant_retry_rows = 400;
        let sweeps = SweepSettings::default();
        SolverSettings {
            factored_min_rows,
            interior_min_rows: factored_min_rows,
            large_island_bodies: interior::DENSE_BODIES,
            dantzig_max_rows: compliant_retry_rows,
            compliant_retry_rows,
            iterative_sweeps: 1000,
            warm_sweeps: sweeps.check_every,
            start_sweeps: 128,
            sweeps_after_interior: 200,
            warm_close: 1e-4,
            sweeps,
            large_island: PileSweepSettings::default(),
            island_blocks: BlockSweepSettings::default(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every list the choice can give ends with an attempt that answers
    /// whatever it finds, and the sweeps answer last only from
    /// `dantzig_max_rows` rows.
    #[test]
    fn every_list_of_attempts_ends_with_one_that_answers() {
        let settings = SolverSettings::default();
        for rows in [1, 2, 63, 64, 65, 299, 300, 399, 400, 401, 5000] {
            for iterative_min_rows in [0, 2, 64, 300, u32::MAX] {
                for moving_bodies in [None, Some(3), Some(1000)] {
                    for warm_is_close in [false, true] {
                        let facts = SystemFacts {
                            rows,
                            iterative_min_rows,
                            moving_bodies,
                            warm_is_close,
                        };
                        let list = attempts(&facts, &settings);
                        let last = *list.last().expect("at least one attempt");
                        match last {
                            Attempt::ClosedForm | Attempt::LargeIsland | Attempt::Fallback => {}
                            Attempt::Sweeps => assert!(rows >= settings.dantzig_max_rows),
                            _ => panic!("{facts:?}: {list:?}"),
                        }
                        if list.contains(&Attempt::Fallback) {
                            assert!(list.contains(&Attempt::Dantzig), "{list:?}");
                        }
                    }
                }
            }
        }
    }
}
