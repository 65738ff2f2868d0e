//! What a run counts and measures besides its stage seconds (`timers`):
//! the work it did and skipped, per rank, and how its stages were
//! distributed, and the numerical failure that stops a run
//! (`check_states`). A leaf module: `step` fills these in and `output`
//! writes them.

use super::event_path::LoopSeconds;
use crate::body::{BodyId, BodyState};
use crate::contact::solver::SolveStats;
use crate::scene::bounds::MAX_SPEED;
use serde::{Deserialize, Serialize};

/// What the simulator did and what it skipped, counted over the run.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Counters {
    pub steps: u64,
    pub integrations: u64,
    pub integrations_skipped_resting: u64,
    pub candidate_pairs: u64,
    pub pair_tests: u64,
    /// Candidate pairs not tested because neither body moves (two fixed
    /// bodies, two bodies of a resting system, a fixed and a resting body).
    pub pairs_skipped_resting: u64,
    /// End-of-step pair tests skipped (SPEC 2.6): pairs that touched at the
    /// step's start, were separating after its contact solve, and are proven
    /// apart by more than the contact tolerance along their old normal.
    pub pairs_skipped_separating: u64,
    pub vclip_iterations: u64,
    pub toi_events: u64,
    /// Impact events by how fast their pair approached at the instant (the
    /// fastest of its contact points): below the restitution threshold
    /// g·dt/2 (no bounce), up to 0.2 m/s, up to 1 m/s, faster. Where a
    /// pour's events come from, for the contact model's dial.
    pub toi_events_by_approach: [u64; 4],
    /// Impact events by how many bodies they rolled back to their instant
    /// and solved again: 1, 2, 3–7, 8–31, 32 or more. An event inside a
    /// pile rolls back the pile (its contact island), and each costs the
    /// pile's contact solve.
    pub toi_events_by_rollback: [u64; 5],
    /// Impact events on a pair that had contact points when it was last
    /// solved in the step (at its start or at an earlier event): a point
    /// sank past what the pair carried (a rocking body's other corner
    /// landing, an overlap a speculative contact let through), and the
    /// roll-back repaired it. The rest of `toi_events` are pairs that met
    /// from apart (or from near points only).
    pub overlap_repairs: u64,
    pub toi_bisection_queries: u64,
    /// Impacts found at another impact's instant, in a pair that had begun
    /// to overlap before it unseen (see `Region::earlier_impact`).
    pub toi_missed_overlaps: u64,
    /// Contact islands solved again because a body in them turned by
    /// `SPIN_TRUST` on the forces of their last solve.
    pub spin_resolves: u64,
    /// Most impact events in one step (all groups together).
    pub max_events_in_step: u64,
    pub steps_with_events: u64,
    pub overlaps_accepted: u64,
    /// Pairs a speculative contact pushed on in a step (it held a resting
    /// force or deferred a bounce), counted once a step.
    pub speculative_pushes: u64,
    /// Those of them that ended the step apart by more than the contact
    /// tolerance: a push with no touch, to be seen as a gap.
    pub speculative_ghosts: u64,
    pub islands: u64,
    pub contacts: u64,
    /// Touching body pairs solved, by the contact points (normal rows) each
    /// carried: 1, 2, 3, 4, 5–8, 9–16, 17–32, more.
    pub points_per_pair: [u64; 8],
    pub solve: SolveStats,
    pub bodies_fallen: u64,
    pub wakes: u64,
    /// Interaction groups stepped (`step::group`), over the run.
    pub groups: u64,
    /// Most bodies (moving and woken, not the read-only neighbours) in one group.
    pub largest_group: u64,
    /// Groups stepped again from the step's start because a realised path
    /// left its group and met another group or a body outside its input.
    pub group_reruns: u64,
}

impl Counters {
    /// Counts one impact event that rolled back `bodies` bodies in
    /// `toi_events_by_rollback`.
    pub(crate) fn count_event_rollback(&mut self, bodies: usize) {
        let bucket = match bodies {
            0..=2 => bodies.max(1) - 1,
            3..=7 => 2,
            8..=31 => 3,
            _ => 4,
        };
        self.toi_events_by_rollback[bucket] += 1;
    }

    /// Counts one touching pair's `points` in `points_per_pair`.
    pub(crate) fn count_pair_points(&mut self, points: usize) {
        let bucket = match points {
            0..=4 => points.max(1) - 1,
            5..=8 => 4,
            9..=16 => 5,
            17..=32 => 6,
            _ => 7,
        };
        self.points_per_pair[bucket] += 1;
    }

    /// Adds what one group step counted (`steps` and the per-step maxima
    /// are the caller's).
    pub(crate) fn add(&mut self, o: &Counters) {
        self.integrations += o.integrations;
        self.integrations_skipped_resting += o.integrations_skipped_resting;
        self.candidate_pairs += o.candidate_pairs;
        self.pair_tests += o.pair_tests;
        self.pairs_skipped_resting += o.pairs_skipped_resting;
        self.pairs_skipped_separating += o.pairs_skipped_separating;
        self.vclip_iterations += o.vclip_iterations;
        self.toi_events += o.toi_events;
        for (x, y) in self
            .toi_events_by_approach
            .iter_mut()
            .zip(o.toi_events_by_approach)
        {
            *x += y;
        }
        for (x, y) in self
            .toi_events_by_rollback
            .iter_mut()
            .zip(o.toi_events_by_rollback)
        {
            *x += y;
        }
        self.overlap_repairs += o.overlap_repairs;
        self.toi_bisection_queries += o.toi_bisection_queries;
        self.toi_missed_overlaps += o.toi_missed_overlaps;
        self.spin_resolves += o.spin_resolves;
        self.overlaps_accepted += o.overlaps_accepted;
        self.speculative_pushes += o.speculative_pushes;
        self.speculative_ghosts += o.speculative_ghosts;
        self.islands += o.islands;
        self.contacts += o.contacts;
        for (x, y) in self.points_per_pair.iter_mut().zip(o.points_per_pair) {
            *x += y;
        }
        self.solve.add(&o.solve);
        self.bodies_fallen += o.bodies_fallen;
        self.wakes += o.wakes;
    }
}

#[derive(Debug, Clone)]
pub struct NumericalFailure {
    pub body: BodyId,
    pub stage: &'static str,
    pub time: f64,
    pub detail: String,
}

impl std::fmt::Display for NumericalFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(
            f,
            "numerical failure at t = {:.6} s in stage {}: body {} {}",
            self.time, self.stage, self.body.0, self.detail
        )
    }
}

/// Stops the run when a state is non-finite or faster than `MAX_SPEED`,
/// naming the stage that produced it: `solve_islands` right after a
/// contact solve (impulses), `integrate` at the end of the step (forces,
/// including a scene's own `[[forces]]`, acting over it). `states` are
/// (world id, state).
pub(crate) fn check_states<'a>(
    states: impl Iterator<Item = (usize, &'a BodyState)>,
    stage: &'static str,
    t: f64,
) -> Result<(), NumericalFailure> {
    for (i, s) in states {
        let finite = s.position.iter().all(|x| x.is_finite())
            && s.velocity.iter().all(|x| x.is_finite())
            && s.angular_momentum.iter().all(|x| x.is_finite())
            && s.orientation.coords.iter().all(|x| x.is_finite());
        let detail = if !finite {
            "has a non-finite state".to_string()
        } else if s.velocity.norm() > MAX_SPEED {
            format!("exploded (speed {:.3e} m/s)", s.velocity.norm())
        } else {
            continue;
        };
        return Err(NumericalFailure {
            body: BodyId(i as u32),
            stage,
            time: t,
            detail,
        });
    }
    Ok(())
}

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
/// One rank's account of a run (summary's `per_rank`).
pub struct RankSummary {
    pub rank: u32,
    /// `coordinator`, `worker` or `renderer`.
    pub role: String,
    pub busy_s: f64,
    pub waiting_s: f64,
    pub tasks: u64,
    pub narrowphase_tasks: u64,
    pub island_tasks: u64,
    /// Estimated cost (seconds, by the calibrated model) of the work given.
    pub estimated_cost_s: f64,
    pub bytes_sent: u64,
    pub bytes_received: u64,
    /// Estimated relative speed (1 = as fast as the model's calibration).
    pub speed: f64,
    pub frames_rendered: u64,
    /// Rows this rank swept in the blocks of islands shared by blocks,
    /// times the sweeps (`--island-blocks`; the greedy rule's share).
    #[serde(default)]
    pub block_rows_swept: u64,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
/// How often each distributable stage went to workers or ran on rank 0 alone.
pub struct Distribution {
    pub narrowphase_distributed: u64,
    pub narrowphase_local: u64,
    pub solve_distributed: u64,
    pub solve_local: u64,
    /// Steps whose group steps (`time_of_impact`) went to workers, and
    /// steps that ran them on rank 0 alone.
    pub groups_distributed: u64,
    pub groups_local: u64,
    /// Of `groups_distributed`, the steps the cost model would have kept on
    /// rank 0 and the measured times (or a probe) sent out
    /// (`cluster::schedule::StageChoice`).
    pub groups_by_measure: u64,
    /// Of `solve_distributed`, the same for the island solves.
    pub solves_by_measure: u64,
    /// Groups too large to share out whole whose first stage went out in
    /// ranges of their pairs before they stepped (`PreparePairs`), and
    /// groups to be split whose first stage did (`--split-groups`).
    pub groups_prepared: u64,
    /// Steps with a group that would hold the other ranks up
    /// (`Executor::split_groups`): those that split it, as the measured
    /// times chose (or a probe), and those that stepped it whole.
    pub steps_split: u64,
    pub steps_kept_whole: u64,
    /// Large islands whose sweeps rank 0 shared with every worker by
    /// blocks (`--island-blocks`, `solver::sweeps_by_blocks`,
    /// `cluster::shared_island`; one whose solve ended before its first
    /// sweep is not counted), and the rounds of messages their sweeps
    /// took.
    pub islands_shared: u64,
    pub block_exchanges: u64,
    pub message_latency_s: f64,
    /// Wall seconds rank 0 spent inside the stages that go to other ranks
    /// when there are some (pair tasks, island solves, group steps; the
    /// outermost only), waiting for replies included.
    pub distributable_s: f64,
    /// That share of the run's wall time: the thesis's p (eq. 4.3), on one
    /// rank the share of the work the cluster can take.
    pub parallel_fraction: f64,
    /// 1 / (1 − p): the most any number of ranks can speed the run up.
    pub amdahl_bound: f64,
    /// Seconds the group steps took, each counted where it ran.
    pub group_s: f64,
    /// Of those, the share in each step's largest group (summed over the
    /// steps; a split group's parts count apart): no number of ranks takes
    /// the group stage below this share of its one-rank time.
    pub largest_group_share: f64,
    /// The most R ranks can speed the group stage up, for R in
    /// `BOUND_RANKS`: the group steps' seconds over the sum, step by step,
    /// of max(the largest group, all the groups / R), where each group runs
    /// whole on one rank and every rank is as fast as this run's.
    pub group_speedup_bound: Vec<RankBound>,
    /// The same bound were each group's event loop shared: a group takes
    /// its time outside the loop plus the loop's critical path through the
    /// bodies its events and searches read and move
    /// (`step::event_path`), every event on a rank of its own as soon as
    /// what it depends on has ended, messages free. Only where the loops
    /// were timed (`--predict`); empty otherwise.
    #[serde(default)]
    pub event_shared_bound: Vec<RankBound>,
    /// The event loops' seconds over their critical paths, summed over
    /// the groups and steps: how many events at a time the loops hold
    /// (0 where they were not timed).
    #[serde(default)]
    pub event_loop_parallelism: f64,
    /// The whole step on R ranks, for R in `BOUND_RANKS`, predicted from
    /// this run's measured tasks and bytes over `prediction_link` with the
    /// scheduler's rules (`cluster::predict`). Only a one-rank run
    /// predicts (it measures every task); empty on several ranks.
    #[serde(default)]
    pub predicted: Vec<PredictedRanks>,
    /// The link the prediction assumed (`--link-latency-us`,
    /// `--link-bytes-per-s`).
    #[serde(default)]
    pub prediction_link: Option<PredictionLink>,
    /// Seconds the prediction spent encoding and decoding the tasks'
    /// messages to time them, which it leaves out of the one-rank time.
    #[serde(default)]
    pub prediction_measuring_s: f64,
}

/// One entry of `Distribution::predicted`.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PredictedRanks {
    pub ranks: u32,
    /// This run's wall seconds over `wall_s`.
    pub speedup: f64,
    /// The run's steps, predicted on `ranks` ranks.
    pub wall_s: f64,
    /// The longest step so predicted.
    pub worst_step_s: f64,
    /// What `wall_s` is made of (to rounding): rank 0's own seconds and
    /// each distributable stage's predicted seconds, summed over the steps.
    #[serde(default)]
    pub by_stage: PredictedStages,
}

/// A predicted wall split by what takes it (`PredictedRanks::by_stage`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PredictedStages {
    /// Rank 0's own: everything outside the distributable stages
    /// (integration, broadphase, planning, merging, the leak check, the
    /// outputs), the same on any number of ranks.
    pub coordinator_s: f64,
    pub narrowphase_s: f64,
    pub island_solves_s: f64,
    pub group_steps_s: f64,
    /// The first stage of the groups split before they step.
    pub prepare_pairs_s: f64,
}

impl PredictedStages {
    /// Their sum: the predicted wall, to rounding.
    pub fn total_s(&self) -> f64 {
        self.coordinator_s
            + self.narrowphase_s
            + self.island_solves_s
            + self.group_steps_s
            + self.prepare_pairs_s
    }
}

/// The link `Distribution::predicted` assumed between rank 0 and each worker.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
pub struct PredictionLink {
    /// One way (half a round trip).
    pub latency_s: f64,
    pub bytes_per_s: f64,
}

/// One entry of `Distribution::group_speedup_bound`.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct RankBound {
    pub ranks: u32,
    pub speedup: f64,
}

/// The rank counts `Distribution::group_speedup_bound` is given for (the
/// many-ranks series': `scripts/bench_many_ranks.sh`).
pub const BOUND_RANKS: [u32; 4] = [2, 4, 8, 16];

/// What the group steps cost: each body's share of its group's time in the
/// last step (the schedule's prediction of the next), and the run's totals
/// for `Distribution`. Never part of a result; not checkpointed.
#[derive(Clone, Debug, Default)]
pub struct GroupWork {
    pub body_cost: Vec<f64>,
    pub seconds: f64,
    pub largest_seconds: f64,
    /// For each of `BOUND_RANKS`, the steps' max(largest group, all / R).
    pub bound_seconds: [f64; BOUND_RANKS.len()],
    /// The same with each group's event loop shared (`GroupSeconds::shared_s`).
    pub shared_bound_seconds: [f64; BOUND_RANKS.len()],
    /// The event loops' seconds and critical paths, summed, where they were
    /// timed (`StepSettings::time_events`).
    pub event_loops: Option<LoopSeconds>,
}

impl GroupWork {
    pub fn new(bodies: usize) -> Self {
        GroupWork {
            body_cost: vec![0.0; bodies],
            ..Default::default()
        }
    }

    /// Adds one step's group steps: each one's seconds where it ran, and
    /// its event loop's seconds and critical path.
    pub fn add_step(&mut self, groups: impl Iterator<Item = GroupSeconds>) {
        let (mut all, mut largest, mut longest_shared) = (0.0, 0.0_f64, 0.0_f64);
        for g in groups {
            all += g.busy_s;
            largest = largest.max(g.busy_s);
            longest_shared = longest_shared.max(g.shared_s());
            if let Some(l) = g.event_loop {
                self.event_loops = Some(self.event_loops.unwrap_or_default().plus(l));
            }
        }
        self.seconds += all;
        self.largest_seconds += largest;
        for (k, &r) in BOUND_RANKS.iter().enumerate() {
            let share = all / f64::from(r);
            self.bound_seconds[k] += largest.max(share);
            self.shared_bound_seconds[k] += longest_shared.max(share);
        }
    }
}

/// One group step's seconds, as `GroupWork::add_step` takes them.
#[derive(Clone, Copy, Debug, Default)]
pub struct GroupSeconds {
    /// The whole step where it ran.
    pub busy_s: f64,
    /// Its event loop's searches and events (part of `busy_s`) and their
    /// critical path (`step::event_path`), where the loop was timed.
    pub event_loop: Option<LoopSeconds>,
}

impl GroupSeconds {
    /// The step with its event loop shared: its time outside the loop
    /// plus the loop's critical path (the whole step where not timed).
    fn shared_s(&self) -> f64 {
        self.event_loop
            .map_or(self.busy_s, |l| self.busy_s - l.work_s + l.path_s)
    }
}

impl Distribution {
    /// Fills in `parallel_fraction`, `amdahl_bound` and the group work for
    /// a run of `wall_s`.
    pub fn close(&mut self, wall_s: f64, groups: &GroupWork) {
        self.group_s = groups.seconds;
        self.largest_group_share = if groups.seconds > 0.0 {
            groups.largest_seconds / groups.seconds
        } else {
            0.0
        };
        let p = if wall_s > 0.0 {
            (self.distributable_s / wall_s).clamp(0.0, 1.0)
        } else {
            0.0
        };
        self.parallel_fraction = p;
        self.amdahl_bound = 1.0 / (1.0 - p).max(1e-6);
        self.group_speedup_bound = rank_bounds(groups.seconds, &groups.bound_seconds);
        if let Some(loops) = groups.event_loops {
            self.event_shared_bound = rank_bounds(groups.seconds, &groups.shared_bound_seconds);
            self.event_loop_parallelism = if loops.path_s > 0.0 {
                loops.work_s / loops.path_s
            } else {
                1.0
            };
        }
    }
}

/// `seconds` over each of `bounds`, for each of `BOUND_RANKS`.
fn rank_bounds(seconds: f64, bounds: &[f64; BOUND_RANKS.len()]) -> Vec<RankBound> {
    BOUND_RANKS
        .iter()
        .zip(bounds)
        .map(|(&ranks, &bound)| RankBound {
            ranks,
            speedup: if bound > 0.0 { seconds / bound } else { 1.0 },
        })
        .collect()
}

/// Times the outermost distributable stage: stages called from inside
/// another (a group step's own pair tasks and solves) are not counted again.
#[derive(Clone, Debug, Default)]
pub(crate) struct StageClock {
    depth: u32,
    started: Option<std::time::Instant>,
}

impl StageClock {
    pub(crate) fn enter(&mut self) {
        if self.depth == 0 {
            self.started = Some(std::time::Instant::now());
        }
        self.depth += 1;
    }

    /// Returns the seconds to add (the outermost stage's wall time, else 0).
    pub(crate) fn leave(&mut self) -> f64 {
        self.depth -= 1;
        if self.depth == 0 {
            self.started
                .take()
                .map_or(0.0, |t| t.elapsed().as_secs_f64())
        } else {
            0.0
        }
    }
}
