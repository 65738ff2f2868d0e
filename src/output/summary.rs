//! `summary.json`: what a run did, how long it took and how it ended.

use crate::step::Fall;
use crate::step::stats::{Counters, StageSeconds};
pub use crate::step::stats::{Distribution, RankSummary};
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Summary {
    pub scene: String,
    /// The scene file the run was loaded from (absolute where it could be
    /// resolved, as given otherwise), and the FNV-1a 64 of its bytes as 16 hex
    /// digits (`scene_digest`). `rigidsim view` refuses an output folder whose
    /// digest is not that of the scene it is given. `None` in summaries
    /// written before these fields existed, or if the file could not be read
    /// again when the run started.
    #[serde(default)]
    pub scene_path: Option<String>,
    #[serde(default)]
    pub scene_digest: Option<String>,
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

/// The FNV-1a 64 of a scene file's bytes, 16 hex digits: `summary.json`'s
/// `scene_digest`. It tells apart the scenes a folder could have been written
/// from (an edited copy, another scene); it is no defence against a forger.
pub fn scene_digest(bytes: &[u8]) -> String {
    let mut h = super::FNV_OFFSET;
    super::fnv1a(&mut h, bytes);
    format!("{h:016x}")
}

/// `summary.json`'s `scene_path` and `scene_digest` for the scene at `path`,
/// read when the run starts. Both `None` if the file cannot be read again.
pub fn scene_file_identity(path: &Path) -> (Option<String>, Option<String>) {
    match std::fs::read(path) {
        Ok(bytes) => {
            let shown = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
            (
                Some(shown.display().to_string()),
                Some(scene_digest(&bytes)),
            )
        }
        Err(_) => (None, None),
    }
}
