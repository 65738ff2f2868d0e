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

/// The loop's tasks so far, on their dependency path.
#[derive(Clone, Debug, Default)]
pub(crate) struct EventPaths {
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
    /// A loop over `bodies` bodies, nothing done yet.
    pub(crate) fn new(bodies: usize) -> Self {
        EventPaths {
            moved: vec![0.0; bodies],
            read: vec![0.0; bodies],
            ..Default::default()
        }
    }

    /// A time-of-impact search of the pair of bodies `a` and `b` that took
    /// `s` seconds.
    pub(crate) fn search(&mut self, (a, b): (usize, usize), s: f64) {
        let end = self.moved[a].max(self.moved[b]) + s;
        for i in [a, b] {
            self.read[i] = self.read[i].max(end);
        }
        self.finish(s, end);
    }

    /// An event that took `s` seconds, moving the bodies in `moved` and
    /// reading those in `read` (a body in both counts as moved).
    pub(crate) fn event(&mut self, moved: &[usize], read: &[usize], s: f64) {
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

    /// The loop's tasks' seconds, summed.
    pub(crate) fn work_s(&self) -> f64 {
        self.work_s
    }

    /// The loop's critical path in seconds (at most `work_s`).
    pub(crate) fn path_s(&self) -> f64 {
        self.path_s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn events_of_separate_bodies_run_side_by_side() {
        let mut p = EventPaths::new(4);
        p.event(&[0, 1], &[], 2.0);
        p.event(&[2, 3], &[], 3.0);
        assert_eq!(p.work_s(), 5.0);
        assert_eq!(p.path_s(), 3.0);
    }

    #[test]
    fn events_sharing_a_body_run_in_turn() {
        let mut p = EventPaths::new(3);
        p.event(&[0, 1], &[], 2.0);
        p.event(&[1, 2], &[], 3.0);
        assert_eq!(p.path_s(), 5.0);
    }

    #[test]
    fn a_search_waits_for_the_move_and_the_next_move_for_the_search() {
        let mut p = EventPaths::new(4);
        p.event(&[0], &[], 1.0);
        // Reads body 0 after its move; body 3 is free.
        p.search((0, 3), 0.5);
        assert_eq!(p.path_s(), 1.5);
        // Moving 3 waits for the search that read it.
        p.event(&[3], &[], 1.0);
        assert_eq!(p.path_s(), 2.5);
        // A search of untouched bodies starts at once.
        p.search((1, 2), 0.25);
        assert_eq!(p.path_s(), 2.5);
        assert_eq!(p.work_s(), 2.75);
    }

    #[test]
    fn reads_share_a_body_but_a_move_waits_for_them() {
        let mut p = EventPaths::new(3);
        p.event(&[0], &[2], 1.0);
        p.event(&[1], &[2], 1.0);
        assert_eq!(p.path_s(), 1.0, "two readers of body 2 run side by side");
        p.event(&[2], &[], 1.0);
        assert_eq!(p.path_s(), 2.0);
        assert_eq!(p.work_s(), 3.0);
    }
}
