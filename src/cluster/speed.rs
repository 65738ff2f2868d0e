//! How fast the ranks are: the `--slow-rank` test aid (a rank that spins
//! to look slower) and the fit of each rank's speed from its batches.

use super::schedule;
use std::time::{Duration, Instant};

/// Test aid: `--slow-rank R=F` makes rank R take F times longer per batch
/// (it spins for (F − 1)× its work's CPU time), like a PC another user is loading.
pub fn slow_factor(slow: &[(i32, f64)], rank: i32) -> f64 {
    slow.iter()
        .filter(|(r, _)| *r == rank)
        .map(|(_, f)| *f)
        .fold(1.0, f64::max)
}

/// CPU time this thread has used. A slowed rank's extra work is counted in
/// it, not on the wall clock: on a loaded machine a batch's wall time
/// includes time the rank sat preempted, and stalling (factor − 1)× that
/// multiplied every preemption spike (a rank set 3× slower measured 21×
/// slower while another job used the second core).
pub(super) fn thread_cpu_time() -> Duration {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec; CLOCK_THREAD_CPUTIME_ID
    // is supported on every Linux the cluster runs on.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    if rc != 0 {
        return Duration::ZERO;
    }
    Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}

/// Keeps the CPU busy for (factor − 1)× the CPU time the batch's work took
/// (`cpu_at_start` was read when it began), as a slower PC would, and
/// returns the batch's wall time `since` it began. A sleep would not do: its
/// granularity (tens of µs) dwarfs the microsecond batches of small scenes
/// and would fake a much slower rank.
pub(super) fn stall(factor: f64, since: Instant, cpu_at_start: Duration) -> Duration {
    if factor > 1.0 {
        let now = thread_cpu_time();
        let until = now + now.saturating_sub(cpu_at_start).mul_f64(factor - 1.0);
        while thread_cpu_time() < until {
            std::hint::spin_loop();
        }
    }
    since.elapsed()
}

/// Smoothed moments of (cost given, busy time reported) per batch, for a
/// least-squares fit busy = overhead + cost / speed. The fixed per-batch
/// overhead would otherwise make a rank given only small tasks look slow, get
/// even smaller tasks, and starve.
#[derive(Default, Clone)]
pub(super) struct SpeedMeter {
    c: f64,
    b: f64,
    cc: f64,
    cb: f64,
}

impl SpeedMeter {
    pub(super) fn add(&mut self, cost: f64, busy: f64) {
        let s = schedule::smooth_slow;
        self.c = s(self.c, cost);
        self.b = s(self.b, busy);
        self.cc = s(self.cc, cost * cost);
        self.cb = s(self.cb, cost * busy);
    }

    /// 1 / slope of the fit, kept within 4× of plain cost / busy (which
    /// overhead biases low, but noise cannot swing): a fit over microsecond
    /// batches on shared cores can otherwise run away.
    pub(super) fn speed(&self) -> f64 {
        let ratio = self.c / self.b;
        let var = self.cc - self.c * self.c;
        let cov = self.cb - self.c * self.b;
        if var > 0.01 * self.cc && cov > 0.0 {
            (var / cov).clamp(ratio, 4.0 * ratio)
        } else {
            ratio
        }
    }
}
