//! The step's settings: how a run asks the step to work (test aids and
//! measurements), held once by the world and sent with every group, the
//! same on every rank.

use serde::{Deserialize, Serialize};

/// Share of its radius by which each predicted swept sphere grows when the
/// groups are formed (`group::plan_groups`; not for the pairs tested):
/// without it a pile's group often re-runs, with more the groups grow and
/// each event costs more. Results do not depend on it.
pub const GROUP_MARGIN: f64 = 0.25;

/// How a run asks the step to work (`World::settings`): the resting
/// systems, the optimisations a test compares with and without, and what
/// the step keeps for the caller. Sent to the workers in `GroupParams`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepSettings {
    /// Enables resting systems (on by default; analytic tests may switch it off).
    pub sleep_enabled: bool,
    /// Seconds a body stays slow before it rests.
    pub sleep_after: f64,
    /// Enables the separating-pair skip (on by default; a test compares).
    pub skip_separating: bool,
    /// Starts iterative solves from the last forces (on by default; a test
    /// compares).
    pub warm_start: bool,
    /// Islands of this many rows or more are solved by sequential impulses
    /// (`solver::ITERATIVE_MIN_ROWS`; a test lowers it to make a small
    /// stack iterative).
    pub iterative_min_rows: usize,
    /// Share of its radius by which each predicted sphere grows when the
    /// groups are formed (`GROUP_MARGIN` by default; results do not
    /// depend on it, a test compares).
    pub group_margin: f64,
    /// Splits large groups into the parts that interact within the step
    /// (`group::split_group`; off by default, `--split-groups`): the same
    /// answers where the parts meet nothing else, more work on one rank,
    /// smaller units to share over many.
    pub split_groups: bool,
    /// Keeps a copy of every contact island of this many rows or more
    /// that the step builds, in the order it builds them
    /// (`Diagnostics::captured_islands`, `GroupReply`), for the caller to write
    /// (`--capture-islands`); `None` (the default): none is kept. Changes
    /// no result.
    pub capture_min_rows: Option<usize>,
    /// Times each group's event loop, its events and searches, for
    /// `distributed.event_shared_bound` (`step::event_path`; with
    /// `--predict`). Changes no result; costs a clock reading a search.
    pub time_events: bool,
}

impl Default for StepSettings {
    fn default() -> Self {
        StepSettings {
            sleep_enabled: true,
            sleep_after: 0.5,
            skip_separating: true,
            warm_start: true,
            iterative_min_rows: crate::contact::solver::ITERATIVE_MIN_ROWS,
            group_margin: GROUP_MARGIN,
            split_groups: false,
            capture_min_rows: None,
            time_events: false,
        }
    }
}
