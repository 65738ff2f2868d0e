//! Rank 0's executor (`MpiExecutor`): its state, its start, the workers'
//! reports, and the `Executor` seam the step calls. Its other parts, by
//! concern: `messages`, `scatter`, `stages`, `prepare`, `network`.

use super::Roles;
use super::network::{Network, Stage};
use super::protocol::{Reply, Request as Req, WorkerReport};
use super::schedule::{self, CostModel};
use super::speed::SpeedMeter;
use crate::body::ObjectDef;
use crate::collision::narrowphase::{PairResult, PairTask};
use crate::contact::solver::{IslandResult, IslandTask};
use crate::output::summary::{Distribution, RankSummary};
use crate::scene::ForceWindow;
use crate::step::stats::StageClock;
use crate::step::{
    Executor, GroupInput, GroupParams, GroupReply, PreparedPairs, SPLIT_AUTO_MIN_MEMBERS,
    SPLIT_MIN_MEMBERS, StepStatic,
};
use mpi::topology::SimpleCommunicator;
use std::time::Instant;

#[derive(Default, Clone)]
pub(super) struct RankBook {
    pub(super) tasks_np: u64,
    pub(super) tasks_is: u64,
    pub(super) cost_s: f64,
    pub(super) busy_s: f64,
    pub(super) waiting_s: f64,
    pub(super) bytes_sent: u64,
    pub(super) bytes_received: u64,
    /// Rows times sweeps of the shared islands' blocks it swept.
    pub(super) block_rows: u64,
}

/// Rank 0's executor: decides per stage and per frame whether to distribute;
/// pair tasks by the thesis's greedy plan (one message to each worker, its
/// own share, gather), island solves and group steps by self-scheduling
/// (chunks handed out as workers answer, rank 0 taking the smallest tasks
/// in between); results merged in task order either way.
pub struct MpiExecutor<'w> {
    pub(super) world: &'w SimpleCommunicator,
    pub(super) roles: Roles,
    pub(super) model: CostModel,
    /// Estimated speed per slot: slot 0 is rank 0, slot k is `roles.workers[k-1]`.
    pub(super) speeds: Vec<f64>,
    pub(super) book: Vec<RankBook>,
    pub(super) meters: Vec<SpeedMeter>,
    /// Each slot's speed at sweeping blocks of a shared island
    /// (`shared_island`), rows swept against seconds.
    pub(super) block_meters: Vec<SpeedMeter>,
    pub(super) latency_s: f64,
    pub(super) dist: Distribution,
    pub(super) clock: StageClock,
    pub(super) polygons: Vec<usize>,
    pub(super) parts: Vec<usize>,
    /// Distribute regardless of cost (tests of determinism and balance).
    pub force_distribute: bool,
    /// Split the groups that would hold up the other ranks
    /// (`Executor::split_groups`; on unless `--whole-groups`).
    pub split_where_it_pays: bool,
    pub(super) net: Network,
    /// Where the group steps and the island solves went and what they
    /// took (`StageChoice`).
    pub(super) group_choice: schedule::StageChoice,
    /// Whether splitting the groups that would hold the others up pays,
    /// measured as for `group_choice` ("out" is split), and this step's
    /// choice, predicted cost and start (`Executor::groups_stepped`).
    pub(super) split_choice: schedule::StageChoice,
    pub(super) split_step: Option<(bool, f64, Instant)>,
    pub(super) solve_choice: schedule::StageChoice,
}

impl MpiExecutor<'_> {
    /// Runs a distributed stage: its time counts as distributable, and the
    /// bytes it moved teach the link's cost model.
    fn in_stage<R>(&mut self, stage: Stage, run: impl FnOnce(&mut Self) -> R) -> R {
        self.clock.enter();
        let mark = self.traffic_mark(stage);
        let r = run(self);
        self.learn_traffic(stage, mark);
        self.dist.distributable_s += self.clock.leave();
        r
    }
}

impl<'w> MpiExecutor<'w> {
    pub fn new(world: &'w SimpleCommunicator, roles: Roles, objects: &[ObjectDef]) -> Self {
        let slots = roles.workers.len() + 1;
        let mut exec = MpiExecutor {
            world,
            model: CostModel::default(),
            speeds: vec![1.0; slots],
            book: vec![RankBook::default(); slots],
            meters: vec![SpeedMeter::default(); slots],
            block_meters: vec![SpeedMeter::default(); slots],
            latency_s: 0.0,
            dist: Distribution::default(),
            clock: StageClock::default(),
            polygons: objects.iter().map(|o| o.polygon_count).collect(),
            parts: objects.iter().map(|o| o.parts.len()).collect(),
            force_distribute: false,
            split_where_it_pays: true,
            net: Network::default(),
            group_choice: schedule::StageChoice::default(),
            split_choice: schedule::StageChoice::default(),
            split_step: None,
            solve_choice: schedule::StageChoice::default(),
            roles,
        };
        exec.measure_latency();
        exec.measure_link_rates();
        exec
    }

    /// Tells workers and renderer to stop; collects their reports.
    pub fn stop(&mut self) -> Vec<(i32, WorkerReport)> {
        let mut reports = Vec::new();
        for &w in &self.roles.workers.clone() {
            self.send(w, &Req::Stop);
            if let Reply::Report(r) = self.receive(w) {
                reports.push((w, r));
            }
        }
        reports
    }

    pub fn summaries(&self, workers: &[(i32, WorkerReport)]) -> Vec<RankSummary> {
        let mut out = vec![RankSummary {
            rank: 0,
            role: "coordinator".into(),
            busy_s: self.book[0].busy_s,
            waiting_s: self.book[0].waiting_s,
            tasks: self.book[0].tasks_np + self.book[0].tasks_is,
            narrowphase_tasks: self.book[0].tasks_np,
            island_tasks: self.book[0].tasks_is,
            estimated_cost_s: self.book[0].cost_s,
            bytes_sent: self.book.iter().map(|b| b.bytes_sent).sum(),
            bytes_received: self.book.iter().map(|b| b.bytes_received).sum(),
            speed: self.speeds[0],
            frames_rendered: 0,
            block_rows_swept: self.book[0].block_rows,
        }];
        for (k, &w) in self.roles.workers.iter().enumerate() {
            let rep = workers
                .iter()
                .find(|(r, _)| *r == w)
                .map(|(_, r)| r.clone())
                .unwrap_or_default();
            out.push(RankSummary {
                rank: w as u32,
                role: "worker".into(),
                busy_s: rep.busy_s,
                waiting_s: rep.waiting_s,
                tasks: rep.narrowphase_tasks + rep.island_tasks,
                narrowphase_tasks: rep.narrowphase_tasks,
                island_tasks: rep.island_tasks,
                estimated_cost_s: self.book[k + 1].cost_s,
                bytes_sent: rep.bytes_sent,
                bytes_received: rep.bytes_received,
                speed: self.speeds[k + 1],
                frames_rendered: 0,
                block_rows_swept: self.book[k + 1].block_rows,
            });
        }
        out
    }
}

impl Executor for MpiExecutor<'_> {
    fn share_forces(&mut self, forces: &[ForceWindow]) {
        let req = Req::Forces {
            forces: forces.to_vec(),
        };
        for &w in &self.roles.workers.clone() {
            self.send(w, &req);
        }
        for &w in &self.roles.workers.clone() {
            let _ = self.receive(w);
        }
    }

    fn finish(&mut self) -> (Vec<RankSummary>, Distribution) {
        let reports = self.stop();
        (self.summaries(&reports), self.dist.clone())
    }

    fn narrowphase(&mut self, objects: &[ObjectDef], tasks: Vec<PairTask>) -> Vec<PairResult> {
        self.in_stage(Stage::Narrowphase, |e| e.narrowphase_stage(objects, tasks))
    }

    fn solve_islands(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
        self.in_stage(Stage::SolveIslands, |e| e.solve_islands_stage(tasks))
    }

    fn step_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<GroupReply> {
        self.in_stage(Stage::StepGroups, |e| {
            e.step_groups_stage(st, params, inputs)
        })
    }

    fn prepare_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<PreparedPairs> {
        self.in_stage(Stage::StepGroups, |e| {
            e.prepare_groups_stage(st, params, inputs)
        })
    }

    fn split_groups(&mut self, groups: &[(f64, usize)]) -> Vec<bool> {
        let none = vec![false; groups.len()];
        if !self.split_where_it_pays {
            return none;
        }
        // A group predicted above each rank's fair share of the step's
        // group work, where the group steps would go out now, would hold
        // the other ranks up.
        let total: f64 = groups.iter().map(|&(c, _)| c).sum();
        let (_, workers) = self.group_workers(total, groups.len());
        if workers == 0 {
            return none;
        }
        let fair = total / (1 + workers) as f64;
        // `--force-distribute` (a test aid) takes every group that may be
        // split at all, so that small scenes take this path too.
        let fewest = if self.force_distribute {
            SPLIT_MIN_MEMBERS
        } else {
            SPLIT_AUTO_MIN_MEMBERS
        };
        let above: Vec<bool> = groups
            .iter()
            .map(|&(c, members)| c > fair && members >= fewest)
            .collect();
        if !above.contains(&true) {
            return above;
        }
        // Whether it pays is measured: on a settled pile the split groups'
        // steps share out, while bodies pour in their parts meet so often
        // that the runs lost cost more than the sharing gains.
        let split = self.split_choice.goes_out();
        self.split_step = Some((split, total, Instant::now()));
        if split {
            self.dist.steps_split += 1;
            above
        } else {
            self.dist.steps_kept_whole += 1;
            none
        }
    }

    fn groups_stepped(&mut self) {
        if let Some((split, cost, started)) = self.split_step.take() {
            self.split_choice
                .record(split, cost, started.elapsed().as_secs_f64());
        }
    }
}
