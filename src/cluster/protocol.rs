//! Every message that crosses ranks (SPEC 3.4). Per distributed stage, one
//! message to each worker and one back for pair tasks; for island solves
//! and group steps a few chunks each way (rank 0 hands out the next chunk
//! as a worker answers, `MpiExecutor::self_schedule`); plus one to the
//! render rank per frame. Bodies travel as ids and changing state only: every rank loaded the
//! scene, so shapes and masses never travel. Encoded with bincode.

use crate::collision::narrowphase::{PairResult, PairTask};
use crate::contact::block_sweeps::{BlockState, BlockSystem};
use crate::contact::solver::{IslandResult, IslandTask};
use crate::render::Frame;
use crate::scene::ForceWindow;
use crate::step::{GroupInput, GroupParams, GroupReply, PreparedPairs};
use serde::{Deserialize, Serialize};

/// Rank 0 → worker requests.
pub const TAG_REQUEST: i32 = 10;
/// Worker → rank 0 replies.
pub const TAG_REPLY: i32 = 11;
/// Rank 0 → renderer frames.
pub const TAG_FRAME: i32 = 12;
/// Renderer → rank 0, once, after the last frame.
pub const TAG_RENDER_REPORT: i32 = 13;
/// Renderer → rank 0, one empty message after each piece of its final
/// work (a queued frame drawn, an earlier frame replayed into the video):
/// rank 0 waits for the report only while these keep coming
/// (`RENDER_DEADLINE`).
pub const TAG_RENDER_ALIVE: i32 = 14;

/// Sent by rank 0 to one worker.
#[derive(Debug, Serialize, Deserialize)]
pub enum Request {
    /// `narrowphase` stage: V-Clip on these body pairs (poses and cached
    /// feature ids included). Collision request of the thesis.
    Narrowphase { tasks: Vec<PairTask> },
    /// `solve_islands` stage: these contact systems (one chunk of the
    /// stage's; the next comes when this one is answered). Contact request.
    SolveIslands { tasks: Vec<IslandTask> },
    /// `time_of_impact` stage: these interaction groups (one chunk of the
    /// stage's, largest first), each stepped whole (`step::run_group`: its
    /// end-of-step results, impact events, re-solves), with the step's
    /// start time and step settings. The worker runs their narrowphase batches
    /// and island solves itself.
    StepGroups {
        params: GroupParams,
        inputs: Vec<GroupInput>,
    },
    /// `time_of_impact` stage, before `StepGroups` in a step with a group
    /// too large to share out whole: the first stage (end-of-step results
    /// and times of impact, `step::prepare_pairs`) of these ranges of its
    /// pairs. The group then goes out whole with all its answers.
    PreparePairs {
        params: GroupParams,
        /// What the ranges read of their groups: per range, the part of
        /// its group's input its pairs name (`GroupInput::first_stage_input`).
        inputs: Vec<GroupInput>,
        /// Per range: its group (an index into `inputs`) and its pairs.
        shares: Vec<(u32, (usize, usize))>,
    },
    /// `solve_islands` stage, an island shared by the ranks
    /// (`shared_island`): sweep these blocks `sweeps` times from these
    /// states and send them back. `open` (the solve's first exchange)
    /// carries the blocks' systems, which the worker keeps for the
    /// exchanges after it.
    SweepBlocks {
        open: Option<Vec<BlockSystem>>,
        states: Vec<BlockState>,
        sweeps: u32,
    },
    /// At a step boundary of a live run or a replay of one
    /// (`Executor::share_forces`): the scene's external forces from now on,
    /// all of them (its own `[[forces]]` and the hand's). The worker
    /// answers `Pong`. Never sent by a plain run.
    Forces { forces: Vec<ForceWindow> },
    /// Start-up latency probe: the worker answers `Pong` at once.
    Ping,
    /// Start-up link-rate probe (`MpiExecutor::measure_link_rates`): the
    /// worker echoes the payload at once, so one round trip carries it each
    /// way. Neither side books its bytes: they are not the run's traffic.
    Probe { payload: Vec<u8> },
    /// End of run: the worker answers `Report` and exits.
    Stop,
}

/// Sent by a worker to rank 0, in answer to one `Request`.
#[derive(Debug, Serialize, Deserialize)]
pub enum Reply {
    /// Results in the order of the request's tasks, and the seconds computing them.
    Narrowphase {
        results: Vec<PairResult>,
        busy_s: f64,
    },
    SolveIslands {
        results: Vec<IslandResult>,
        busy_s: f64,
    },
    /// One answer per group of the request, in its order.
    StepGroups {
        replies: Vec<GroupReply>,
        busy_s: f64,
    },
    /// One answer per share of the request, in its order.
    PreparePairs {
        prepared: Vec<PreparedPairs>,
        busy_s: f64,
    },
    /// The blocks' states after the sweeps, in the request's order.
    SweepBlocks {
        states: Vec<BlockState>,
        busy_s: f64,
    },
    Pong,
    /// The `Probe` request's payload, back.
    Probe {
        payload: Vec<u8>,
    },
    Report(WorkerReport),
}

/// A worker's own account of the run (for `summary.json`'s `per_rank`).
#[derive(Debug, Default, Clone, Serialize, Deserialize)]
pub struct WorkerReport {
    pub busy_s: f64,
    pub waiting_s: f64,
    pub narrowphase_tasks: u64,
    pub island_tasks: u64,
    pub bytes_sent: u64,
    pub bytes_received: u64,
}

/// Rank 0 → renderer. Never answered, but for the one report after `Finish`.
#[derive(Debug, Serialize, Deserialize)]
pub enum RenderMessage {
    /// Body poses at a screen update (render message of the thesis).
    Frame(Frame),
    /// A resumed run, before its first frame: the digests of the frames
    /// the run it continues published (`FrameRenderer::expect_earlier`).
    Earlier(Vec<u64>),
    /// The final state: write `preview.png`, close the video, report.
    Finish(Frame),
}

/// Renderer → rank 0 after `Finish`.
#[derive(Debug, Default, Clone, Serialize, Deserialize)]
pub struct RenderReport {
    pub rendered: u64,
    pub dropped: u64,
    pub adapter: Option<String>,
    pub notes: Vec<String>,
    pub busy_s: f64,
    pub bytes_received: u64,
}

pub fn encode<T: Serialize>(value: &T) -> Vec<u8> {
    bincode::serde::encode_to_vec(value, bincode::config::standard())
        .expect("in-memory bincode encoding cannot fail")
}

pub fn decode<T: for<'de> Deserialize<'de>>(bytes: &[u8]) -> Result<T, String> {
    bincode::serde::decode_from_slice(bytes, bincode::config::standard())
        .map(|(v, _)| v)
        .map_err(|e| format!("malformed message ({} bytes): {e}", bytes.len()))
}
