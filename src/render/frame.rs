//! A frame of poses, as rank 0 publishes it, and where frames go
//! (`FrameSink`).

use crate::output::summary::RankSummary;
use crate::output::{FNV_OFFSET, fnv1a};
use serde::{Deserialize, Serialize};

/// One body's pose as the renderer needs it (render message, SPEC 3.4).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct Pose {
    pub position: [f32; 3],
    pub orientation: [f32; 4],
}

/// A frame of poses for the renderer.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Frame {
    pub index: u64,
    /// The index of the first frame this run publishes: 0, or on a resumed
    /// run the checkpoint's next frame index. Every frame carries it because
    /// the render rank never sees the checkpoint, and the first frame it
    /// receives may not be the run's first (frames can be dropped).
    pub first_index: u64,
    pub time: f64,
    pub poses: Vec<Pose>,
}

impl Frame {
    /// FNV-1a 64 of the frame's index and poses: the same on rank 0, which
    /// keeps it in checkpoints, and on the rank that draws the frame.
    pub fn digest(&self) -> u64 {
        let mut h = FNV_OFFSET;
        fnv1a(&mut h, &self.index.to_le_bytes());
        for p in &self.poses {
            for x in p.position.iter().chain(&p.orientation) {
                fnv1a(&mut h, &x.to_le_bytes());
            }
        }
        h
    }

    /// The text its PNG carries under `render::FRAME_MARK_KEY`.
    pub fn mark(&self) -> String {
        frame_mark(self.index, self.digest())
    }
}

pub(super) fn frame_mark(index: u64, digest: u64) -> String {
    format!("frame {index} poses {digest:016x}")
}

/// Where frames go: nowhere, a renderer on this rank, or the render rank.
pub trait FrameSink {
    fn publish(&mut self, frame: Frame);
    /// A resumed run, before its first frame: the digests of the frames
    /// `0..first` the run it continues published.
    fn expect_earlier(&mut self, _digests: Vec<u64>) {}
    /// Ends the stream; returns (frames rendered, frames dropped, adapter, notes).
    fn finish(&mut self, last: Frame) -> (u64, u64, Option<String>, Vec<String>);
    /// The render rank's line in `per_rank`, when frames go to another rank.
    fn rank_summary(&self) -> Option<RankSummary> {
        None
    }
    /// Why the frames' destination stopped answering, if it did (the render
    /// rank, in `finish`): the job must then end without it.
    fn lost(&self) -> Option<String> {
        None
    }
}

pub struct NoFrames;

impl FrameSink for NoFrames {
    fn publish(&mut self, _frame: Frame) {}
    fn finish(&mut self, _last: Frame) -> (u64, u64, Option<String>, Vec<String>) {
        (0, 0, None, Vec::new())
    }
}
