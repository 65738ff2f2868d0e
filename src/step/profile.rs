//! What a one-rank run's distributable work costs, step by step: each
//! outermost stage call's tasks with their measured seconds and the bytes
//! their messages would carry, and the wall time of the step around them.
//! A `StepSink` (`cluster::predict`) turns it into the speed-up N ranks
//! would give; the step itself never reads it.

use super::stats::Distribution;
use crate::contact::block_sweeps::{BlockRunner, SweptBlocks};
use serde::Serialize;
use serde::de::DeserializeOwned;
use std::time::Instant;

/// The distributable stages, as `Executor`'s methods name them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StageKind {
    Narrowphase,
    IslandSolves,
    GroupSteps,
    PreparePairs,
}

/// One task of a stage call, as it ran here.
#[derive(Clone, Debug, Default)]
pub struct TaskCost {
    pub seconds: f64,
    /// Its request and its answer, encoded as the cluster sends them.
    pub bytes: u64,
    /// The seconds encoding and decoding them take, where it is sent out.
    pub codec: Codec,
    /// What the scheduler knows of it beforehand, in its stage's own
    /// units (an island's `cost_units`, a group's `predicted_s`): what it
    /// orders and cuts the tasks by. 0: unknown, its seconds stand in.
    pub estimate: f64,
    /// An island solve that several ranks would share by blocks
    /// (`contact::solver::sweeps_by_blocks`): rank 0 solves it with every
    /// worker, never sends it whole.
    pub by_blocks: bool,
    /// The rounds of block sweeps of the task's large islands, in order
    /// (an island solve's own; a group step's, of the islands it solved).
    pub rounds: Vec<BlockRound>,
}

/// One round of a large island's sweeps by blocks (`contact::block_sweeps`)
/// as it ran here, block by block.
#[derive(Clone, Debug, Default)]
pub struct BlockRound {
    pub blocks: Vec<BlockWork>,
}

/// One block's part of a round.
#[derive(Clone, Copy, Debug, Default)]
pub struct BlockWork {
    /// Its rows, by which the ranks share the blocks out.
    pub rows: usize,
    pub seconds: f64,
    /// Its state to a worker and back, and at a solve's first round its
    /// system, encoded as the cluster sends them.
    pub bytes: u64,
}

/// A message as the cluster would send it, encoded and decoded here: its
/// bytes, and the seconds its sender takes to encode it and its receiver
/// to decode it.
#[derive(Clone, Copy, Debug, Default)]
pub struct Wire {
    pub bytes: u64,
    pub encode_s: f64,
    pub decode_s: f64,
}

impl Wire {
    /// `value` encoded as `cluster::protocol` encodes it (bincode,
    /// standard configuration), and decoded back.
    pub fn of<T: Serialize + DeserializeOwned>(value: &T) -> Wire {
        let config = bincode::config::standard();
        let started = Instant::now();
        let bytes = bincode::serde::encode_to_vec(value, config).expect("a task encodes");
        let encode_s = started.elapsed().as_secs_f64();
        let started = Instant::now();
        let (decoded, _): (T, usize) =
            bincode::serde::decode_from_slice(&bytes, config).expect("a task decodes");
        let decode_s = started.elapsed().as_secs_f64();
        drop(decoded);
        Wire {
            bytes: bytes.len() as u64,
            encode_s,
            decode_s,
        }
    }
}

/// What encoding and decoding a task sent out costs each side: rank 0
/// encodes its request and decodes its answer, the worker the other way.
#[derive(Clone, Copy, Debug, Default)]
pub struct Codec {
    pub rank0_s: f64,
    pub worker_s: f64,
}

impl TaskCost {
    /// A task of `seconds` whose request and answer travel as measured.
    pub fn sent(seconds: f64, request: Wire, answer: Wire) -> TaskCost {
        TaskCost {
            seconds,
            bytes: request.bytes + answer.bytes,
            codec: Codec {
                rank0_s: request.encode_s + answer.decode_s,
                worker_s: request.decode_s + answer.encode_s,
            },
            ..Default::default()
        }
    }

    /// What the scheduler orders and cuts it by (`estimate`).
    pub fn known(&self) -> f64 {
        if self.estimate > 0.0 {
            self.estimate
        } else {
            self.seconds
        }
    }

    /// Seconds of the task's block sweeps.
    pub fn swept_s(&self) -> f64 {
        self.rounds
            .iter()
            .flat_map(|r| &r.blocks)
            .map(|b| b.seconds)
            .sum()
    }
}

/// Sweeps every block here in turn, as `InlineBlocks` does, and records
/// each round (`--predict`). The bytes of a block's state are counted at
/// the solve's first round, with its system, and stand for every round.
#[derive(Default)]
pub struct TimedBlocks {
    pub rounds: Vec<BlockRound>,
    /// Per block, the bytes of its state there and back.
    state_bytes: Vec<u64>,
}

impl BlockRunner for TimedBlocks {
    fn sweep_blocks(&mut self, blocks: &mut SweptBlocks, sweeps: usize) {
        let count = blocks.blocks.len();
        if blocks.first {
            self.state_bytes = (0..count)
                .map(|k| 2 * wire_bytes(&blocks.state_of(k)))
                .collect();
        }
        let mut round = BlockRound::default();
        for k in 0..count {
            let opened = if blocks.first {
                wire_bytes(&blocks.system_of(k))
            } else {
                0
            };
            let started = Instant::now();
            blocks.sweep_here(k, sweeps);
            round.blocks.push(BlockWork {
                rows: blocks.blocks.rows(k),
                seconds: started.elapsed().as_secs_f64(),
                bytes: self.state_bytes[k] + opened,
            });
        }
        self.rounds.push(round);
    }
}

/// One outermost call of a distributable stage.
#[derive(Clone, Debug)]
pub struct StageCall {
    pub kind: StageKind,
    pub tasks: Vec<TaskCost>,
}

/// One step: its wall seconds on this rank and the stage calls within.
/// What is not in a stage call is rank 0's own (integration, broadphase,
/// planning, merging, the leak check, the outputs).
#[derive(Clone, Debug, Default)]
pub struct StepProfile {
    pub wall_s: f64,
    pub stages: Vec<StageCall>,
}

impl StepProfile {
    /// Seconds of the step's stage calls.
    pub fn stage_seconds(&self) -> f64 {
        self.stages
            .iter()
            .flat_map(|c| &c.tasks)
            .map(|t| t.seconds)
            .sum()
    }
}

/// Takes each step's profile as it ends, and writes what it made of them
/// into the run's `Distribution` at the end.
pub trait StepSink {
    fn step(&mut self, profile: &StepProfile);
    fn close(&mut self, distribution: &mut Distribution);
}

/// Records the stage calls of `Inline` between step boundaries
/// (`Executor::groups_stepped`, once a step).
pub struct Profiler {
    sink: Box<dyn StepSink>,
    step: StepProfile,
    step_started: Instant,
    call: Vec<TaskCost>,
    /// Seconds of this step spent measuring messages (`wire`): the
    /// profile's own, not the step's.
    measuring_s: f64,
    /// The same over the run.
    measured_s: f64,
}

impl Profiler {
    pub fn new(sink: Box<dyn StepSink>) -> Self {
        Profiler {
            sink,
            step: StepProfile::default(),
            step_started: Instant::now(),
            call: Vec::new(),
            measuring_s: 0.0,
            measured_s: 0.0,
        }
    }

    /// `value` as a message (`Wire::of`), the time that takes left out of
    /// the step's wall.
    pub(crate) fn wire<T: Serialize + DeserializeOwned>(&mut self, value: &T) -> Wire {
        let started = Instant::now();
        let wire = Wire::of(value);
        self.measuring_s += started.elapsed().as_secs_f64();
        wire
    }

    /// Adds a task of the call under way: its seconds since `started`,
    /// its request and its answer.
    pub(crate) fn task<T: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned>(
        &mut self,
        started: Instant,
        request: &T,
        answer: &R,
    ) {
        let seconds = started.elapsed().as_secs_f64();
        let (request, answer) = (self.wire(request), self.wire(answer));
        self.add(TaskCost::sent(seconds, request, answer));
    }

    /// Adds a task of the call under way, as measured.
    pub(crate) fn add(&mut self, task: TaskCost) {
        self.call.push(task);
    }

    /// Ends the call under way.
    pub(crate) fn end_call(&mut self, kind: StageKind) {
        let tasks = std::mem::take(&mut self.call);
        self.step.stages.push(StageCall { kind, tasks });
    }

    /// Ends the step under way and starts the next.
    pub(crate) fn end_step(&mut self) {
        let now = Instant::now();
        self.step.wall_s = (now - self.step_started).as_secs_f64() - self.measuring_s;
        self.step_started = now;
        self.measured_s += std::mem::take(&mut self.measuring_s);
        self.sink.step(&self.step);
        self.step.stages.clear();
    }

    /// The run is over: what is left of its last step counts, and the
    /// sink writes its figures.
    pub(crate) fn close(&mut self, distribution: &mut Distribution) {
        self.end_step();
        self.sink.close(distribution);
        distribution.prediction_measuring_s = self.measured_s;
    }
}

/// Bytes `value` takes in the cluster's messages (bincode, standard
/// configuration, as `cluster::protocol::encode`), counted without
/// writing them.
pub fn wire_bytes<T: Serialize>(value: &T) -> u64 {
    let mut size = bincode::enc::write::SizeWriter::default();
    bincode::serde::encode_into_writer(value, &mut size, bincode::config::standard())
        .expect("counting encoded bytes cannot fail");
    size.bytes_written as u64
}
