//! Interaction groups: the impact events of a step, group by group.
//!
//! After the step's contact solve, integration and broadphase, the moving
//! bodies fall into groups: the connected components of the graph whose
//! nodes are the dynamic bodies (moving ones, and the sleeping ones a
//! candidate pair reaches, each with its whole resting system) and whose
//! edges are the candidate pairs and the contacts touching now. Fixed and
//! driven bodies take no impulse, so they are no nodes and connect nothing:
//! a group carries the ones its pairs reach, read-only.
//!
//! A group's step (`step_group`) is a function of static data and the
//! group's own input only: the end-of-step results of its pairs, then every
//! impact event in time order with roll-back, re-solve and re-integration,
//! spin re-solves and earlier impacts. Nothing in it reads the rest of the
//! world, so its cost is its own bodies' cost and its result does not depend
//! on what else the world holds, or on where it ran.
//!
//! An impact can send a body outside the spheres it was grouped by. After
//! every group has run, the paths the bodies took since their first
//! roll-back (`GroupOutput::pieces`) are tested against every body's predicted
//! spheres and against each other (`find_leaks`); where a path meets another
//! group, the two merge, and where it meets a body outside its input, that
//! body joins; either way the group is stepped again from the step's start.
//! Repeated until nothing new meets, so every meeting is handled as if the
//! group had been one from the start, whatever the number of ranks.

use super::contact::{SolvedTogether, SpinResolves, Touching, WarmContact};
use super::impacts::step_group;
use super::region::{PairKey, PairMap, Region, Segment, StepStatic};
use super::stats::{Counters, NumericalFailure, StageSeconds};
use super::toi::{Since, SolvedSince};
use super::{Executor, Inline};
use crate::body::Body;
use crate::body::{Activity, BodyId, BodyState};
use crate::collision::broadphase::{self, SphereProxy};
use crate::collision::narrowphase::CachedFeatures;
use crate::collision::narrowphase::PairResult;
use crate::contact::island::DisjointSets;
use crate::scene::Scene;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};

/// Share of its radius by which each predicted swept sphere grows when the
/// groups are formed (`plan_groups`; not for the pairs tested). Measured on
/// the first 0.6 s of the 1000-body pour: without it 51 groups re-ran
/// (the pile's group each time) and the step took 16.4 s; with 1 cm on
/// the 4 cm parts (a quarter of a sphere's radius) one did, in 11.4 s; at
/// 3 cm none, in 11.6 s (larger groups cost more per event). Results do
/// not depend on it (same state hash).
pub const GROUP_MARGIN: f64 = 0.25;

/// What the whole world holds when the impact stage starts (world indices),
/// from which every group's input is cut.
pub(crate) struct StepStart {
    pub seg: Vec<Segment>,
    pub end: Vec<BodyState>,
    /// The broadphase's candidate pairs (sorted).
    pub pairs: Vec<PairKey>,
    /// The predicted paths' swept spheres, tagged with world ids, grown by
    /// `GROUP_MARGIN` (what the groups are formed by).
    pub grown: Vec<SphereProxy>,
    pub since: SolvedSince,
    pub separating: PairMap<Vector3<f64>>,
    /// Bodies solved together at the step's start (islands of two or more).
    pub together: Vec<Vec<usize>>,
    pub spin_resolves: SpinResolves,
    /// Contacts touching at the step's start.
    pub touching: Vec<PairKey>,
    /// Seconds each body's group step took last step, shared out over its
    /// members (the schedule's prediction; never part of a result).
    pub body_cost: Vec<f64>,
}

/// The bodies of one group, as world ids.
#[derive(Clone, Debug, Default)]
pub(crate) struct GroupPlan {
    /// Dynamic bodies (sorted): the moving ones and the resting systems reached.
    pub members: Vec<u32>,
    /// Fixed and driven bodies it reads (sorted).
    pub neighbours: Vec<u32>,
    /// Indices into `StepStart::pairs` of its pairs (sorted).
    pub pairs: Vec<usize>,
}

impl GroupPlan {
    /// The group's id: its lowest member.
    pub fn id(&self) -> u32 {
        self.members[0]
    }
}

/// Partitions the world's candidate pairs into groups, ordered by id.
pub(crate) fn plan_groups(world: &Region, start: &StepStart) -> Vec<GroupPlan> {
    let n = world.bodies.len();
    let dynamic = |i: u32| {
        let b = &world.bodies[i as usize];
        b.is_dynamic() && b.activity != Activity::Fallen
    };
    let mut sets = DisjointSets::new(n);
    for &(a, b) in start.pairs.iter().chain(&start.touching) {
        if dynamic(a) && dynamic(b) {
            sets.union(a, b);
        }
    }
    // Bodies whose predicted spheres, grown by `GROUP_MARGIN`, meet are
    // grouped too, and a fixed or driven body that close is read, also by
    // a resting body (it may wake in the step and move along it): an
    // impact that sends a body a little off its prediction then stays
    // inside its group instead of re-running it and the group it meets.
    // `step_group` relies on this: a realised path inside the grown
    // prediction cannot meet anything outside the group.
    let mut near_fixed: Vec<(u32, u32)> = Vec::new();
    for (a, b) in broadphase::candidate_pairs(&start.grown, |a, b| dynamic(a) || dynamic(b)) {
        match (dynamic(a), dynamic(b)) {
            (true, true) => sets.union(a, b),
            (true, false) => near_fixed.push((a, b)),
            (false, true) => near_fixed.push((b, a)),
            (false, false) => {}
        }
    }
    // A resting system is reached whole (its roots are its lowest member).
    for i in 0..n {
        if world.bodies[i].activity == Activity::Sleeping {
            sets.union(i as u32, world.sleep_group[i]);
        }
    }
    let mut by_root: BTreeMap<u32, GroupPlan> = BTreeMap::new();
    for (k, &(a, b)) in start.pairs.iter().enumerate() {
        let root = if dynamic(a) {
            sets.find(a)
        } else {
            sets.find(b)
        };
        let plan = by_root.entry(root).or_default();
        plan.pairs.push(k);
        for x in [a, b] {
            if !dynamic(x) {
                plan.neighbours.push(x);
            }
        }
    }
    for i in 0..n as u32 {
        if dynamic(i) {
            if let Some(plan) = by_root.get_mut(&sets.find(i)) {
                plan.members.push(i);
            }
        }
    }
    for (d, x) in near_fixed {
        if let Some(plan) = by_root.get_mut(&sets.find(d)) {
            plan.neighbours.push(x);
        }
    }
    let mut plans: Vec<GroupPlan> = by_root.into_values().collect();
    for p in &mut plans {
        p.neighbours.sort_unstable();
        p.neighbours.dedup();
    }
    plans.sort_by_key(GroupPlan::id);
    plans
}

/// Each body's entries of a map keyed by world pair (a, b), a < b, listed
/// under both bodies, so a group finds its own entries at the cost of its
/// own bodies.
pub(crate) struct PairIndex(Vec<Vec<PairKey>>);

impl PairIndex {
    pub fn new<'k>(n: usize, keys: impl Iterator<Item = &'k PairKey>) -> Self {
        let mut by_body = vec![Vec::new(); n];
        for &(a, b) in keys {
            by_body[a as usize].push((a, b));
        }
        PairIndex(by_body)
    }

    /// The keys among the (sorted) bodies `ids`, as world keys.
    fn among(&self, ids: &[u32]) -> Vec<PairKey> {
        ids.iter()
            .flat_map(|&a| self.0[a as usize].iter().copied())
            .filter(|&(_, b)| ids.binary_search(&b).is_ok())
            .collect()
    }
}

/// The per-step indices `group_input` looks entries up with.
pub(crate) struct StartIndex {
    pub features: PairIndex,
    pub since: PairIndex,
    pub separating: PairIndex,
    pub warm: PairIndex,
}

/// The group's input, cut from the world at the start of the impact stage.
pub(crate) fn group_input(
    world: &Region,
    start: &StepStart,
    index: &StartIndex,
    plan: &GroupPlan,
) -> GroupInput {
    let mut ids: Vec<u32> = plan
        .members
        .iter()
        .chain(&plan.neighbours)
        .copied()
        .collect();
    ids.sort_unstable();
    ids.dedup();
    let local = |w: u32| {
        ids.binary_search(&w)
            .expect("a group's pair has both bodies in it") as u32
    };
    let key = |(a, b): PairKey| (local(a), local(b));
    let body_key = |(a, b): (BodyId, BodyId)| (BodyId(local(a.0)), BodyId(local(b.0)));
    let features = index
        .features
        .among(&ids)
        .into_iter()
        .map(|k| (key(k), world.features[&k].clone()))
        .collect();
    let warm = index
        .warm
        .among(&ids)
        .into_iter()
        .map(|(a, b)| {
            let k = (BodyId(a), BodyId(b));
            (body_key(k), world.warm[&k].clone())
        })
        .collect();
    let since = index
        .since
        .among(&ids)
        .into_iter()
        .map(|k| (key(k), start.since[&k]))
        .collect();
    let separating = index
        .separating
        .among(&ids)
        .into_iter()
        .map(|k| (key(k), start.separating[&k]))
        .collect();
    let together = start
        .together
        .iter()
        .filter(|bodies| ids.binary_search(&(bodies[0] as u32)).is_ok())
        .map(|bodies| bodies.iter().map(|&i| local(i as u32) as usize).collect())
        .collect();
    let spin_resolves = start
        .spin_resolves
        .0
        .iter()
        .filter_map(|&(t, i)| ids.binary_search(&(i as u32)).ok().map(|l| (t, l)))
        .collect();
    // A body never grouped before counts as a pair test's worth (10 µs).
    let predicted_s = plan
        .members
        .iter()
        .map(|&i| start.body_cost[i as usize].max(1e-5))
        .sum();
    GroupInput {
        predicted_s,
        prepared: None,
        bodies: ids
            .iter()
            .map(|&w| world.bodies[w as usize].clone())
            .collect(),
        sleep_timer: ids.iter().map(|&w| world.sleep_timer[w as usize]).collect(),
        sleep_group: ids.iter().map(|&w| world.sleep_group[w as usize]).collect(),
        features,
        warm,
        seg: ids.iter().map(|&w| start.seg[w as usize]).collect(),
        end: ids.iter().map(|&w| start.end[w as usize]).collect(),
        pairs: plan.pairs.iter().map(|&k| key(start.pairs[k])).collect(),
        since,
        separating,
        together,
        spin_resolves,
        ids,
    }
}

/// What a group's impact loop carries from one event to the next.
pub(crate) struct GroupState {
    pub seg: Vec<Segment>,
    pub end: Vec<BodyState>,
    /// The group's candidate pairs (their end-of-step narrowphase is the
    /// group step's first stage).
    pub pairs: Vec<PairKey>,
    pub since: SolvedSince,
    pub separating: PairMap<Vector3<f64>>,
    pub together: SolvedTogether,
    pub spin_resolves: SpinResolves,
    /// The first stage's answers, when computed beforehand in shares
    /// (`prepare_pairs`); `None`: the step computes them.
    pub prepared: Option<PreparedPairs>,
}

/// The first stage of a group's step for some of its pairs: their
/// end-of-step results and times of impact. Each pair's answer depends
/// only on the group's input, so a large group's pairs can be shared out
/// over ranks (`prepare_pairs`) before one rank takes its events; the step
/// then starts from these answers instead of computing them, and ends
/// exactly as it would have.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct PreparedPairs {
    pub(crate) results: Vec<PairResult>,
    pub(crate) toi: Vec<Option<f64>>,
    pub(crate) counters: Counters,
    pub(crate) stage: StageSeconds,
    /// Wall seconds it took where it ran (part of the group's cost).
    pub(crate) busy_s: f64,
}

impl PreparedPairs {
    /// V-Clip tasks it ran.
    pub fn tasks(&self) -> u64 {
        self.counters.pair_tests
    }

    /// The shares of one group's pairs, in the order of their ranges, as
    /// one (the ranges must cover the pairs in order).
    pub fn joined(shares: Vec<PreparedPairs>) -> PreparedPairs {
        let mut all = PreparedPairs::default();
        for s in shares {
            all.results.extend(s.results);
            all.toi.extend(s.toi);
            all.counters.add(&s.counters);
            all.stage.narrowphase += s.stage.narrowphase;
            all.stage.time_of_impact += s.stage.time_of_impact;
            all.busy_s += s.busy_s;
        }
        all
    }
}

/// The first stage of group `input`'s step for its pairs `from..to`
/// (`PreparedPairs`), on any rank.
pub fn prepare_pairs(
    st: &StepStatic,
    input: &GroupInput,
    (from, to): (usize, usize),
) -> PreparedPairs {
    let clock = std::time::Instant::now();
    let pairs = &input.pairs[from..to];
    let mut g = Region {
        st,
        ids: input.ids.clone(),
        bodies: input.bodies.clone(),
        features: input
            .features
            .iter()
            .filter(|(k, _)| pairs.binary_search(k).is_ok())
            .cloned()
            .collect(),
        warm: BTreeMap::new(),
        sleep_timer: input.sleep_timer.clone(),
        sleep_group: input.sleep_group.clone(),
        counters: Counters::default(),
        stage: StageSeconds::default(),
        impacts: Vec::new(),
        pair_forces: BTreeMap::new(),
        integrated: Default::default(),
    };
    let separating: PairMap<Vector3<f64>> = input.separating.iter().cloned().collect();
    let since: SolvedSince = input.since.iter().cloned().collect();
    let results =
        g.narrowphase_skipping_separating(&mut Inline::default(), pairs, &input.end, &separating);
    let toi_clock = std::time::Instant::now();
    let h = st.settings.dt;
    let toi = pairs
        .iter()
        .zip(&results)
        .map(|(&k, r)| g.time_of_impact(k, r, &input.seg, h, &since))
        .collect();
    g.stage.time_of_impact += toi_clock.elapsed().as_secs_f64();
    PreparedPairs {
        results,
        toi,
        counters: g.counters,
        stage: g.stage,
        busy_s: clock.elapsed().as_secs_f64(),
    }
}

/// What a group's step reads besides the scene: the step's start time and
/// the world's switches. Sent with the groups a worker steps.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GroupParams {
    t0: f64,
    skip_separating: bool,
    warm_start: bool,
    iterative_min_rows: usize,
    sleep_enabled: bool,
    sleep_after: f64,
    group_margin: f64,
}

impl GroupParams {
    /// The world's switches for a step starting at `t0`.
    pub(crate) fn of_world(w: &super::World, t0: f64) -> Self {
        GroupParams {
            t0,
            skip_separating: w.skip_separating,
            warm_start: w.warm_start,
            iterative_min_rows: w.iterative_min_rows,
            sleep_enabled: w.sleep_enabled,
            sleep_after: w.sleep_after,
            group_margin: w.group_margin,
        }
    }

    pub(crate) fn of(st: &StepStatic) -> Self {
        GroupParams {
            t0: st.t0,
            skip_separating: st.skip_separating,
            warm_start: st.warm_start,
            iterative_min_rows: st.iterative_min_rows,
            sleep_enabled: st.sleep_enabled,
            sleep_after: st.sleep_after,
            group_margin: st.group_margin,
        }
    }

    /// The step's static data, with a scene that every rank loaded alike.
    pub fn statics<'s>(&self, scene: &'s Scene) -> StepStatic<'s> {
        StepStatic {
            objects: &scene.objects,
            settings: &scene.settings,
            forces: &scene.forces,
            t0: self.t0,
            skip_separating: self.skip_separating,
            warm_start: self.warm_start,
            iterative_min_rows: self.iterative_min_rows,
            sleep_enabled: self.sleep_enabled,
            sleep_after: self.sleep_after,
            group_margin: self.group_margin,
        }
    }
}

/// One group's input, ids and state only (`group_input`): what rank 0 sends
/// a worker to step.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GroupInput {
    ids: Vec<u32>,
    bodies: Vec<Body>,
    features: Vec<(PairKey, Vec<CachedFeatures>)>,
    warm: Vec<((BodyId, BodyId), Vec<WarmContact>)>,
    sleep_timer: Vec<f64>,
    sleep_group: Vec<u32>,
    seg: Vec<Segment>,
    end: Vec<BodyState>,
    pairs: Vec<PairKey>,
    since: Vec<(PairKey, Since)>,
    separating: Vec<(PairKey, Vector3<f64>)>,
    /// Islands solved together at the step's start (local indices).
    together: Vec<Vec<usize>>,
    spin_resolves: Vec<(f64, usize)>,
    /// Seconds its step is expected to take: what its bodies' groups took
    /// last step (`GroupOutput::busy_s`, shared out over their members).
    predicted_s: f64,
    /// Its first stage, when computed beforehand (`GroupState::prepared`).
    prepared: Option<PreparedPairs>,
}

impl GroupInput {
    /// Seconds its step is expected to take, for the schedule.
    pub fn predicted_s(&self) -> f64 {
        self.predicted_s
    }

    /// Its candidate pairs (the first stage's tasks).
    pub fn pair_count(&self) -> usize {
        self.pairs.len()
    }

    /// Hands the step its first stage, computed beforehand for all its
    /// pairs in order (`prepare_pairs`, `PreparedPairs::joined`).
    pub fn set_prepared(&mut self, prepared: PreparedPairs) {
        assert_eq!(
            prepared.results.len(),
            self.pairs.len(),
            "one answer per pair"
        );
        self.prepared = Some(prepared);
    }
}

/// What a group's step returns (`step_group`), ids and state only.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct GroupOutput {
    pub(crate) ids: Vec<u32>,
    pub(crate) bodies: Vec<Body>,
    pub(crate) sleep_timer: Vec<f64>,
    pub(crate) end: Vec<BodyState>,
    pub(crate) pairs: Vec<PairKey>,
    pub(crate) results: Vec<PairResult>,
    pub(crate) warm: Vec<((BodyId, BodyId), Vec<WarmContact>)>,
    pub(crate) impacts: Vec<Touching>,
    pub(crate) pair_forces: Vec<((BodyId, BodyId), f64)>,
    pub(crate) counters: Counters,
    pub(crate) stage: StageSeconds,
    /// Impact events taken (spin re-solves not counted).
    pub(crate) events: u64,
    /// Swept spheres (world ids) of the paths its bodies took after their
    /// first roll-back that leave their grown prediction.
    pub(crate) pieces: Vec<SphereProxy>,
    /// Wall seconds the step took where it ran (the next step's prediction).
    pub(crate) busy_s: f64,
    /// V-Clip tasks of its first stage run beforehand (`PreparedPairs`):
    /// in `counters`, but counted where they ran.
    pub(crate) prepared_tasks: u64,
}

impl GroupOutput {
    /// V-Clip tasks and island solves the group's step ran.
    pub fn tasks(&self) -> (u64, u64) {
        (
            self.counters.pair_tests - self.prepared_tasks,
            self.counters.islands,
        )
    }
}

/// A numerical failure inside a group's step, as it travels between ranks.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GroupFailure {
    body: u32,
    stage: String,
    time: f64,
    detail: String,
}

impl From<NumericalFailure> for GroupFailure {
    fn from(f: NumericalFailure) -> Self {
        GroupFailure {
            body: f.body.0,
            stage: f.stage.to_string(),
            time: f.time,
            detail: f.detail,
        }
    }
}

impl From<GroupFailure> for NumericalFailure {
    fn from(f: GroupFailure) -> Self {
        NumericalFailure {
            body: BodyId(f.body),
            stage: if f.stage == "integrate" {
                "integrate"
            } else {
                "solve_islands"
            },
            time: f.time,
            detail: f.detail,
        }
    }
}

/// One group's answer: its output, or where it went numerically wrong.
/// (`None` only as a placeholder while answers are gathered.)
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct GroupReply(pub(crate) Option<Result<GroupOutput, GroupFailure>>);

impl GroupReply {
    /// V-Clip tasks and island solves the group's step ran.
    pub fn tasks(&self) -> (u64, u64) {
        match &self.0 {
            Some(Ok(out)) => out.tasks(),
            _ => (0, 0),
        }
    }
}

/// Steps one group from its input, anywhere: the same function on rank 0
/// and on a worker. Its narrowphase batches and island solves go through
/// `exec`.
pub fn run_group(st: &StepStatic, input: GroupInput, exec: &mut dyn Executor) -> GroupReply {
    let GroupInput {
        ids,
        bodies,
        features,
        warm,
        sleep_timer,
        sleep_group,
        seg,
        end,
        pairs,
        since,
        separating,
        together: islands,
        spin_resolves,
        predicted_s: _,
        prepared,
    } = input;
    let clock = std::time::Instant::now();
    // A first stage run beforehand is part of what the group cost.
    let prepared_s = prepared.as_ref().map_or(0.0, |p| p.busy_s);
    let mut together = SolvedTogether::new(ids.len());
    together.record_islands(islands);
    let region = Region {
        st,
        ids,
        bodies,
        features: features.into_iter().collect(),
        warm: warm.into_iter().collect(),
        sleep_timer,
        sleep_group,
        counters: Counters::default(),
        stage: StageSeconds::default(),
        impacts: Vec::new(),
        pair_forces: BTreeMap::new(),
        integrated: Default::default(),
    };
    let state = GroupState {
        seg,
        end,
        pairs,
        since: since.into_iter().collect(),
        separating: separating.into_iter().collect(),
        together,
        spin_resolves: SpinResolves(spin_resolves),
        prepared,
    };
    let output = step_group(region, state, exec).map(|mut out| {
        out.busy_s = clock.elapsed().as_secs_f64() + prepared_s;
        out
    });
    GroupReply(Some(output.map_err(GroupFailure::from)))
}

/// Where a group's realised paths met what it did not hold.
enum Leak {
    /// Another group (index into the plans).
    Group(usize),
    /// A body in no group's input (world id).
    Body(u32),
}

/// The realised paths that left their groups: for each group that ran, the
/// groups and outside bodies its pieces meet (tested against every body's
/// predicted spheres and every other group's pieces).
fn find_leaks(
    n: usize,
    start: &StepStart,
    plans: &[GroupPlan],
    runs: &[Option<GroupOutput>],
    owner: &[Option<usize>],
) -> Vec<(usize, Leak)> {
    let mut pieces = Vec::new();
    for (p, run) in runs.iter().enumerate() {
        if let Some(run) = run {
            pieces.extend(run.pieces.iter().map(|s| SphereProxy {
                body: (n + p) as u32,
                ..*s
            }));
        }
    }
    if pieces.is_empty() {
        return Vec::new();
    }
    // (a, b) with b a group's pieces, a a body or another group's pieces.
    let pairs = broadphase::crossing_pairs(&start.grown, &pieces);
    let mut leaks = Vec::new();
    for (a, b) in pairs {
        let p = b as usize - n;
        if a as usize >= n {
            leaks.push((p, Leak::Group(a as usize - n)));
            continue;
        }
        match owner[a as usize] {
            Some(q) if q == p => {}
            Some(q) => leaks.push((p, Leak::Group(q))),
            None if plans[p].neighbours.binary_search(&a).is_ok() => {}
            None => leaks.push((p, Leak::Body(a))),
        }
    }
    leaks
}

/// Runs every group of the step and re-runs merged ones until no realised
/// path leaves its group; returns the runs in group-id order.
pub(crate) fn step_groups<'s>(
    st: &'s StepStatic<'s>,
    world: &Region<'s>,
    start: &StepStart,
    exec: &mut dyn Executor,
) -> Result<(Vec<GroupOutput>, u64), NumericalFailure> {
    let n = world.bodies.len();
    let index = StartIndex {
        features: PairIndex::new(n, world.features.keys()),
        since: PairIndex::new(n, start.since.keys()),
        separating: PairIndex::new(n, start.separating.keys()),
        warm: PairIndex::new(
            n,
            world
                .warm
                .keys()
                .map(|(a, b)| (a.0, b.0))
                .collect::<Vec<_>>()
                .iter(),
        ),
    };
    let mut plans = plan_groups(world, start);
    let mut runs: Vec<Option<GroupOutput>> = (0..plans.len()).map(|_| None).collect();
    let params = GroupParams::of(st);
    let mut reruns = 0u64;
    loop {
        // Every group still to step, through the executor (inline, or
        // scattered over the workers); answers come back in group order.
        let todo: Vec<usize> = (0..plans.len()).filter(|&p| runs[p].is_none()).collect();
        let inputs = todo
            .iter()
            .map(|&p| group_input(world, start, &index, &plans[p]))
            .collect();
        for (p, reply) in todo.into_iter().zip(exec.step_groups(st, &params, inputs)) {
            let output = reply.0.expect("every group answered")?;
            runs[p] = Some(output);
        }
        let mut owner: Vec<Option<usize>> = vec![None; n];
        for (p, plan) in plans.iter().enumerate() {
            for &i in &plan.members {
                owner[i as usize] = Some(p);
            }
        }
        let leaks = find_leaks(n, start, &plans, &runs, &owner);
        if leaks.is_empty() {
            break;
        }
        // Merge: groups that met become one (the lowest index keeps the
        // plan); outside bodies join the group that met them.
        let mut sets = DisjointSets::new(plans.len());
        let mut joins: BTreeMap<usize, BTreeSet<u32>> = BTreeMap::new();
        for (p, leak) in leaks {
            match leak {
                Leak::Group(q) => sets.union(p as u32, q as u32),
                Leak::Body(b) => {
                    joins.entry(p).or_default().insert(b);
                }
            }
        }
        let mut merged: BTreeMap<u32, GroupPlan> = BTreeMap::new();
        let mut changed: BTreeSet<u32> = BTreeSet::new();
        for (p, plan) in plans.iter().enumerate() {
            let root = sets.find(p as u32);
            if root != p as u32 || joins.contains_key(&p) {
                changed.insert(root);
            }
            let m = merged.entry(root).or_default();
            m.members.extend(&plan.members);
            m.neighbours.extend(&plan.neighbours);
            m.pairs.extend(&plan.pairs);
            for &b in joins.get(&p).into_iter().flatten() {
                let body = &world.bodies[b as usize];
                if !body.is_dynamic() {
                    m.neighbours.push(b);
                } else if body.activity == Activity::Sleeping {
                    let s = world.sleep_group[b as usize];
                    m.members.extend((0..n as u32).filter(|&i| {
                        world.bodies[i as usize].activity == Activity::Sleeping
                            && world.sleep_group[i as usize] == s
                    }));
                } else {
                    m.members.push(b);
                }
            }
        }
        let mut old_runs: Vec<Option<GroupOutput>> = runs;
        plans = Vec::new();
        runs = Vec::new();
        for (root, mut m) in merged {
            m.members.sort_unstable();
            m.members.dedup();
            m.neighbours.sort_unstable();
            m.neighbours.dedup();
            m.pairs.sort_unstable();
            m.pairs.dedup();
            plans.push(m);
            if changed.contains(&root) {
                reruns += 1;
                runs.push(None);
            } else {
                runs.push(old_runs[root as usize].take());
            }
        }
        // Keep the plans in id order (a merged group takes its lowest member).
        let mut order: Vec<usize> = (0..plans.len()).collect();
        order.sort_by_key(|&p| plans[p].id());
        let mut taken: Vec<Option<(GroupPlan, Option<GroupOutput>)>> =
            plans.into_iter().zip(runs).map(Some).collect();
        plans = Vec::new();
        runs = Vec::new();
        for p in order {
            let (plan, run) = taken[p].take().expect("each plan once");
            plans.push(plan);
            runs.push(run);
        }
    }
    Ok((
        runs.into_iter()
            .map(|r| r.expect("every group ran"))
            .collect(),
        reruns,
    ))
}

/// World ids of a group's touching contacts, impacts and warm starts.
pub(crate) fn to_world_touching(ids: &[u32], t: Touching) -> Touching {
    Touching {
        a: BodyId(ids[t.a.index()]),
        b: BodyId(ids[t.b.index()]),
        ..t
    }
}

pub(crate) fn to_world_warm(
    ids: &[u32],
    ((a, b), w): ((BodyId, BodyId), Vec<WarmContact>),
) -> ((BodyId, BodyId), Vec<WarmContact>) {
    ((BodyId(ids[a.index()]), BodyId(ids[b.index()])), w)
}
