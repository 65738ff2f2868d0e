//! The speed-up a lab can expect: a one-rank run's steps
//! (`step::profile`), each stage call's measured tasks replayed on N ranks
//! with the scheduler's own rules, over a link given as parameters. Pure:
//! no MPI, so a one-rank run predicts what the cluster would do with it.
//!
//! A step on N ranks takes rank 0's own seconds (everything outside the
//! distributable stages, as measured) plus, for each stage call, the
//! faster of running it on rank 0 alone and sharing it out: the
//! self-scheduled stages (island solves, group steps, the first stage of
//! large groups) as `scatter.rs` hands out chunks, the narrowphase by the
//! greedy plan (`schedule::assign`). Every message crosses rank 0's one
//! link, one after another (`schedule::Link`). Groups count as the run
//! stepped them: whole, or split into parts with `--split-groups`. Large
//! islands cut in blocks (`--island-blocks`) count as `shared_island`
//! shares them, round by round over every rank: in the island stage, and
//! in the group steps rank 0 keeps.

use super::scatter::{CHUNK_SHARE, COORDINATOR_SHARE};
use super::schedule;
use crate::step::profile::{
    BlockRound, Codec, StageCall, StageKind, StepProfile, StepSink, TaskCost,
};
use crate::step::stats::{
    BOUND_RANKS, Distribution, PredictedRanks, PredictedStages, PredictionLink,
};

/// The link the prediction assumes between rank 0 and each worker.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LinkModel {
    /// One way, seconds: half a round trip.
    pub latency_s: f64,
    pub bytes_per_s: f64,
}

impl LinkModel {
    /// A lab's 100 Mbit/s switched network as `scripts/lab.sh` measured it
    /// (`bench/results/vm-2cpu/network.md`, 2 PCs): 1.1 ms round trips and
    /// 7.7 MB/s of MPI payload.
    pub const LAB_100_MBIT: LinkModel = LinkModel {
        latency_s: 550e-6,
        bytes_per_s: 7.7e6,
    };
}

/// Replays each step on `BOUND_RANKS` ranks (`StepSink`).
pub struct Prediction {
    link: LinkModel,
    one_rank_s: f64,
    predicted_s: [f64; BOUND_RANKS.len()],
    by_stage: [PredictedStages; BOUND_RANKS.len()],
    worst_step_s: [f64; BOUND_RANKS.len()],
}

impl Prediction {
    pub fn new(link: LinkModel) -> Self {
        Prediction {
            link,
            one_rank_s: 0.0,
            predicted_s: [0.0; BOUND_RANKS.len()],
            by_stage: [PredictedStages::default(); BOUND_RANKS.len()],
            worst_step_s: [0.0; BOUND_RANKS.len()],
        }
    }
}

impl StepSink for Prediction {
    fn step(&mut self, profile: &StepProfile) {
        let own = (profile.wall_s - profile.stage_seconds()).max(0.0);
        self.one_rank_s += profile.wall_s;
        let mut step_s = [own; BOUND_RANKS.len()];
        let mut step = [PredictedStages {
            coordinator_s: own,
            ..Default::default()
        }; BOUND_RANKS.len()];
        for call in &profile.stages {
            let best = stage_s_up_to(call, MOST_RANKS, &self.link);
            for (i, &ranks) in BOUND_RANKS.iter().enumerate() {
                let stage_s = best[ranks as usize - 1];
                step_s[i] += stage_s;
                *stage_entry(&mut step[i], call.kind) += stage_s;
            }
        }
        for i in 0..BOUND_RANKS.len() {
            // Rank 0 alone is always a choice: never longer than the step
            // took (which the sums above meet only to their rounding).
            step_s[i] = step_s[i].min(profile.wall_s);
            self.predicted_s[i] += step_s[i];
            add_stages(&mut self.by_stage[i], &step[i]);
            self.worst_step_s[i] = self.worst_step_s[i].max(step_s[i]);
        }
    }

    fn close(&mut self, distribution: &mut Distribution) {
        distribution.prediction_link = Some(PredictionLink {
            latency_s: self.link.latency_s,
            bytes_per_s: self.link.bytes_per_s,
        });
        distribution.predicted = BOUND_RANKS
            .iter()
            .enumerate()
            .map(|(i, &ranks)| {
                let wall_s = self.predicted_s[i];
                PredictedRanks {
                    ranks,
                    wall_s,
                    speedup: if wall_s > 0.0 {
                        self.one_rank_s / wall_s
                    } else {
                        1.0
                    },
                    worst_step_s: self.worst_step_s[i],
                    by_stage: self.by_stage[i],
                }
            })
            .collect();
    }
}

/// Where a stage call's predicted seconds count.
fn stage_entry(stages: &mut PredictedStages, kind: StageKind) -> &mut f64 {
    match kind {
        StageKind::Narrowphase => &mut stages.narrowphase_s,
        StageKind::IslandSolves => &mut stages.island_solves_s,
        StageKind::GroupSteps => &mut stages.group_steps_s,
        StageKind::PreparePairs => &mut stages.prepare_pairs_s,
    }
}

fn add_stages(sum: &mut PredictedStages, step: &PredictedStages) {
    sum.coordinator_s += step.coordinator_s;
    sum.narrowphase_s += step.narrowphase_s;
    sum.island_solves_s += step.island_solves_s;
    sum.group_steps_s += step.group_steps_s;
    sum.prepare_pairs_s += step.prepare_pairs_s;
}

/// The most ranks predicted.
const MOST_RANKS: usize = BOUND_RANKS[BOUND_RANKS.len() - 1] as usize;

/// Seconds one stage call takes on 1, 2, … `most` ranks: alone, or shared
/// with as many workers as is fastest (the scheduler chooses how many,
/// `schedule::workers_to_use_over_link`, and keeps a stage home where
/// none pays). Alone on several ranks, rank 0 still shares its large
/// islands' sweeps by blocks (`blocked_s`). Each rank count's sharing is
/// simulated once.
fn stage_s_up_to(call: &StageCall, most: usize, link: &LinkModel) -> Vec<f64> {
    if call.kind == StageKind::IslandSolves && call.tasks.iter().any(|t| t.by_blocks) {
        return islands_by_blocks_up_to(call, most, link);
    }
    let alone: f64 = call.tasks.iter().map(|t| t.seconds).sum();
    let mut best = vec![alone; most];
    let order = largest_first(&call.tasks);
    for r in 2..=most {
        let home: f64 = call.tasks.iter().map(|t| blocked_s(t, r, link)).sum();
        let shared = if call.tasks.len() < 2 {
            f64::INFINITY
        } else {
            match call.kind {
                StageKind::Narrowphase => planned_s(&call.tasks, r, link),
                StageKind::IslandSolves | StageKind::GroupSteps | StageKind::PreparePairs => {
                    self_scheduled_s(&call.tasks, &order, r, link)
                }
            }
        };
        best[r - 1] = best[r - 2].min(home).min(shared);
    }
    best
}

/// An island stage with islands the ranks share by blocks
/// (`cluster::stages`): on several ranks rank 0 solves those first, each
/// with every worker, then the others as any island stage.
fn islands_by_blocks_up_to(call: &StageCall, most: usize, link: &LinkModel) -> Vec<f64> {
    let rest = StageCall {
        kind: StageKind::IslandSolves,
        tasks: call
            .tasks
            .iter()
            .filter(|t| !t.by_blocks)
            .cloned()
            .collect(),
    };
    let rest_s = stage_s_up_to(&rest, most, link);
    let blocked = || call.tasks.iter().filter(|t| t.by_blocks);
    (1..=most)
        .map(|r| blocked().map(|t| blocked_s(t, r, link)).sum::<f64>() + rest_s[r - 1])
        .collect()
}

/// A task's seconds with its large islands' sweeps shared by blocks over
/// `ranks` ranks (`cluster::shared_island`): all but the block sweeps as
/// measured, then each round as rank 0 runs it (`round_s`). One rank, or
/// a task without rounds: its seconds.
fn blocked_s(task: &TaskCost, ranks: usize, link: &LinkModel) -> f64 {
    if ranks < 2 || task.rounds.is_empty() {
        return task.seconds;
    }
    let rounds: f64 = task.rounds.iter().map(|r| round_s(r, ranks, link)).sum();
    task.seconds - task.swept_s() + rounds
}

/// One round of block sweeps on `ranks` ranks: the blocks planned by
/// their rows over the ranks (`schedule::assign`, rank 0 at a full share,
/// as `shared_island` plans them), each worker's sent and answered over
/// rank 0's link.
fn round_s(round: &BlockRound, ranks: usize, link: &LinkModel) -> f64 {
    let rows: Vec<f64> = round.blocks.iter().map(|b| b.rows as f64).collect();
    let slot = schedule::assign(&rows, &vec![1.0; ranks], 1.0);
    let mut load = vec![0.0; ranks];
    let mut bytes = vec![0u64; ranks];
    for (block, &r) in round.blocks.iter().zip(&slot) {
        load[r] += block.seconds;
        bytes[r] += block.bytes;
    }
    slots_s(&load, &bytes, link)
}

/// Rank 0's link, which carries one message at a time.
struct SharedLink<'l> {
    model: &'l LinkModel,
    free_at: f64,
}

impl SharedLink<'_> {
    /// A request of `bytes` (its answer's bytes counted with it) posted at
    /// `t`: when the worker has it.
    fn send(&mut self, t: f64, bytes: u64) -> f64 {
        let start = t.max(self.free_at);
        self.free_at = start + bytes as f64 / self.model.bytes_per_s;
        self.free_at + self.model.latency_s
    }
}

/// Self-scheduling (`scatter.rs`): the tasks largest first by what the
/// scheduler knows of them (`TaskCost::known`); rank 0 takes one at a time
/// from the back, each worker a chunk from the front of at least
/// `CHUNK_SHARE` of its share of what is known to be left, the next chunk
/// one round trip after it answers; each task takes the seconds it took,
/// and a chunk the encoding and decoding of its messages, rank 0's part of
/// which also keeps rank 0 from its own tasks. Every rank as fast as this
/// one.
fn self_scheduled_s(tasks: &[TaskCost], order: &[usize], ranks: usize, link: &LinkModel) -> f64 {
    let (mut front, mut back) = (0, order.len());
    let mut left: f64 = tasks.iter().map(TaskCost::known).sum();
    let mut rank0 = 0.0_f64;
    let mut worker_free = vec![0.0_f64; ranks - 1];
    let mut shared = SharedLink {
        model: link,
        free_at: 0.0,
    };
    let mut answered = 0.0_f64;
    while front < back {
        let (w, t) = worker_free
            .iter()
            .copied()
            .enumerate()
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .expect("at least one worker");
        if rank0 <= t {
            back -= 1;
            rank0 += tasks[order[back]].seconds;
            left -= tasks[order[back]].known();
            continue;
        }
        let want = CHUNK_SHARE * left / ranks as f64;
        let (first, mut known, mut cost, mut bytes) = (front, 0.0, 0.0, 0);
        let mut codec = Codec::default();
        while front < back && (front == first || known < want) {
            let task = &tasks[order[front]];
            known += task.known();
            cost += task.seconds;
            bytes += task.bytes;
            codec.rank0_s += task.codec.rank0_s;
            codec.worker_s += task.codec.worker_s;
            front += 1;
        }
        left -= known;
        rank0 += codec.rank0_s;
        let done = shared.send(t, bytes) + cost + codec.worker_s + codec.rank0_s;
        answered = answered.max(done + link.latency_s);
        worker_free[w] = done + 2.0 * link.latency_s;
    }
    rank0.max(answered)
}

/// The greedy plan (`schedule::assign`): one message per worker, rank 0
/// planned at `COORDINATOR_SHARE` of its speed; rank 0 encodes and decodes
/// the workers' messages besides its own tasks.
fn planned_s(tasks: &[TaskCost], ranks: usize, link: &LinkModel) -> f64 {
    let costs: Vec<f64> = tasks.iter().map(|t| t.seconds).collect();
    let slot = schedule::assign(&costs, &vec![1.0; ranks], COORDINATOR_SHARE);
    let mut load = vec![0.0; ranks];
    let mut bytes = vec![0u64; ranks];
    for (task, &r) in tasks.iter().zip(&slot) {
        load[r] += task.seconds;
        bytes[r] += task.bytes;
        if r > 0 {
            load[0] += task.codec.rank0_s;
            load[r] += task.codec.worker_s;
        }
    }
    slots_s(&load, &bytes, link)
}

/// Rank 0's `load[0]` beside each worker's: its `bytes` over rank 0's link
/// after the workers' before it, its load, its answer back. A worker with
/// no bytes has nothing to do.
fn slots_s(load: &[f64], bytes: &[u64], link: &LinkModel) -> f64 {
    let mut shared = SharedLink {
        model: link,
        free_at: 0.0,
    };
    (1..load.len())
        .filter(|&r| bytes[r] > 0)
        .map(|r| shared.send(0.0, bytes[r]) + load[r] + link.latency_s)
        .fold(load[0], f64::max)
}

/// Task indices by decreasing estimate (`TaskCost::known`), ties by index.
fn largest_first(tasks: &[TaskCost]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..tasks.len()).collect();
    order.sort_by(|&i, &j| {
        tasks[j]
            .known()
            .total_cmp(&tasks[i].known())
            .then(i.cmp(&j))
    });
    order
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::step::profile::BlockWork;

    /// Seconds one stage call takes on up to `ranks` ranks.
    fn stage_s(call: &StageCall, ranks: usize, link: &LinkModel) -> f64 {
        stage_s_up_to(call, ranks, link)[ranks - 1]
    }

    fn tasks(seconds: &[f64], bytes: u64) -> Vec<TaskCost> {
        seconds
            .iter()
            .map(|&seconds| TaskCost {
                seconds,
                bytes,
                ..Default::default()
            })
            .collect()
    }

    const FREE: LinkModel = LinkModel {
        latency_s: 0.0,
        bytes_per_s: f64::INFINITY,
    };

    /// Equal tasks over a free link: N ranks take 1/N of the time, to
    /// the rounding of whole tasks.
    #[test]
    fn equal_tasks_on_a_free_link_divide_by_the_ranks() {
        let call = StageCall {
            kind: StageKind::GroupSteps,
            tasks: tasks(&[1e-3; 64], 1000),
        };
        for ranks in [2, 4, 8] {
            let s = stage_s(&call, ranks, &FREE);
            let ideal = 64e-3 / ranks as f64;
            assert!(
                s >= ideal - 1e-12 && s <= ideal + 1e-3,
                "{ranks} ranks: {s}"
            );
        }
    }

    /// A task sent out costs its encoding and decoding: rank 0's part
    /// (its request, its answer) and the worker's, on the chunk's path and
    /// rank 0's part on rank 0's time too. Two 1 s tasks on 2 ranks over a
    /// free link: 1 s without, 1.3 s with 0.1 s and 0.2 s of it.
    #[test]
    fn a_sent_tasks_encoding_counts() {
        let mut call = StageCall {
            kind: StageKind::GroupSteps,
            tasks: tasks(&[1.0, 1.0], 1),
        };
        assert_eq!(stage_s(&call, 2, &FREE), 1.0);
        for task in &mut call.tasks {
            task.codec = Codec {
                rank0_s: 0.1,
                worker_s: 0.2,
            };
        }
        assert!((stage_s(&call, 2, &FREE) - 1.3).abs() < 1e-12);
        // The greedy plan: the worker's 1 s task and its 0.2 s, rank 0's
        // 1 s and its 0.1 s.
        let planned = StageCall {
            kind: StageKind::Narrowphase,
            ..call
        };
        assert!((stage_s(&planned, 2, &FREE) - 1.2).abs() < 1e-12);
    }

    /// One task that is 95 % of the work bounds any number of ranks.
    #[test]
    fn the_largest_task_bounds_the_stage() {
        let mut seconds = vec![95e-3];
        seconds.extend([1e-3; 5]);
        let call = StageCall {
            kind: StageKind::GroupSteps,
            tasks: tasks(&seconds, 1000),
        };
        let s = stage_s(&call, 16, &FREE);
        assert!((s - 95e-3).abs() < 1e-12, "{s}");
    }

    /// Over a slow link the bytes outweigh the work, and the stage stays
    /// on rank 0: never slower than alone.
    #[test]
    fn a_stage_whose_bytes_outweigh_it_stays_home() {
        let call = StageCall {
            kind: StageKind::IslandSolves,
            tasks: tasks(&[1e-5; 10], 100_000),
        };
        let slow = LinkModel {
            latency_s: 1e-3,
            bytes_per_s: 1e6,
        };
        let alone: f64 = call.tasks.iter().map(|t| t.seconds).sum();
        assert_eq!(stage_s(&call, 4, &slow), alone);
        let planned = StageCall {
            kind: StageKind::Narrowphase,
            ..call
        };
        assert_eq!(stage_s(&planned, 4, &slow), alone);
    }

    /// The link carries one message at a time: four workers' chunks of
    /// 1 MB over 1 MB/s take at least 4 s to send, whatever the work.
    #[test]
    fn the_shared_link_serialises_the_messages() {
        let call = StageCall {
            kind: StageKind::GroupSteps,
            tasks: tasks(&[10.0; 8], 1_000_000),
        };
        let link = LinkModel {
            latency_s: 0.0,
            bytes_per_s: 1e6,
        };
        let s = stage_s(&call, 5, &link);
        // Alone: 80 s. Rank 0 and the workers share it, each worker's
        // chunk waiting for the ones sent before.
        assert!(s > 80.0 / 5.0 && s < 80.0, "{s}");
    }

    /// A whole step: rank 0's own seconds stay, the stages shrink.
    #[test]
    fn a_step_keeps_rank_0s_own_seconds() {
        let mut p = Prediction::new(FREE);
        p.step(&StepProfile {
            wall_s: 0.1,
            stages: vec![StageCall {
                kind: StageKind::GroupSteps,
                tasks: tasks(&[10e-3; 8], 10),
            }],
        });
        let mut d = Distribution::default();
        p.close(&mut d);
        let two = &d.predicted[0];
        assert_eq!(two.ranks, 2);
        // 20 ms of rank 0's own, 80 ms of groups halved.
        assert!((two.wall_s - 0.06).abs() < 1e-12, "{}", two.wall_s);
        assert!((two.speedup - 0.1 / 0.06).abs() < 1e-9);
        // Split by what takes it: the same 20 ms of rank 0's own on every
        // count, the groups' 40 ms here and 10 ms on 8 ranks.
        assert!((two.by_stage.coordinator_s - 0.02).abs() < 1e-12);
        assert!((two.by_stage.group_steps_s - 0.04).abs() < 1e-12);
        assert_eq!(two.by_stage.island_solves_s, 0.0);
        let eight = d.predicted.iter().find(|p| p.ranks == 8).unwrap();
        assert!((eight.by_stage.coordinator_s - 0.02).abs() < 1e-12);
        assert!((eight.by_stage.group_steps_s - 0.01).abs() < 1e-12);
        for p in &d.predicted {
            assert!((p.by_stage.total_s() - p.wall_s).abs() <= 1e-12 * p.wall_s);
        }
    }

    /// An island of 10 s whose 8 s of sweeps are one round of four equal
    /// blocks (of 2 s and `bytes` each).
    fn blocked_island(bytes: u64) -> TaskCost {
        let block = BlockWork {
            rows: 300,
            seconds: 2.0,
            bytes,
        };
        TaskCost {
            seconds: 10.0,
            bytes: 1000,
            by_blocks: true,
            rounds: vec![BlockRound {
                blocks: vec![block; 4],
            }],
            ..Default::default()
        }
    }

    /// Its blocks shared over a free link: the 2 s that are not block
    /// sweeps stay on rank 0, the round divides by the ranks; the island
    /// stage's other islands follow it.
    #[test]
    fn an_island_shared_by_blocks_divides_its_sweeps() {
        let mut call = StageCall {
            kind: StageKind::IslandSolves,
            tasks: vec![blocked_island(0)],
        };
        assert_eq!(stage_s(&call, 1, &FREE), 10.0);
        assert_eq!(stage_s(&call, 2, &FREE), 6.0);
        assert_eq!(stage_s(&call, 4, &FREE), 4.0);
        call.tasks.extend(tasks(&[1.0, 1.0], 10));
        assert_eq!(stage_s(&call, 2, &FREE), 7.0);
        // As a group step's islands, where rank 0 keeps the group.
        let group = StageCall {
            kind: StageKind::GroupSteps,
            tasks: vec![TaskCost {
                by_blocks: false,
                ..blocked_island(0)
            }],
        };
        assert_eq!(stage_s(&group, 4, &FREE), 4.0);
    }

    /// The blocks' states cross rank 0's link each round, and the island
    /// stage shares them whatever they cost: at 1 MB a block over 1 MB/s
    /// two ranks take 8 s where a free link gives 6.
    #[test]
    fn a_rounds_bytes_cross_the_link() {
        let call = StageCall {
            kind: StageKind::IslandSolves,
            tasks: vec![blocked_island(1_000_000)],
        };
        let link = LinkModel {
            latency_s: 0.0,
            bytes_per_s: 1e6,
        };
        // Rank 0: 2 s + 4 s of its blocks; the worker: 2 s of bytes, 4 s.
        assert_eq!(stage_s(&call, 2, &link), 2.0 + 6.0);
    }

    /// The scheduler orders and cuts tasks by its estimates, and pays for
    /// those that were off: a 4 s group estimated as the smallest reaches
    /// the worker last, and two ranks take 5 s where 4 s would do.
    #[test]
    fn tasks_go_out_by_their_estimates() {
        let mut call = StageCall {
            kind: StageKind::GroupSteps,
            tasks: tasks(&[4.0, 1.0, 1.0, 1.0, 1.0], 0),
        };
        assert_eq!(stage_s(&call, 2, &FREE), 4.0);
        for (task, estimate) in call.tasks.iter_mut().zip([1.0, 1.0, 1.0, 1.0, 4.0]) {
            task.estimate = estimate;
        }
        assert_eq!(stage_s(&call, 2, &FREE), 5.0);
    }
}
