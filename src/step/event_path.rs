//! How far a group's event loop could be shared (`EventPaths`): the
//! critical path of its events and time-of-impact searches through the
//! bodies each one reads and moves, against the loop's work. It measures
//! the loop as it ran on one rank; nothing here changes a result.
//!
//! The loop takes its events in time order, one at a time. An event could
//! instead run as soon as every task it depends on has ended:
//! - a search of a pair reads its two bodies' paths: it waits for the last
//!   event that moved either;
//! - an event moves the bodies it rolls back or wakes and reads the bodies
//!   whose pairs it tests again: it waits for the last event that moved any
//!   of them, and, for those it moves, for every search and event that read
//!   them (an event at τ is the earliest for its bodies only once their
//!   pairs' searches have passed τ).
//!
//! On as many ranks as the events could use, with messages free, no
//! schedule ends the loop before that path does: the bound is optimistic.
//! The loop is timed only where the run asks (`StepSettings::time_events`):
//! a clock reading a search costs about 1 % on a machine whose clock is slow
//! to read.

use serde::{Deserialize, Serialize};
use std::time::Instant;

/// The loop's tasks so far, on their dependency path.
#[derive(Clone, Debug, Default)]
pub(crate) struct EventPaths {
    /// Whether the loop is timed at all.
    timed: bool,
    /// When the last event that moved each body would end.
    moved: Vec<f64>,
    /// When the last task that read or moved each body would end.
    read: Vec<f64>,
    /// The tasks' seconds, summed.
    work_s: f64,
    /// The latest end of any task: the loop's critical path.
    path_s: f64,
}

impl EventPaths {
    /// A loop over `bodies` bodies, nothing done yet, timed or not.
    pub(crate) fn new(bodies: usize, timed: bool) -> Self {
        let n = if timed { bodies } else { 0 };
        EventPaths {
            timed,
            moved: vec![0.0; n],
            read: vec![0.0; n],
            ..Default::default()
        }
    }

    /// A task's start, where the loop is timed.
    pub(crate) fn start(&self) -> Option<Instant> {
        self.timed.then(Instant::now)
    }

    /// A time-of-impact search of the pair of bodies `a` and `b`, started
    /// at `started` (`start`; nothing where the loop is not timed).
    pub(crate) fn search(&mut self, pair: (usize, usize), started: Option<Instant>) {
        if let Some(t) = started {
            self.search_took(pair, t.elapsed().as_secs_f64());
        }
    }

    /// An event started at `started` (`start`), moving and reading the
    /// bodies `bodies` gives (nothing where the loop is not timed, and
    /// `bodies` is not called).
    pub(crate) fn event(
        &mut self,
        started: Option<Instant>,
        bodies: impl FnOnce() -> (Vec<usize>, Vec<usize>),
    ) {
        if let Some(t) = started {
            let (moved, read) = bodies();
            self.event_took(&moved, &read, t.elapsed().as_secs_f64());
        }
    }

    /// A time-of-impact search of the pair of bodies `a` and `b` that took
    /// `s` seconds.
    fn search_took(&mut self, (a, b): (usize, usize), s: f64) {
        let end = self.moved[a].max(self.moved[b]) + s;
        for i in [a, b] {
            self.read[i] = self.read[i].max(end);
        }
        self.finish(s, end);
    }

    /// An event that took `s` seconds, moving the bodies in `moved` and
    /// reading those in `read` (a body in both counts as moved).
    fn event_took(&mut self, moved: &[usize], read: &[usize], s: f64) {
        let after_moves = read
            .iter()
            .chain(moved)
            .map(|&i| self.moved[i])
            .fold(0.0, f64::max);
        let after_reads = moved.iter().map(|&i| self.read[i]).fold(0.0, f64::max);
        let end = after_moves.max(after_reads) + s;
        for &i in read {
            self.read[i] = self.read[i].max(end);
        }
        for &i in moved {
            self.moved[i] = end;
            self.read[i] = end;
        }
        self.finish(s, end);
    }

    fn finish(&mut self, s: f64, end: f64) {
        self.work_s += s;
        self.path_s = self.path_s.max(end);
    }

    /// The loop's seconds and critical path, where it was timed.
    pub(crate) fn seconds(&self) -> Option<LoopSeconds> {
        self.timed.then_some(LoopSeconds {
            work_s: self.work_s,
            path_s: self.path_s,
        })
    }
}

/// A timed event loop's seconds (`EventPaths::seconds`), or the sum of
/// several.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct LoopSeconds {
    /// Its searches' and events' seconds, summed.
    pub work_s: f64,
    /// Their critical path (at most `work_s`).
    pub path_s: f64,
}

impl LoopSeconds {
    /// `self` and `other` summed.
    pub fn plus(self, other: LoopSeconds) -> LoopSeconds {
        LoopSeconds {
            work_s: self.work_s + other.work_s,
            path_s: self.path_s + other.path_s,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_of_separate_bodies_run_side_by_side() {
        let mut p = EventPaths::new(4, true);
        p.event_took(&[0, 1], &[], 2.0);
        p.event_took(&[2, 3], &[], 3.0);
        assert_eq!(p.work_s, 5.0);
        assert_eq!(p.path_s, 3.0);
    }

    #[test]
    fn events_sharing_a_body_run_in_turn() {
        let mut p = EventPaths::new(3, true);
        p.event_took(&[0, 1], &[], 2.0);
        p.event_took(&[1, 2], &[], 3.0);
        assert_eq!(p.path_s, 5.0);
    }

    #[test]
    fn a_search_waits_for_the_move_and_the_next_move_for_the_search() {
        let mut p = EventPaths::new(4, true);
        p.event_took(&[0], &[], 1.0);
        // Reads body 0 after its move; body 3 is free.
        p.search_took((0, 3), 0.5);
        assert_eq!(p.path_s, 1.5);
        // Moving 3 waits for the search that read it.
        p.event_took(&[3], &[], 1.0);
        assert_eq!(p.path_s, 2.5);
        // A search of untouched bodies starts at once.
        p.search_took((1, 2), 0.25);
        assert_eq!(p.path_s, 2.5);
        assert_eq!(p.work_s, 2.75);
    }

    #[test]
    fn reads_share_a_body_but_a_move_waits_for_them() {
        let mut p = EventPaths::new(3, true);
        p.event_took(&[0], &[2], 1.0);
        p.event_took(&[1], &[2], 1.0);
        assert_eq!(p.path_s, 1.0, "two readers of body 2 run side by side");
        p.event_took(&[2], &[], 1.0);
        assert_eq!(p.path_s, 2.0);
        assert_eq!(p.work_s, 3.0);
    }

    #[test]
    fn an_untimed_loop_records_nothing() {
        let mut p = EventPaths::new(3, false);
        assert!(!p.timed && p.start().is_none());
        p.search((0, 1), p.start());
        p.event(None, || unreachable!("read sets are not built"));
        assert_eq!((p.work_s, p.path_s), (0.0, 0.0));
        assert_eq!(p.seconds(), None);
    }
}
