//! The first stage of a group's step (each pair's end-of-step result and
//! time of impact), computed beforehand for a range of its pairs on any
//! rank (`prepare_pairs`), and the part of a group's input such a range
//! reads (`GroupInput::first_stage_input`), which is all a rank sharing
//! the stage is sent.

use super::executor::{Executor, GroupInput, PairKey, PreparedPairs, StepStatic};
use super::region::{PairMap, RegionState};
use super::timers::Stage;
use super::toi::{PairAsk, SolvedSince};
use nalgebra::Vector3;

/// The first stage of group `input`'s step for its pairs `from..to`
/// (`PreparedPairs`), on any rank; `exec` runs its narrowphase batch.
pub fn prepare_pairs(
    st: &StepStatic,
    input: &GroupInput,
    (from, to): (usize, usize),
    exec: &mut dyn Executor,
) -> PreparedPairs {
    let clock = std::time::Instant::now();
    let pairs = &input.pairs[from..to];
    let mut state = RegionState {
        bodies: input.bodies.clone(),
        features: input
            .features
            .iter()
            .filter(|(k, _)| pairs.binary_search(k).is_ok())
            .cloned()
            .collect(),
        sleep_timer: input.sleep_timer.clone(),
        sleep_group: input.sleep_group.clone(),
        ..Default::default()
    };
    let mut g = state.region(st, input.ids.clone());
    let separating: PairMap<Vector3<f64>> = input.separating.iter().cloned().collect();
    let since: SolvedSince = input.since.iter().cloned().collect();
    let results = g.narrowphase_skipping_separating(exec, pairs, &input.end, &separating);
    let timer = g.stage.start(Stage::TimeOfImpact);
    let (h, seg, since) = (st.settings.dt, &input.seg, &since);
    let toi = pairs
        .iter()
        .zip(&results)
        .map(|(&k, r)| g.time_of_impact(PairAsk { k, r, seg, since }, h))
        .collect();
    g.stage.stop(timer);
    PreparedPairs {
        results,
        toi,
        counters: state.counters,
        stage: state.stage,
        busy_s: clock.elapsed().as_secs_f64(),
    }
}

impl GroupInput {
    /// What the first stage of pairs `from..to` reads: the bodies those
    /// pairs name (renumbered in the same order), with their states,
    /// segments and sleep, and the pairs' own features, contact times and
    /// separating axes. A pair's answers read only its two bodies and its
    /// own entries, so `prepare_pairs(st, &trimmed, (0, to - from), …)`
    /// answers as `prepare_pairs(st, self, (from, to), …)`, to the bit,
    /// while a range of a pile's pairs carries a share of its bodies.
    pub fn first_stage_input(&self, (from, to): (usize, usize)) -> GroupInput {
        let wanted = &self.pairs[from..to];
        let mut kept: Vec<u32> = wanted.iter().flat_map(|&(a, b)| [a, b]).collect();
        kept.sort_unstable();
        kept.dedup();
        let renumber = |(a, b): PairKey| {
            let local = |i: u32| kept.binary_search(&i).expect("a kept pair's body") as u32;
            (local(a), local(b))
        };
        let each = |i: &u32| *i as usize;
        GroupInput {
            ids: kept.iter().map(|i| self.ids[each(i)]).collect(),
            bodies: kept.iter().map(|i| self.bodies[each(i)].clone()).collect(),
            features: entries_of(&self.features, wanted, renumber),
            warm: Vec::new(),
            sleep_timer: kept.iter().map(|i| self.sleep_timer[each(i)]).collect(),
            sleep_group: kept.iter().map(|i| self.sleep_group[each(i)]).collect(),
            seg: kept.iter().map(|i| self.seg[each(i)]).collect(),
            end: kept.iter().map(|i| self.end[each(i)]).collect(),
            pairs: wanted.iter().map(|&k| renumber(k)).collect(),
            since: entries_of(&self.since, wanted, renumber),
            separating: entries_of(&self.separating, wanted, renumber),
            together: Vec::new(),
            spin_resolves: Vec::new(),
            predicted_s: self.predicted_s,
            prepared: None,
            keep_paths: false,
        }
    }
}

/// The entries of `list` for the pairs `wanted` (sorted), renumbered.
fn entries_of<T: Clone>(
    list: &[(PairKey, T)],
    wanted: &[PairKey],
    renumber: impl Fn(PairKey) -> PairKey,
) -> Vec<(PairKey, T)> {
    list.iter()
        .filter(|(k, _)| wanted.binary_search(k).is_ok())
        .map(|(k, v)| (renumber(*k), v.clone()))
        .collect()
}
