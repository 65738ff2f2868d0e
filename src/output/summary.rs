//! `summary.json`: what a run did, how long it took and how it ended.

use crate::step::Fall;
use crate::step::stats::{Counters, StageSeconds};
pub use crate::step::stats::{Distribution, RankSummary};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Summary {
    pub scene: String,
    pub ranks: u32,
    pub bodies: usize,
    pub steps: u64,
    pub sim_time_s: f64,
    pub wall_time_s: f64,
    pub dt_s: f64,
    pub frame_interval_s: f64,
    pub worst_frame_s: f64,
    pub realtime_factor: f64,
    /// `duration`, `rest` or `failed`.
    pub end_reason: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub failure: Option<String>,
    pub max_penetration_m: f64,
    pub energy_initial_j: f64,
    pub energy_final_j: f64,
    pub stage_seconds: StageSeconds,
    pub per_rank: Vec<RankSummary>,
    pub state_hash: String,
    pub counters: Counters,
    pub bodies_resting: usize,
    pub bodies_fallen: usize,
    /// Each body that fell below `fall_z` and the simulated time it fell at
    /// (the end of the step that found it there), in the order they fell:
    /// `[{ "body": i, "time": t }]`.
    #[serde(default)]
    pub fallen: Vec<Fall>,
    /// Stages distributed to workers, and how often each ran on rank 0 alone.
    pub distributed: Distribution,
    pub frames_rendered: u64,
    pub frames_dropped: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub render_adapter: Option<String>,
    pub notes: Vec<String>,
}
