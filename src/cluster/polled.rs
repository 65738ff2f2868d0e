//! Rank 0's executor for a group step of its own while it serves the workers.

use crate::body::ObjectDef;
use crate::collision::narrowphase::{self, PairResult, PairTask};
use crate::contact::solver::{self, IslandResult, IslandTask};
use crate::output::summary::{Distribution, RankSummary};
use crate::step::{
    Executor, GroupInput, GroupParams, GroupReply, Inline, PreparedPairs, StepStatic,
};

/// Rank 0's executor for a group step of its own within a self-scheduled
/// stage: every stage the group calls runs inline, after serving the
/// workers (`poll`).
pub(super) struct Polled<'p> {
    inline: Inline,
    poll: &'p mut dyn FnMut(),
}

impl<'p> Polled<'p> {
    pub(super) fn new(poll: &'p mut dyn FnMut()) -> Self {
        Polled {
            inline: Inline::default(),
            poll,
        }
    }
}

impl Executor for Polled<'_> {
    // Task by task, polling between them: a group's first batch holds all
    // its pairs (milliseconds for a pile), and a worker waiting for its
    // next chunk would wait for all of it.
    fn narrowphase(&mut self, objects: &[ObjectDef], tasks: Vec<PairTask>) -> Vec<PairResult> {
        tasks
            .iter()
            .map(|t| {
                (self.poll)();
                narrowphase::query_pair(objects, t)
            })
            .collect()
    }
    fn solve_islands(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
        tasks
            .iter()
            .map(|t| {
                (self.poll)();
                solver::solve_island(t)
            })
            .collect()
    }
    fn step_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<GroupReply> {
        (self.poll)();
        self.inline.step_groups(st, params, inputs)
    }
    fn prepare_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<PreparedPairs> {
        (self.poll)();
        self.inline.prepare_groups(st, params, inputs)
    }
    fn finish(&mut self) -> (Vec<RankSummary>, Distribution) {
        self.inline.finish()
    }
}
