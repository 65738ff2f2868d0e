//! The stage timers (Rapier's `counters`): wall seconds per stage of the
//! step (`StageSeconds`, summary.json's `stage_seconds`), each stage's span
//! timed by a `StageTimer` from `StageSeconds::start` to
//! `StageSeconds::stop`. A leaf module.
//!
//! Time of impact runs inside it the stages its events call for (a group's
//! narrowphase batches, the broadphase of re-integrated paths, the island
//! solves at an impact), which count under their own names; its own seconds
//! are its wall time less what those stages gained meanwhile
//! (`Stage::NESTED`), the rule `stop` applies.

use serde::{Deserialize, Serialize};
use std::time::Instant;

/// A timed stage: one field of `StageSeconds`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Integrate,
    Broadphase,
    Narrowphase,
    TimeOfImpact,
    BuildIslands,
    SolveIslands,
    Communication,
    Render,
}

impl Stage {
    /// The stages time of impact calls into, counted under their own and
    /// not under it.
    pub const NESTED: [Stage; 4] = [
        Stage::Broadphase,
        Stage::Narrowphase,
        Stage::BuildIslands,
        Stage::SolveIslands,
    ];
}

/// Wall seconds per stage (summary's `stage_seconds`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct StageSeconds {
    pub integrate: f64,
    pub broadphase: f64,
    pub narrowphase: f64,
    pub time_of_impact: f64,
    pub build_islands: f64,
    pub solve_islands: f64,
    pub communication: f64,
    pub render: f64,
}

/// A stage being timed, from `StageSeconds::start` to `StageSeconds::stop`.
/// It borrows nothing, so the stage's code may change whatever holds the
/// seconds it is stopped into.
#[must_use = "a stage's time counts once its timer is stopped"]
pub(crate) struct StageTimer {
    stage: Stage,
    started: Instant,
    /// The seconds of `Stage::NESTED` when it started.
    nested: f64,
}

impl StageSeconds {
    /// Starts timing `stage`.
    pub(crate) fn start(&self, stage: Stage) -> StageTimer {
        StageTimer {
            stage,
            started: Instant::now(),
            nested: self.nested(),
        }
    }

    /// Adds the wall seconds since `timer` started to its stage; to time of
    /// impact, less what the stages it calls into gained meanwhile.
    pub(crate) fn stop(&mut self, timer: StageTimer) {
        let mut seconds = timer.started.elapsed().as_secs_f64();
        if timer.stage == Stage::TimeOfImpact {
            seconds -= self.nested() - timer.nested;
        }
        *self.seconds_mut(timer.stage) += seconds;
    }

    /// Adds `other`'s seconds of `stages` (what a region that ran them
    /// hands back).
    pub(crate) fn add(&mut self, other: &StageSeconds, stages: &[Stage]) {
        for &stage in stages {
            *self.seconds_mut(stage) += other.seconds(stage);
        }
    }

    fn seconds(&self, stage: Stage) -> f64 {
        match stage {
            Stage::Integrate => self.integrate,
            Stage::Broadphase => self.broadphase,
            Stage::Narrowphase => self.narrowphase,
            Stage::TimeOfImpact => self.time_of_impact,
            Stage::BuildIslands => self.build_islands,
            Stage::SolveIslands => self.solve_islands,
            Stage::Communication => self.communication,
            Stage::Render => self.render,
        }
    }

    fn seconds_mut(&mut self, stage: Stage) -> &mut f64 {
        match stage {
            Stage::Integrate => &mut self.integrate,
            Stage::Broadphase => &mut self.broadphase,
            Stage::Narrowphase => &mut self.narrowphase,
            Stage::TimeOfImpact => &mut self.time_of_impact,
            Stage::BuildIslands => &mut self.build_islands,
            Stage::SolveIslands => &mut self.solve_islands,
            Stage::Communication => &mut self.communication,
            Stage::Render => &mut self.render,
        }
    }

    /// Seconds of the stages time of impact calls into.
    fn nested(&self) -> f64 {
        Stage::NESTED.iter().map(|&s| self.seconds(s)).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn time_of_impact_excludes_the_stages_it_calls() {
        let mut s = StageSeconds::default();
        let toi = s.start(Stage::TimeOfImpact);
        let inner = s.start(Stage::Narrowphase);
        std::thread::sleep(std::time::Duration::from_millis(20));
        s.stop(inner);
        s.stop(toi);
        assert!(s.narrowphase >= 0.02, "{s:?}");
        // Its own time is the few microseconds around the narrowphase.
        assert!(s.time_of_impact >= 0.0 && s.time_of_impact < 0.01, "{s:?}");
    }

    #[test]
    fn add_takes_only_the_stages_named() {
        let mut a = StageSeconds::default();
        let b = StageSeconds {
            narrowphase: 1.0,
            time_of_impact: 2.0,
            render: 3.0,
            ..Default::default()
        };
        a.add(&b, &[Stage::Narrowphase, Stage::TimeOfImpact]);
        assert_eq!((a.narrowphase, a.time_of_impact, a.render), (1.0, 2.0, 0.0));
    }
}
