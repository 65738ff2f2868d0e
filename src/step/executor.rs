//! The seam between the step and where its pure work runs: the `Executor`
//! (one rank: `Inline`; several: `cluster`) and every type its methods
//! carry, down to the plain data those are made of. A group's step crosses
//! it whole: its static data and parameters (`StepStatic`, `GroupParams`),
//! its input (`GroupInput`), its first stage computed beforehand
//! (`PreparedPairs`) and its answer (`GroupReply`), built of segments
//! (`Segment`), pair keys (`PairKey`) and when pairs were last solved
//! (`Since`).
//!
//! It imports no stage of `step`, only the leaves (`stats`, `timers`,
//! `settings`, `touching`): every stage can take an `Executor` without the
//! seam importing the stages back.

use super::event_path::LoopSeconds;
use super::settings::StepSettings;
use super::stats::{Counters, Distribution, GroupSeconds, NumericalFailure, RankSummary};
use super::timers::{Stage, StageSeconds};
use super::touching::{Touching, WarmContact};
use crate::body::{Body, BodyId, BodyState, ObjectDef};
use crate::collision::broadphase::SphereProxy;
use crate::collision::narrowphase::{CachedFeatures, PairResult, PairTask};
use crate::contact::solver::{IslandResult, IslandTask};
use crate::scene::{ForceWindow, Scene, Settings};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Runs the distributable stages. One rank: `Inline`; several: `cluster`.
pub trait Executor {
    fn narrowphase(&mut self, objects: &[ObjectDef], tasks: Vec<PairTask>) -> Vec<PairResult>;
    fn solve_islands(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult>;
    /// The `time_of_impact` stage: each group's step (`group::run_group`),
    /// answers in the order of `inputs`.
    fn step_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<GroupReply>;
    /// The first stage of each group's step for all its pairs
    /// (`group::prepare_pairs`), answers in the order of `inputs`: what a
    /// large group is split by (`group::split_group`).
    fn prepare_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<PreparedPairs>;
    /// Which of the step's groups (their predicted seconds and bodies, in
    /// group order) to split into the parts that meet within the step
    /// (`group::split_group`): piles (`group::SPLIT_AUTO_MIN_MEMBERS`) that
    /// would hold up the ranks sharing the group steps, where splitting
    /// measures faster. The choice changes the time, not the answer: a
    /// split group ends as it would whole (`docs/architecture.md`). One
    /// rank splits none (unless `StepSettings::split_groups` asks for all).
    fn split_groups(&mut self, groups: &[(f64, usize)]) -> Vec<bool> {
        vec![false; groups.len()]
    }
    /// The step's groups are all stepped (after `split_groups`), so what
    /// its choice cost can be measured.
    fn groups_stepped(&mut self) {}
    /// The scene's external forces changed at a step boundary (a live
    /// live run's hand, `run --inputs`): every rank that steps groups must
    /// integrate with these from the next step on. Inline: nothing to do,
    /// the step reads `World::scene`.
    fn share_forces(&mut self, _forces: &[ForceWindow]) {}
    /// Ends the run on every rank; returns the per-rank accounts and how often
    /// each stage was distributed.
    fn finish(&mut self) -> (Vec<RankSummary>, Distribution);
}

/// What every region of one step reads and nothing changes: the scene's
/// objects, settings and force windows, the step's start time, and the
/// world's step settings.
pub struct StepStatic<'s> {
    pub(crate) objects: &'s [ObjectDef],
    pub(crate) settings: &'s Settings,
    pub(crate) forces: &'s [ForceWindow],
    /// Simulated time at the step's start.
    pub(crate) t0: f64,
    pub(crate) step_settings: StepSettings,
}

/// What a group's step reads besides the scene: the step's start time and
/// the world's step settings. Sent with the groups a worker steps.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GroupParams {
    t0: f64,
    settings: StepSettings,
}

impl GroupParams {
    /// A step starting at `t0` with the world's `settings`.
    pub(crate) fn new(t0: f64, settings: StepSettings) -> Self {
        GroupParams { t0, settings }
    }

    pub(crate) fn of(st: &StepStatic) -> Self {
        GroupParams {
            t0: st.t0,
            settings: st.step_settings,
        }
    }

    /// The step's static data, with a scene that every rank loaded alike.
    pub fn statics<'s>(&self, scene: &'s Scene) -> StepStatic<'s> {
        StepStatic {
            objects: &scene.objects,
            settings: &scene.settings,
            forces: &scene.forces,
            t0: self.t0,
            step_settings: self.settings,
        }
    }
}

/// One group's input, ids and state only (`group::group_input`): what
/// rank 0 sends a worker to step.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GroupInput {
    pub(super) ids: Vec<u32>,
    pub(super) bodies: Vec<Body>,
    pub(super) features: Vec<(PairKey, Vec<CachedFeatures>)>,
    pub(super) warm: Vec<((BodyId, BodyId), Vec<WarmContact>)>,
    pub(super) sleep_timer: Vec<f64>,
    pub(super) sleep_group: Vec<u32>,
    pub(super) seg: Vec<Segment>,
    pub(super) end: Vec<BodyState>,
    pub(super) pairs: Vec<PairKey>,
    pub(super) since: Vec<(PairKey, Since)>,
    pub(super) separating: Vec<(PairKey, Vector3<f64>)>,
    /// Islands solved together at the step's start (local indices).
    pub(super) together: Vec<Vec<usize>>,
    pub(super) spin_resolves: Vec<(f64, usize)>,
    /// Seconds its step is expected to take: what its bodies' groups took
    /// last step (`GroupOutput::busy_s`, shared out over their members).
    pub(super) predicted_s: f64,
    /// Its first stage, when computed beforehand (`impacts::GroupState::prepared`).
    pub(super) prepared: Option<PreparedPairs>,
    /// Whether its step returns its bodies' segments (`impacts::GroupState::keep_paths`).
    pub(super) keep_paths: bool,
}

impl GroupInput {
    /// Seconds its step is expected to take, for the schedule.
    pub fn predicted_s(&self) -> f64 {
        self.predicted_s
    }

    /// Its candidate pairs (the first stage's tasks).
    pub fn pair_count(&self) -> usize {
        self.pairs.len()
    }

    /// Whether its first stage was computed beforehand.
    pub fn is_prepared(&self) -> bool {
        self.prepared.is_some()
    }

    /// Hands the step its first stage, computed beforehand for all its
    /// pairs in order (`group::prepare_pairs`, `PreparedPairs::joined`).
    pub fn set_prepared(&mut self, prepared: PreparedPairs) {
        assert_eq!(
            prepared.results.len(),
            self.pairs.len(),
            "one answer per pair"
        );
        self.prepared = Some(prepared);
    }
}

/// What a group's step returns (`impacts::step_group`), ids and state only.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct GroupOutput {
    pub(crate) ids: Vec<u32>,
    pub(crate) bodies: Vec<Body>,
    pub(crate) sleep_timer: Vec<f64>,
    pub(crate) end: Vec<BodyState>,
    pub(crate) pairs: Vec<PairKey>,
    pub(crate) results: Vec<PairResult>,
    pub(crate) warm: Vec<((BodyId, BodyId), Vec<WarmContact>)>,
    pub(crate) impacts: Vec<Touching>,
    pub(crate) pair_forces: Vec<((BodyId, BodyId), f64)>,
    pub(crate) counters: Counters,
    pub(crate) stage: StageSeconds,
    /// Impact events taken (spin re-solves not counted).
    pub(crate) events: u64,
    /// Swept spheres (world ids) of the paths its bodies took after their
    /// first roll-back that leave their grown prediction.
    pub(crate) pieces: Vec<SphereProxy>,
    /// Wall seconds the step took where it ran (the next step's prediction).
    pub(crate) busy_s: f64,
    /// Of those, the seconds of its event loop's searches and events, and
    /// their critical path through the bodies each reads and moves
    /// (`event_path::EventPaths`): what the loop would take shared. `None`
    /// unless the loop was timed (`StepSettings::time_events`).
    pub(crate) event_loop: Option<LoopSeconds>,
    /// V-Clip tasks of its first stage run beforehand (`PreparedPairs`):
    /// in `counters`, but counted where they ran.
    pub(crate) prepared_tasks: u64,
    /// Where asked for (`impacts::GroupState::keep_paths`): the segments each body
    /// that left its predicted path took, in time order (world id; the
    /// first is its segment at the step's start, each later one begins at
    /// the event that rolled it back).
    pub(crate) paths: Vec<(u32, Vec<Segment>)>,
}

impl GroupOutput {
    /// Its seconds as the step's group work counts them.
    pub fn seconds(&self) -> GroupSeconds {
        GroupSeconds {
            busy_s: self.busy_s,
            event_loop: self.event_loop,
        }
    }

    /// V-Clip tasks and island solves the group's step ran.
    pub fn tasks(&self) -> (u64, u64) {
        (
            self.counters.pair_tests - self.prepared_tasks,
            self.counters.islands,
        )
    }
}

/// A numerical failure inside a group's step, as it travels between ranks.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GroupFailure {
    body: u32,
    stage: String,
    time: f64,
    detail: String,
}

impl From<NumericalFailure> for GroupFailure {
    fn from(f: NumericalFailure) -> Self {
        GroupFailure {
            body: f.body.0,
            stage: f.stage.to_string(),
            time: f.time,
            detail: f.detail,
        }
    }
}

impl From<GroupFailure> for NumericalFailure {
    fn from(f: GroupFailure) -> Self {
        NumericalFailure {
            body: BodyId(f.body),
            stage: if f.stage == "integrate" {
                "integrate"
            } else {
                "solve_islands"
            },
            time: f.time,
            detail: f.detail,
        }
    }
}

/// One group's answer: its output, or where it went numerically wrong
/// (`None` only as a placeholder while answers are gathered); and the
/// islands its step captured (`StepSettings::capture_min_rows`), also
/// before a failure, for the rank that stepped it to write: they never
/// travel (a worker's reply arrives without them).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct GroupReply(
    pub(crate) Option<Result<GroupOutput, GroupFailure>>,
    #[serde(skip)] pub(crate) Vec<IslandTask>,
);

impl GroupReply {
    /// V-Clip tasks and island solves the group's step ran.
    pub fn tasks(&self) -> (u64, u64) {
        match &self.0 {
            Some(Ok(out)) => out.tasks(),
            _ => (0, 0),
        }
    }
}

/// The first stage of a group's step for some of its pairs: their
/// end-of-step results and times of impact. Each pair's answer depends
/// only on the group's input, so a large group's pairs can be shared out
/// over ranks (`group::prepare_pairs`) before one rank takes its events; the step
/// then starts from these answers instead of computing them, and ends
/// exactly as it would have.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PreparedPairs {
    pub(crate) results: Vec<PairResult>,
    pub(crate) toi: Vec<Option<f64>>,
    pub(crate) counters: Counters,
    pub(crate) stage: StageSeconds,
    /// Wall seconds it took where it ran (part of the group's cost).
    pub(crate) busy_s: f64,
}

impl PreparedPairs {
    /// V-Clip tasks it ran.
    pub fn tasks(&self) -> u64 {
        self.counters.pair_tests
    }

    /// The shares of one group's pairs, in the order of their ranges, as
    /// one (the ranges must cover the pairs in order).
    pub fn joined(shares: Vec<PreparedPairs>) -> PreparedPairs {
        let mut all = PreparedPairs::default();
        for s in shares {
            all.results.extend(s.results);
            all.toi.extend(s.toi);
            all.counters.add(&s.counters);
            all.stage
                .add(&s.stage, &[Stage::Narrowphase, Stage::TimeOfImpact]);
            all.busy_s += s.busy_s;
        }
        all
    }
}

/// A body pair in local indices, `a < b`.
pub(crate) type PairKey = (u32, u32);

/// A body's motion over the current step: start state at `time` (seconds into
/// the step) with constant force and torque until the end of the step.
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub(crate) struct Segment {
    pub state: BodyState,
    pub time: f64,
    pub force: Vector3<f64>,
    pub torque: Vector3<f64>,
}

/// When a pair's contacts were last solved (the step's start, or an
/// impact's τ, seconds into the step), its deepest overlap then
/// (`toi::SolvedSince`), and whether it had contact points then (not only
/// near points): an impact of such a pair repairs an overlap
/// (`Counters::overlap_repairs`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub(crate) struct Since {
    pub time: f64,
    pub deepest: f64,
    pub touched: bool,
}
