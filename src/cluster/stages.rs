//! Each distributed stage of rank 0's executor: pair tasks, island solves
//! and group steps, on rank 0 alone or shared out.

use super::MpiExecutor;
use super::network::Stage;
use super::polled::Polled;
use super::protocol::{Reply, Request as Req};
use super::scatter::{COORDINATOR_SHARE, SELF_SCHEDULED_SHARE};
use super::schedule;
use super::shared_island::SharedBlocks;
use crate::body::ObjectDef;
use crate::collision::narrowphase::{self, PairResult, PairTask};
use crate::contact::solver::{self, IslandResult, IslandTask};
use crate::step::{GroupInput, GroupParams, GroupReply, StepStatic, run_group};
use std::time::Instant;

impl MpiExecutor<'_> {
    /// Workers for a group stage of `total` predicted seconds over `tasks`
    /// tasks: (the cost model's, the one taken), the measured times
    /// (`group_choice`, `StageChoice`) sending it out where the model
    /// would keep it on rank 0.
    pub(super) fn group_workers(&self, total: f64, tasks: usize) -> (usize, usize) {
        let modelled =
            self.workers_for_stage(Stage::StepGroups, total, tasks, SELF_SCHEDULED_SHARE);
        let workers = self
            .group_choice
            .workers(modelled, self.workers_without_link(total), tasks);
        (modelled, workers)
    }
}

impl MpiExecutor<'_> {
    pub(super) fn narrowphase_stage(
        &mut self,
        objects: &[ObjectDef],
        tasks: Vec<PairTask>,
    ) -> Vec<PairResult> {
        let units: Vec<f64> = tasks
            .iter()
            .map(|t| {
                let (a, b) = (t.object_a as usize, t.object_b as usize);
                schedule::pair_units(
                    t.warm.len(),
                    self.parts[a],
                    self.parts[b],
                    self.polygons[a],
                    self.polygons[b],
                )
            })
            .collect();
        let costs: Vec<f64> = units.iter().map(|u| u * self.model.pair_coef).collect();
        let total: f64 = costs.iter().sum();
        let workers = self.workers_for(total, tasks.len());
        if workers == 0 {
            self.dist.narrowphase_local += 1;
            let clock = Instant::now();
            let r: Vec<PairResult> = tasks
                .iter()
                .map(|t| narrowphase::query_pair(objects, t))
                .collect();
            let s = clock.elapsed().as_secs_f64();
            self.model.calibrate_pairs(units.iter().sum(), s);
            self.book[0].busy_s += s;
            self.book[0].tasks_np += tasks.len() as u64;
            return r;
        }
        self.dist.narrowphase_distributed += 1;
        let (results, total_busy, own_tasks) = self.distribute(
            workers,
            COORDINATOR_SHARE,
            tasks,
            &costs,
            |share| Req::Narrowphase { tasks: share },
            |own| {
                own.iter()
                    .map(|t| narrowphase::query_pair(objects, t))
                    .collect()
            },
            |reply| match reply {
                Reply::Narrowphase { results, busy_s } => Some((results, busy_s)),
                _ => None,
            },
        );
        self.model.calibrate_pairs(units.iter().sum(), total_busy);
        self.book[0].tasks_np += own_tasks.len() as u64;
        results
    }

    pub(super) fn solve_islands_stage(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
        if self.roles.workers.is_empty() || !tasks.iter().any(solver::sweeps_by_blocks) {
            return self.solve_whole_islands(tasks);
        }
        // The islands swept by blocks first, every rank sharing each; then
        // the others shared out whole.
        let (by_blocks, whole): (Vec<usize>, Vec<usize>) =
            (0..tasks.len()).partition(|&i| solver::sweeps_by_blocks(&tasks[i]));
        let mut results = vec![IslandResult::default(); tasks.len()];
        let started = Instant::now();
        for &i in &by_blocks {
            results[i] = solver::solve_island_with(&tasks[i], &mut SharedBlocks::new(self));
        }
        self.book[0].busy_s += started.elapsed().as_secs_f64();
        self.book[0].tasks_is += by_blocks.len() as u64;
        let mut tasks: Vec<Option<IslandTask>> = tasks.into_iter().map(Some).collect();
        let rest: Vec<IslandTask> = whole
            .iter()
            .map(|&i| tasks[i].take().expect("once"))
            .collect();
        for (r, &i) in self.solve_whole_islands(rest).into_iter().zip(&whole) {
            results[i] = r;
        }
        results
    }

    /// The stage's islands, each solved whole on one rank.
    fn solve_whole_islands(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
        let units: Vec<f64> = tasks.iter().map(IslandTask::cost_units).collect();
        let costs: Vec<f64> = units.iter().map(|u| u * self.model.island_coef).collect();
        let total: f64 = costs.iter().sum();
        // Self-scheduled: rank 0 works at its full speed (as for groups).
        let modelled = self.workers_for_stage(
            Stage::SolveIslands,
            total,
            tasks.len(),
            SELF_SCHEDULED_SHARE,
        );
        // Where measured times send the solves out, as for the group steps.
        let workers =
            self.solve_choice
                .workers(modelled, self.workers_without_link(total), tasks.len());
        if workers > 0 && modelled == 0 {
            self.dist.solves_by_measure += 1;
        }
        let started = Instant::now();
        if workers == 0 {
            self.dist.solve_local += 1;
            let r: Vec<IslandResult> = tasks.iter().map(solver::solve_island).collect();
            let s = started.elapsed().as_secs_f64();
            self.model.calibrate_islands(units.iter().sum(), s);
            self.book[0].busy_s += s;
            self.book[0].tasks_is += tasks.len() as u64;
            self.solve_choice.record(false, total, s);
            return r;
        }
        self.dist.solve_distributed += 1;
        let (results, total_busy, own_tasks) = self.self_schedule(
            workers,
            tasks,
            &costs,
            |share| Req::SolveIslands { tasks: share },
            |own, _| solver::solve_island(&own),
            |reply| match reply {
                Reply::SolveIslands { results, busy_s } => Some((results, busy_s)),
                _ => None,
            },
        );
        self.model.calibrate_islands(units.iter().sum(), total_busy);
        self.book[0].tasks_is += own_tasks.len() as u64;
        self.solve_choice
            .record(true, total, started.elapsed().as_secs_f64());
        results
    }

    /// Workers a self-scheduled stage of this estimated cost takes where
    /// its measured times send it out (`StageChoice`): those the model would
    /// use without the link's bytes (a much slower worker stays left out),
    /// at least one.
    fn workers_without_link(&self, estimated_s: f64) -> usize {
        if self.roles.workers.is_empty() {
            0
        } else {
            schedule::workers_to_use(
                estimated_s,
                &self.speeds,
                SELF_SCHEDULED_SHARE,
                self.latency_s,
            )
            .max(1)
        }
    }

    pub(super) fn step_groups_stage(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<GroupReply> {
        // Seconds, from what the same bodies' groups took last step.
        let costs: Vec<f64> = inputs.iter().map(GroupInput::predicted_s).collect();
        let total: f64 = costs.iter().sum();
        let (modelled, workers) = self.group_workers(total, inputs.len());
        if workers > 0 && modelled == 0 {
            self.dist.groups_by_measure += 1;
        }
        let started = Instant::now();
        let replies = self.step_groups_on(st, params, inputs, costs, workers);
        self.group_choice
            .record(workers > 0, total, started.elapsed().as_secs_f64());
        replies
    }

    /// The group steps on rank 0 alone (`workers` = 0) or self-scheduled
    /// over rank 0 and `workers` workers.
    fn step_groups_on(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
        costs: Vec<f64>,
        workers: usize,
    ) -> Vec<GroupReply> {
        if workers == 0 {
            // On rank 0, whose executor (this one) still scatters the
            // groups' own narrowphase batches and island solves where they
            // pay; those count their own tasks and busy time.
            self.dist.groups_local += 1;
            return inputs
                .into_iter()
                .map(|input| run_group(st, input, self))
                .collect();
        }
        self.dist.groups_distributed += 1;
        let (inputs, costs) = self.prepare_large_groups(st, params, workers, inputs, costs);
        let (replies, _, own) = self.self_schedule(
            workers,
            inputs,
            &costs,
            |share| Req::StepGroups {
                params: params.clone(),
                inputs: share,
            },
            |input, poll| run_group(st, input, &mut Polled::new(poll)),
            |reply| match reply {
                Reply::StepGroups { replies, busy_s } => Some((replies, busy_s)),
                _ => None,
            },
        );
        for &i in &own {
            let (pairs, islands) = replies[i].tasks();
            self.book[0].tasks_np += pairs;
            self.book[0].tasks_is += islands;
        }
        // The islands rank 0's own group steps captured (`GroupReply`; the
        // workers write theirs), which the step takes in group order: all
        // with the first of its replies, in the order it ran them.
        let mut replies = replies;
        if let Some(&first) = own.iter().min() {
            let captured: Vec<_> = own
                .iter()
                .flat_map(|&i| std::mem::take(&mut replies[i].1))
                .collect();
            replies[first].1 = captured;
        }
        replies
    }
}
