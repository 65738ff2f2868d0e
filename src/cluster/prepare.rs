//! The first stage of large groups' steps (`prepare_pairs`), their pairs
//! cut into ranges and shared out before the groups step.

use super::MpiExecutor;
use super::polled::Polled;
use super::protocol::{Reply, Request as Req};
use crate::step::{GroupInput, GroupParams, Inline, PreparedPairs, StepStatic, prepare_pairs};
use std::collections::BTreeMap;
use std::time::Instant;

impl MpiExecutor<'_> {
    /// The first stage of each of these groups for all its pairs, before
    /// they are split (`Executor::prepare_groups`): on rank 0 alone, or
    /// each group's pairs cut into ranges (`prepared_cuts`) and self-scheduled,
    /// as for `prepare_large_groups`.
    pub(super) fn prepare_groups_stage(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<PreparedPairs> {
        let costs: Vec<f64> = inputs
            .iter()
            .map(|i| i.predicted_s() * FIRST_STAGE_SHARE)
            .collect();
        let total: f64 = costs.iter().sum();
        let pairs: usize = inputs.iter().map(GroupInput::pair_count).sum();
        let (_, workers) = self.group_workers(total, pairs);
        if workers == 0 {
            let clock = Instant::now();
            let prepared: Vec<PreparedPairs> = inputs
                .iter()
                .map(|input| {
                    prepare_pairs(st, input, (0, input.pair_count()), &mut Inline::default())
                })
                .collect();
            self.book[0].busy_s += clock.elapsed().as_secs_f64();
            self.book[0].tasks_np += prepared.iter().map(PreparedPairs::tasks).sum::<u64>();
            return prepared;
        }
        let ranks = workers + 1;
        let jobs: Vec<(usize, usize, f64)> = (0..inputs.len())
            .map(|g| {
                let pairs = inputs[g].pair_count();
                let cuts = if pairs >= ranks * MIN_PREPARED_PAIRS {
                    prepared_cuts(pairs, ranks)
                } else {
                    1
                };
                (g, cuts, costs[g])
            })
            .collect();
        self.prepare_in_ranges(st, params, workers, &inputs, &jobs)
    }

    /// The first stage of each group of `jobs` (index into `inputs`, the
    /// number of ranges its pairs are cut into, its estimated seconds),
    /// self-scheduled over rank 0 and `workers` workers (`PreparePairs`);
    /// each group's answers joined, in the order of `jobs`.
    fn prepare_in_ranges(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        workers: usize,
        inputs: &[GroupInput],
        jobs: &[(usize, usize, f64)],
    ) -> Vec<PreparedPairs> {
        let mut shares: Vec<(usize, (usize, usize))> = Vec::new();
        let mut share_costs = Vec::new();
        for &(g, cuts, cost) in jobs {
            let n = inputs[g].pair_count();
            for r in 0..cuts {
                shares.push((g, (r * n / cuts, (r + 1) * n / cuts)));
                share_costs.push(cost / cuts as f64);
            }
        }
        self.dist.groups_prepared += jobs.iter().filter(|&&(_, cuts, _)| cuts > 1).count() as u64;
        let (prepared, _, own) = self.self_schedule(
            workers,
            shares.clone(),
            &share_costs,
            |share| {
                // Each range with what its own pairs read, not the whole
                // group's input (a pile's range names a share of its bodies).
                let (read, shares) = share
                    .into_iter()
                    .enumerate()
                    .map(|(i, (g, (from, to)))| {
                        let trimmed = inputs[g].first_stage_input((from, to));
                        (trimmed, (i as u32, (0, to - from)))
                    })
                    .unzip();
                Req::PreparePairs {
                    params: params.clone(),
                    inputs: read,
                    shares,
                }
            },
            |(g, range), poll| prepare_pairs(st, &inputs[g], range, &mut Polled::new(poll)),
            |reply| match reply {
                Reply::PreparePairs { prepared, busy_s } => Some((prepared, busy_s)),
                _ => None,
            },
        );
        for &i in &own {
            self.book[0].tasks_np += prepared[i].tasks();
        }
        let mut by_group: BTreeMap<usize, Vec<PreparedPairs>> = BTreeMap::new();
        for ((g, _), p) in shares.into_iter().zip(prepared) {
            by_group.entry(g).or_default().push(p);
        }
        jobs.iter()
            .map(|&(g, _, _)| PreparedPairs::joined(by_group.remove(&g).unwrap_or_default()))
            .collect()
    }

    /// A group predicted to take more than its ranks' fair share cannot be
    /// balanced whole: the first stage of its step (each pair's end-of-step
    /// result and time of impact, `prepare_pairs`; about half of a pile's
    /// step) goes out first, its pairs cut into ranges (`prepared_cuts`), and the
    /// group then steps its events from those answers wherever it goes.
    /// Returns the inputs and their costs for the group steps that follow.
    pub(super) fn prepare_large_groups(
        &mut self,
        st: &StepStatic,
        params: &GroupParams,
        workers: usize,
        mut inputs: Vec<GroupInput>,
        mut costs: Vec<f64>,
    ) -> (Vec<GroupInput>, Vec<f64>) {
        let ranks = workers + 1;
        let fair = costs.iter().sum::<f64>() / ranks as f64;
        let large: Vec<usize> = (0..inputs.len())
            .filter(|&g| {
                let pairs = inputs[g].pair_count();
                if inputs[g].is_prepared() {
                    false
                } else if self.force_distribute {
                    // Tests of determinism: every group that can be cut is.
                    pairs >= ranks
                } else {
                    pairs >= ranks * MIN_PREPARED_PAIRS && costs[g] > fair
                }
            })
            .collect();
        if large.is_empty() {
            return (inputs, costs);
        }
        // Each large group's pairs in ranges, costed by the first
        // stage's share of the group's predicted time.
        let jobs: Vec<(usize, usize, f64)> = large
            .iter()
            .map(|&g| {
                let cuts = prepared_cuts(inputs[g].pair_count(), ranks);
                (g, cuts, costs[g] * FIRST_STAGE_SHARE)
            })
            .collect();
        let prepared = self.prepare_in_ranges(st, params, workers, &inputs, &jobs);
        for (&g, p) in large.iter().zip(prepared) {
            inputs[g].set_prepared(p);
            costs[g] *= 1.0 - FIRST_STAGE_SHARE;
        }
        (inputs, costs)
    }
}

/// Share of a large group's step its first stage takes (`prepare_pairs`),
/// as measured on a pour's pile.
const FIRST_STAGE_SHARE: f64 = 0.45;
/// A group's first stage is cut into ranges of at least this many pairs
/// per rank (below, messages cost more than the share saves).
const MIN_PREPARED_PAIRS: usize = 16;
/// Ranges per rank a large group's first stage is cut into (of at least
/// `MIN_PREPARED_PAIRS` / 2 pairs each), self-scheduled: the pairs' costs
/// are far from even (in a pour the bodies dropped last still fall fast),
/// so one equal range per rank would leave the ranks with the cheap ranges
/// waiting.
const PREPARED_CUTS_PER_RANK: usize = 4;

/// How many ranges a group's first stage of `pairs` pairs is cut into,
/// over `ranks` ranks (`PREPARED_CUTS_PER_RANK`).
fn prepared_cuts(pairs: usize, ranks: usize) -> usize {
    (ranks * PREPARED_CUTS_PER_RANK)
        .min(pairs / (MIN_PREPARED_PAIRS / 2))
        .max(ranks)
}
