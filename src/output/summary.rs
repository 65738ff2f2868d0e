//! `summary.json`: what a run did, how long it took and how it ended.

use crate::step::Fall;
use crate::step::StageSeconds;
use crate::step::stats::Counters;
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
    pub per_rank: Vec<RankLine>,
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

/// One entry of `per_rank`: the rank's own account (its fields at the top
/// level, as before) and where it ran: its host and what it sent and
/// received per frame (`frame_interval_s` of simulated time, the frames
/// `worst_frame_s` times; a last, partial frame counts as one).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct RankLine {
    #[serde(flatten)]
    pub account: RankSummary,
    /// The rank's host name (on a lab from `scripts/lab.sh`, its "PC").
    #[serde(default)]
    pub host: String,
    #[serde(default)]
    pub bytes_sent_per_frame: f64,
    #[serde(default)]
    pub bytes_received_per_frame: f64,
    /// Rate of the link between rank 0 and this rank, bytes per second,
    /// measured at start-up; absent for rank 0, the renderer, and ranks
    /// reached through shared memory (no slower than an empty message).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub link_bytes_per_s: Option<f64>,
    /// The widest vector instructions of the rank's CPU that faer's kernels
    /// choose between (`cluster::vector_units`: "avx512f", "avx2+fma" or
    /// "sse2"); ranks that differ here may round some factorisations
    /// differently (`notes` then says so).
    #[serde(default)]
    pub vector_units: String,
}

/// Where a rank ran, as rank 0 learnt at start-up.
#[derive(Clone, Debug, Default)]
pub struct RankHost {
    pub host: String,
    pub link_bytes_per_s: Option<f64>,
    pub vector_units: String,
}

impl RankLine {
    /// `account`'s line, on `hosts[account.rank]` (an empty name if absent), over
    /// a run of `frames` frames.
    pub fn new(account: RankSummary, hosts: &[RankHost], frames: u64) -> RankLine {
        let at = hosts
            .get(account.rank as usize)
            .cloned()
            .unwrap_or_default();
        let per_frame = |bytes: u64| {
            if frames > 0 {
                bytes as f64 / frames as f64
            } else {
                0.0
            }
        };
        RankLine {
            host: at.host,
            bytes_sent_per_frame: per_frame(account.bytes_sent),
            bytes_received_per_frame: per_frame(account.bytes_received),
            link_bytes_per_s: at.link_bytes_per_s,
            vector_units: at.vector_units,
            account,
        }
    }
}

impl std::ops::Deref for RankLine {
    type Target = RankSummary;
    fn deref(&self) -> &RankSummary {
        &self.account
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn per_rank_keeps_its_fields_at_the_top_level_and_adds_host_and_bytes_per_frame() {
        let account = RankSummary {
            rank: 1,
            role: "worker".into(),
            bytes_sent: 300,
            bytes_received: 600,
            ..Default::default()
        };
        let hosts = [
            RankHost {
                host: "pc1".into(),
                link_bytes_per_s: None,
                vector_units: "avx2+fma".into(),
            },
            RankHost {
                host: "pc2".into(),
                link_bytes_per_s: Some(1.1e6),
                vector_units: "sse2".into(),
            },
        ];
        let json = serde_json::to_value(RankLine::new(account, &hosts, 3)).unwrap();
        assert_eq!(json["rank"], 1);
        assert_eq!(json["role"], "worker");
        assert_eq!(json["bytes_sent"], 300);
        assert_eq!(json["host"], "pc2");
        assert_eq!(json["bytes_sent_per_frame"], 100.0);
        assert_eq!(json["bytes_received_per_frame"], 200.0);
        assert_eq!(json["link_bytes_per_s"], 1.1e6);
        assert_eq!(json["vector_units"], "sse2");
        // Rank 0 has no link of its own to report, and an unknown rank no host.
        let line = RankLine::new(RankSummary::default(), &hosts, 0);
        let json = serde_json::to_value(&line).unwrap();
        assert!(json.get("link_bytes_per_s").is_none());
        assert_eq!(json["bytes_sent_per_frame"], 0.0);
        let back: RankLine = serde_json::from_value(json).unwrap();
        assert_eq!(back.host, "pc1");
        assert_eq!(
            RankLine::new(
                RankSummary {
                    rank: 7,
                    ..Default::default()
                },
                &hosts,
                1
            )
            .host,
            ""
        );
    }
}
