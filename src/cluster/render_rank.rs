//! The render stream: rank 0's side (`RemoteFrames`) and the render rank's
//! loop.

use super::messages::pause;
use super::protocol::{self, RenderMessage, RenderReport, decode, encode};
use crate::output::summary::RankSummary;
use crate::render::{Frame, FrameRenderer, FrameSink};
use crate::scene::Scene;
use mpi::point_to_point::{Destination, Source};
use mpi::request::{Request, StaticScope};
use mpi::topology::{Communicator, SimpleCommunicator};
use std::collections::VecDeque;
use std::path::Path;
use std::time::{Duration, Instant};

/// The render rank silent for this long after the run's last frame is
/// taken as lost. Its final work comes in pieces that each take well under
/// a second (a queued frame drawn, an earlier frame read back into the
/// video), each followed by a `TAG_RENDER_ALIVE` message; the longest
/// silence is ffmpeg finishing the video, a few seconds.
const RENDER_DEADLINE: Duration = Duration::from_secs(30);

/// A frame's send on its way to the renderer, and its buffer (freed once
/// the send completes).
type FrameInFlight = (Request<'static, [u8], StaticScope>, *mut [u8]);

/// Frames the renderer holds at most; beyond this the oldest are dropped
/// (and counted), so a slow renderer never queues without bound.
pub const RENDER_QUEUE: usize = 64;
/// Sends rank 0 keeps in flight at most (MPI copies small frames eagerly, so
/// this bounds rank 0's buffers; the renderer's queue bounds the backlog).
const MAX_FRAMES_IN_FLIGHT: usize = 64;

/// Rank 0's side of the render stream: non-blocking sends with a bounded
/// queue, so rendering never slows the simulation; when the renderer falls
/// behind, frames are dropped and counted.
pub struct RemoteFrames<'w> {
    world: &'w SimpleCommunicator,
    renderer: i32,
    /// The render rank's host, for the message if it stops answering.
    host: String,
    in_flight: Vec<FrameInFlight>,
    pub dropped: u64,
    pub bytes_sent: u64,
    report: Option<RenderReport>,
    /// Set when the render rank stopped answering in `finish`.
    lost: Option<String>,
}

impl<'w> RemoteFrames<'w> {
    pub fn new(world: &'w SimpleCommunicator, renderer: i32, host: String) -> Self {
        RemoteFrames {
            world,
            renderer,
            host,
            in_flight: Vec::new(),
            dropped: 0,
            bytes_sent: 0,
            report: None,
            lost: None,
        }
    }

    /// Completes finished sends and frees their buffers; whether any did.
    fn reap(&mut self) -> bool {
        let before = self.in_flight.len();
        let mut still = Vec::new();
        for (req, buf) in self.in_flight.drain(..) {
            match req.test() {
                // SAFETY: the buffer was leaked from a Box in `post` and MPI is
                // done with it once the request completed.
                Ok(_) => drop(unsafe { Box::from_raw(buf) }),
                Err(req) => still.push((req, buf)),
            }
        }
        self.in_flight = still;
        self.in_flight.len() < before
    }

    /// Waits for the render report without blocking inside MPI: while the
    /// last sends complete and the renderer's `TAG_RENDER_ALIVE` messages
    /// come, and no longer than `RENDER_DEADLINE` after the last of them,
    /// so a render rank that stopped (a frozen PC, a hung GPU driver) ends
    /// the job after the results are written instead of hanging it.
    fn await_report(&mut self) -> Option<RenderReport> {
        let renderer = self.world.process_at_rank(self.renderer);
        // Receives the signs of life that have arrived; whether there were any.
        let take_alive = || {
            let mut any = false;
            while renderer
                .immediate_probe_with_tag(protocol::TAG_RENDER_ALIVE)
                .is_some()
            {
                let _ = renderer.receive_vec_with_tag::<u8>(protocol::TAG_RENDER_ALIVE);
                any = true;
            }
            any
        };
        let mut heard = Instant::now();
        let mut spins = 0u32;
        loop {
            // (Both run: each completes what has arrived.)
            let sent = self.reap();
            if take_alive() | sent {
                heard = Instant::now();
            }
            if self.in_flight.is_empty()
                && renderer
                    .immediate_probe_with_tag(protocol::TAG_RENDER_REPORT)
                    .is_some()
            {
                let (bytes, _) = renderer.receive_vec_with_tag::<u8>(protocol::TAG_RENDER_REPORT);
                // Signs of life sent before the report have arrived before
                // it (same sender): none is left unreceived.
                take_alive();
                return Some(decode(&bytes).unwrap_or_default());
            }
            if heard.elapsed() > RENDER_DEADLINE {
                return None;
            }
            spins += 1;
            pause(spins);
        }
    }

    fn post(&mut self, msg: &RenderMessage) {
        let bytes = encode(msg).into_boxed_slice();
        self.bytes_sent += bytes.len() as u64;
        let raw: *mut [u8] = Box::into_raw(bytes);
        // SAFETY: `raw` stays allocated until the request completes (see `reap`).
        let buf: &'static [u8] = unsafe { &*raw };
        let req = self
            .world
            .process_at_rank(self.renderer)
            .immediate_send_with_tag(StaticScope, buf, protocol::TAG_FRAME);
        self.in_flight.push((req, raw));
    }
}

impl FrameSink for RemoteFrames<'_> {
    fn publish(&mut self, frame: Frame) {
        self.reap();
        if self.in_flight.len() >= MAX_FRAMES_IN_FLIGHT {
            self.dropped += 1;
            return;
        }
        self.post(&RenderMessage::Frame(frame));
    }

    fn expect_earlier(&mut self, digests: Vec<u64>) {
        self.reap();
        self.post(&RenderMessage::Earlier(digests));
    }

    fn lost(&self) -> Option<String> {
        self.lost.clone()
    }

    fn rank_summary(&self) -> Option<RankSummary> {
        let r = self.report.as_ref()?;
        Some(RankSummary {
            rank: self.renderer as u32,
            role: "renderer".into(),
            busy_s: r.busy_s,
            bytes_received: r.bytes_received,
            frames_rendered: r.rendered,
            speed: 1.0,
            ..Default::default()
        })
    }

    fn finish(&mut self, last: Frame) -> (u64, u64, Option<String>, Vec<String>) {
        self.post(&RenderMessage::Finish(last));
        let Some(report) = self.await_report() else {
            let why = format!(
                "render rank {} (on host {}) has not answered for {} s after the last frame; \
                 its frames, preview and video may be incomplete",
                self.renderer,
                self.host,
                RENDER_DEADLINE.as_secs()
            );
            // Said once, by the caller, after the results are written.
            self.lost = Some(why.clone());
            // The sends still in flight are left to MPI with their buffers
            // (MPI may yet read them; rsmpi panics on dropping an unfinished
            // request), and the job ends soon (`lost`).
            for (request, _buffer) in self.in_flight.drain(..) {
                std::mem::forget(request);
            }
            return (0, self.dropped, None, vec![why]);
        };
        self.report = Some(report.clone());
        (
            report.rendered,
            report.dropped + self.dropped,
            report.adapter,
            report.notes,
        )
    }
}

/// The render rank: draws every frame it receives; when several are waiting
/// it draws the newest and counts the others as dropped. Never sends back
/// until the final report.
pub fn renderer_loop(world: &SimpleCommunicator, scene: &Scene, out_dir: &Path) {
    let root = world.process_at_rank(0);
    let mut report = RenderReport::default();
    let mut renderer = match FrameRenderer::new(scene, out_dir) {
        Ok(r) => {
            report.adapter = Some(r.adapter());
            Some(r)
        }
        Err(e) => {
            eprintln!(
                "rigidsim: rank {} (renderer): {e}; frames will not be drawn",
                world.rank()
            );
            report.notes.push(format!("renderer unavailable: {e}"));
            None
        }
    };
    let mut queue: VecDeque<Frame> = VecDeque::new();
    let mut finish: Option<Frame> = None;
    // Once rank 0 has sent the last frame it waits for the report, and
    // takes each of these as a sign of life (`RENDER_DEADLINE`).
    let mut alive = || root.send_with_tag(&[0u8][..], protocol::TAG_RENDER_ALIVE);
    loop {
        // Take in everything that has arrived (blocking only when idle).
        while finish.is_none()
            && (queue.is_empty() || root.immediate_probe_with_tag(protocol::TAG_FRAME).is_some())
        {
            let (bytes, _) = root.receive_vec_with_tag::<u8>(protocol::TAG_FRAME);
            report.bytes_received += bytes.len() as u64;
            match decode::<RenderMessage>(&bytes) {
                Ok(RenderMessage::Frame(f)) => queue.push_back(f),
                Ok(RenderMessage::Earlier(digests)) => {
                    if let Some(r) = renderer.as_mut() {
                        r.expect_earlier(digests);
                    }
                }
                Ok(RenderMessage::Finish(last)) => finish = Some(last),
                Err(e) => eprintln!("rigidsim: renderer: {e}"),
            }
            while queue.len() > RENDER_QUEUE {
                queue.pop_front();
                report.dropped += 1;
            }
        }
        if let Some(f) = queue.pop_front() {
            if let Some(r) = renderer.as_mut() {
                let clock = Instant::now();
                if let Err(e) = r.render_frame(&f) {
                    report.notes.push(format!("frame {}: {e}", f.index));
                }
                report.busy_s += clock.elapsed().as_secs_f64();
            }
            if finish.is_some() {
                alive();
            }
            continue;
        }
        if let Some(last) = finish.take() {
            if let Some(r) = renderer.as_mut() {
                if let Err(e) = r.finish(&last, &mut alive) {
                    report.notes.push(format!("preview: {e}"));
                }
                report.rendered = r.rendered;
                report.notes.extend(r.notes.iter().cloned());
            }
            root.send_with_tag(&encode(&report)[..], protocol::TAG_RENDER_REPORT);
            return;
        }
    }
}
