//! Pacing a live run to the wall clock: simulated time advances at one
//! second per second of wall time, paused time does not count, and a step
//! that takes longer than its wall time makes the live run run behind (it
//! never skips physics to catch up).
//!
//! Before each step the live run waits until the wall clock reaches the
//! step's start: `origin_wall + (t − origin_sim)`. When it is late by more
//! than `MAX_CATCH_UP`, the origin moves so that it is late by that much
//! only: steps then run back to back until they are on time again, but a
//! long stall is not followed by seconds of fast motion.

use std::time::{Duration, Instant};

/// How far behind the wall clock a live run may fall and still catch up by
/// stepping back to back, seconds: a frame or so of slack for a slow step.
pub const MAX_CATCH_UP: f64 = 0.05;

/// Waits shorter than this are not slept (a sleep overshoots by tens of
/// microseconds; the next step's wait absorbs the difference).
const SHORTEST_SLEEP: Duration = Duration::from_micros(200);

/// The window over which the real-time factor and the worst frame are
/// reported, seconds of wall time.
const REPORT_WINDOW: f64 = 2.0;

pub struct Pacer {
    origin_wall: Instant,
    origin_sim: f64,
    /// Seconds the live run has dropped behind the wall clock in all.
    pub behind_total_s: f64,
    /// How late the last step started, seconds.
    late_s: f64,
    frame_interval: f64,
    /// When the current frame interval's steps began, the simulated time it
    /// began at and the seconds it slept waiting for the clock; the longest
    /// busy time of a frame interval in this window and the one before.
    frame_started: Instant,
    frame_sim: f64,
    frame_slept: f64,
    worst_now: f64,
    worst_before: f64,
    window_started: Instant,
    window_sim: f64,
    factor: f64,
}

impl Pacer {
    pub fn new(sim_time: f64, frame_interval: f64) -> Pacer {
        let now = Instant::now();
        Pacer {
            origin_wall: now,
            origin_sim: sim_time,
            behind_total_s: 0.0,
            late_s: 0.0,
            frame_interval,
            frame_started: now,
            frame_sim: sim_time,
            frame_slept: 0.0,
            worst_now: 0.0,
            worst_before: 0.0,
            window_started: now,
            window_sim: sim_time,
            factor: 1.0,
        }
    }

    /// Waits until the step that starts at `sim_time` is due.
    pub fn wait_for(&mut self, sim_time: f64) {
        let due = self.origin_sim_to_wall(sim_time);
        let now = Instant::now();
        if due > now {
            let wait = due - now;
            if wait > SHORTEST_SLEEP {
                let asleep = Instant::now();
                std::thread::sleep(wait);
                self.frame_slept += asleep.elapsed().as_secs_f64();
            }
            self.late_s = 0.0;
        } else {
            let late = (now - due).as_secs_f64();
            if late > MAX_CATCH_UP {
                let dropped = late - MAX_CATCH_UP;
                self.origin_wall += Duration::from_secs_f64(dropped);
                self.behind_total_s += dropped;
            }
            self.late_s = late.min(MAX_CATCH_UP);
        }
    }

    fn origin_sim_to_wall(&self, sim_time: f64) -> Instant {
        self.origin_wall + Duration::from_secs_f64((sim_time - self.origin_sim).max(0.0))
    }

    /// After a step that ended at `sim_time`: frame and window accounts.
    pub fn stepped(&mut self, sim_time: f64) {
        if sim_time - self.frame_sim >= self.frame_interval - 1e-12 {
            // What the frame's steps cost: its wall time less its waits
            // for the clock. On time, at most the frame interval.
            let busy = self.frame_started.elapsed().as_secs_f64() - self.frame_slept;
            self.worst_now = self.worst_now.max(busy);
            self.frame_slept = 0.0;
            self.frame_started = Instant::now();
            self.frame_sim = sim_time;
        }
        let wall = self.window_started.elapsed().as_secs_f64();
        if wall >= REPORT_WINDOW {
            self.factor = (sim_time - self.window_sim) / wall;
            self.worst_before = self.worst_now;
            self.worst_now = 0.0;
            self.window_started = Instant::now();
            self.window_sim = sim_time;
        }
    }

    /// Pause: simulated time stops; on resume the clock restarts from the
    /// simulated time reached, so paused wall time does not count.
    pub fn resume(&mut self, sim_time: f64) {
        let now = Instant::now();
        self.origin_wall = now;
        self.origin_sim = sim_time;
        self.late_s = 0.0;
        self.frame_started = now;
        self.frame_sim = sim_time;
        self.frame_slept = 0.0;
        self.window_started = now;
        self.window_sim = sim_time;
    }

    /// Simulated over wall seconds over the last report window.
    pub fn realtime_factor(&self) -> f64 {
        self.factor
    }

    /// The longest wall time of a frame interval over the last window.
    pub fn worst_frame_s(&self) -> f64 {
        self.worst_before.max(self.worst_now)
    }

    /// How far simulated time trails the wall clock now, seconds.
    pub fn behind_s(&self) -> f64 {
        self.late_s
    }
}
