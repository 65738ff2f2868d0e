//! One contact system taken through the policy's attempts
//! (`policy::attempts`) in turn: each runs its method, counts it in
//! `SolveStats`, and either answers or leaves what it found for the
//! attempts after it; then the answer's checks (`guard`).

use super::guard;
use super::methods::block_sweeps::{BlockRunner, BlockSweeps, IslandBlocks};
use super::methods::dantzig::Dantzig;
use super::methods::lcp::LcpError;
use super::methods::pile_sweeps::Sweeping;
use super::methods::{interior, pile_sweeps, sweeps};
use super::policy::{Attempt, SolverSettings, SystemFacts};
use super::system::{IterativeSystem, PhaseSystem};
use super::task::{IslandBody, SolveStats};
use nalgebra::Vector3;

/// A system on its way through the attempts, with what they left.
pub(super) struct Chain<'a> {
    system: &'a PhaseSystem,
    /// The system as the sweeps and the interior point see it.
    iterative: IterativeSystem<'a>,
    bodies: usize,
    settings: &'a SolverSettings,
    pub(super) facts: SystemFacts,
    /// The interior point's answer where it missed the conditions: where
    /// the sweeps start.
    missed: Option<Vec<f64>>,
    /// The sweeps' answer where it missed them: Dantzig's start, and the
    /// fallback's answer.
    unconverged: Option<Vec<f64>>,
    /// The start sweeps' answer, and whether it met them: Dantzig's start,
    /// the sweeps' rescue where it met them, and the fallback's answer.
    swept: Option<(Vec<f64>, bool)>,
    /// Dantzig's method once tried, and why it failed on the exact system.
    dantzig: Option<Dantzig<'a>>,
    failure: Option<LcpError>,
    /// Where the large-island method sweeps by blocks.
    by_blocks: Option<ByBlocks<'a>>,
}

/// An island the large-island method sweeps by blocks (`block_sweeps`):
/// its bodies, the blocks to cut it into, and who sweeps them.
pub(super) struct ByBlocks<'a> {
    pub(super) bodies: &'a [IslandBody],
    pub(super) count: usize,
    pub(super) runner: &'a mut dyn BlockRunner,
}

impl<'a> Chain<'a> {
    /// `system` of an island of `bodies` bodies, whose task sets
    /// `iterative_min_rows`, and how it is cut in blocks, where it is.
    pub(super) fn new(
        system: &'a PhaseSystem,
        iterative_min_rows: u32,
        bodies: usize,
        settings: &'a SolverSettings,
        by_blocks: Option<ByBlocks<'a>>,
    ) -> Self {
        let iterative = system.iterative();
        let facts = SystemFacts::of(
            &iterative,
            &system.warm,
            bodies,
            iterative_min_rows,
            settings,
        );
        Chain {
            system,
            iterative,
            bodies,
            settings,
            facts,
            missed: None,
            unconverged: None,
            swept: None,
            dantzig: None,
            failure: None,
            by_blocks,
        }
    }

    /// Runs `attempts` in turn up to the first that answers: with an answer
    /// that meets the conditions, or as the last, whatever it found.
    pub(super) fn walk(
        &mut self,
        attempts: &[Attempt],
        stats: &mut SolveStats,
    ) -> (Attempt, Vec<f64>) {
        for (k, &attempt) in attempts.iter().enumerate() {
            let last = k + 1 == attempts.len();
            if let Some(p) = self.run(attempt, last, stats) {
                return (attempt, p);
            }
        }
        panic!("no attempt of {attempts:?} answered: the policy ends each list with one that does")
    }

    fn run(&mut self, attempt: Attempt, last: bool, stats: &mut SolveStats) -> Option<Vec<f64>> {
        match attempt {
            Attempt::ClosedForm => Some(self.closed_form(stats)),
            Attempt::LargeIsland => self.large_island(last, stats),
            Attempt::WarmSweeps => self.warm_sweeps(stats),
            Attempt::InteriorPoint => self.interior_point(stats),
            Attempt::Sweeps => self.sweeps(last, stats),
            Attempt::StartSweeps => self.start_sweeps(stats),
            Attempt::Dantzig => self.dantzig(stats),
            Attempt::CompliantDantzig => self.compliant_dantzig(stats),
            Attempt::SweepsRescue => self.sweeps_rescue(stats),
            Attempt::InteriorRescue => self.interior_rescue(stats),
            Attempt::Fallback => Some(self.fallback(stats)),
        }
    }

    /// The answer's checks: how far it misses the conditions noted, then
    /// the energy guard, with the dense system's safe answers where
    /// Dantzig's method set one up, else the sweeps'. The closed form's
    /// answer is exact for its one row and applied as it is.
    pub(super) fn guard(
        &self,
        attempt: Attempt,
        p: Vec<f64>,
        velocities: (&[Vector3<f64>], &[Vector3<f64>]),
        stats: &mut SolveStats,
    ) -> Vec<f64> {
        if attempt == Attempt::ClosedForm {
            return p;
        }
        guard::note_violation(self.system, &p, self.bodies, stats);
        match &self.dantzig {
            Some(dantzig) => {
                guard::guard_dense(self.system, dantzig.matrix(), velocities, p, stats)
            }
            None => guard::guard_iterative(self.system, velocities, p, stats, self.settings),
        }
    }

    fn closed_form(&self, stats: &mut SolveStats) -> Vec<f64> {
        stats.closed_form_solves += 1;
        let a00 = self.system.diag[0];
        let p = if a00 > 0.0 {
            (-self.system.rhs[0] / a00).max(0.0)
        } else {
            0.0
        };
        vec![p]
    }

    fn large_island(&mut self, last: bool, stats: &mut SolveStats) -> Option<Vec<f64>> {
        let sweeping = match &mut self.by_blocks {
            Some(by) => Sweeping::Blocks(BlockSweeps::new(
                IslandBlocks::cut(by.bodies, &self.system.rows, by.count),
                &mut *by.runner,
                self.settings.island_blocks,
            )),
            None => Sweeping::Whole,
        };
        let answer = pile_sweeps::solve(
            &self.iterative,
            &self.system.warm,
            self.bodies,
            &self.settings.large_island,
            sweeping,
        );
        stats.iterative_solves += 1;
        stats.iterative_sweeps += answer.sweeps as u64;
        if !answer.met {
            stats.iterative_unconverged += 1;
        }
        (answer.met || last).then_some(answer.p)
    }

    /// The sequential impulses from `start`, `max_sweeps` at most.
    fn sweeps_from(&self, start: &[f64], max_sweeps: usize) -> (Vec<f64>, bool, u32) {
        sweeps::sequential_impulses(
            &self.iterative,
            start,
            self.bodies,
            max_sweeps,
            &self.settings.sweeps,
        )
    }

    /// A system at rest (a stack) meets the conditions in the warm start's
    /// subspace step, a stack's impact in a few sweeps.
    fn warm_sweeps(&self, stats: &mut SolveStats) -> Option<Vec<f64>> {
        let (p, met, sweeps) = self.sweeps_from(&self.system.warm, self.settings.warm_sweeps);
        stats.iterative_sweeps += sweeps as u64;
        met.then(|| {
            stats.iterative_solves += 1;
            p
        })
    }

    /// Below `iterative_min_rows`, where Dantzig's answers are, on the
    /// exact system: no compliance.
    fn interior_point(&mut self, stats: &mut SolveStats) -> Option<Vec<f64>> {
        let strict = IterativeSystem {
            compliance: if self.facts.iterative() {
                self.iterative.compliance
            } else {
                0.0
            },
            ..self.iterative
        };
        let answer = interior::solve(&strict, &self.system.warm, self.bodies)?;
        stats.interior_steps += answer.steps as u64;
        if answer.met {
            stats.interior_solves += 1;
            return Some(answer.p);
        }
        stats.interior_missed += 1;
        self.missed = Some(answer.p);
        None
    }

    fn sweeps(&mut self, last: bool, stats: &mut SolveStats) -> Option<Vec<f64>> {
        stats.iterative_solves += 1;
        let (p, met, sweeps) = match &self.missed {
            Some(start) => self.sweeps_from(start, self.settings.sweeps_after_interior),
            None => self.sweeps_from(&self.system.warm, self.settings.iterative_sweeps),
        };
        stats.iterative_sweeps += sweeps as u64;
        if !met {
            stats.iterative_unconverged += 1;
        }
        if met || last {
            return Some(p);
        }
        self.unconverged = Some(p);
        None
    }

    fn start_sweeps(&mut self, stats: &mut SolveStats) -> Option<Vec<f64>> {
        let (p, met, sweeps) = self.sweeps_from(&self.system.warm, self.settings.start_sweeps);
        stats.iterative_sweeps += sweeps as u64;
        self.swept = Some((p, met));
        None
    }

    /// Dantzig's method starts from the sweeps' answer that missed the
    /// conditions, or from the start sweeps' answer, else from the last
    /// step's impulses where there are any: the sets they imply are most
    /// of the answer's. From `factored_min_rows` rows, like the factors.
    fn dantzig(&mut self, stats: &mut SolveStats) -> Option<Vec<f64>> {
        let warm = &self.system.warm;
        let start = self
            .unconverged
            .clone()
            .or_else(|| self.swept.as_ref().map(|(p, _)| p.clone()))
            .or_else(|| warm.iter().any(|&x| x != 0.0).then(|| warm.clone()));
        let factored = self.facts.rows >= self.settings.factored_min_rows;
        let dantzig = Dantzig::new(&self.iterative, self.bodies, factored, start);
        stats.lcp_solves += 1;
        let answer = dantzig.solve();
        self.dantzig = Some(dantzig);
        match answer {
            Ok(sol) => {
                stats.pivots += sol.pivots as u64;
                Some(sol.x)
            }
            Err(e) => {
                self.failure = Some(e);
                None
            }
        }
    }

    fn compliant_dantzig(&mut self, stats: &mut SolveStats) -> Option<Vec<f64>> {
        let sol = self.dantzig.as_ref()?.solve_compliant().ok()?;
        stats.pivots += sol.pivots as u64;
        stats.compliant_solves += 1;
        Some(sol.x)
    }

    /// Where Dantzig's friction passes cycle on both systems (the bounds
    /// follow normal impulses that move with them), the sequential
    /// impulses with the subspace step may still meet the conditions (on
    /// the compliant iterative system): their answer if they do.
    fn sweeps_rescue(&mut self, stats: &mut SolveStats) -> Option<Vec<f64>> {
        let (p, met, sweeps) = match &self.swept {
            Some((p, met)) => (p.clone(), *met, 0),
            None => self.sweeps_from(&self.system.warm, self.settings.iterative_sweeps),
        };
        stats.iterative_sweeps += sweeps as u64;
        met.then(|| {
            stats.iterative_rescues += 1;
            p
        })
    }

    /// The interior point on the exact system where it was not tried first
    /// (below `interior_min_rows`, or where the last impulses were close
    /// enough for Dantzig's method): its answer where it meets the
    /// conditions. It refuses systems that move too many bodies itself.
    fn interior_rescue(&mut self, stats: &mut SolveStats) -> Option<Vec<f64>> {
        let exact = IterativeSystem {
            compliance: 0.0,
            ..self.iterative
        };
        let answer = interior::solve(&exact, &self.system.warm, self.bodies)?;
        stats.interior_steps += answer.steps as u64;
        answer.met.then(|| {
            stats.interior_solves += 1;
            stats.iterative_rescues += 1;
            answer.p
        })
    }

    /// Every method failed: the answer the sweeps or the start sweeps
    /// left, else Dantzig's method on simpler systems.
    fn fallback(&mut self, stats: &mut SolveStats) -> Vec<f64> {
        let why = self
            .failure
            .take()
            .map_or_else(|| "no method answered".to_string(), |e| e.to_string());
        stats.record_failure(self.facts.rows, why);
        self.unconverged
            .take()
            .or(self.swept.take().map(|(p, _)| p))
            .unwrap_or_else(|| {
                let dantzig = self.dantzig.as_ref();
                dantzig
                    .expect("the fallback follows Dantzig's method")
                    .fallback()
            })
    }
}
