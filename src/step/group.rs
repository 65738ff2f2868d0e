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
use super::region::{PairKey, Region, Segment, StepStatic};
use super::stats::{Counters, NumericalFailure, StageSeconds};
use super::toi::{Since, SolvedSince};
use super::{EVENTS_PER_MOVING_BODY, Executor, MAX_EARLIER_IMPACTS, MIN_EVENTS_PER_STEP};
use crate::body::Body;
use crate::body::{Activity, BodyId, BodyState};
use crate::collision::broadphase::{self, SphereProxy};
use crate::collision::narrowphase::CachedFeatures;
use crate::collision::narrowphase::PairResult;
use crate::contact::island::DisjointSets;
use crate::scene::Scene;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::time::Instant;

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
    pub separating: HashMap<PairKey, Vector3<f64>>,
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
    pub separating: HashMap<PairKey, Vector3<f64>>,
    pub together: SolvedTogether,
    pub spin_resolves: SpinResolves,
}

/// An impact time ordered for the queue (finite, so `total_cmp` is the
/// usual order).
#[derive(Clone, Copy, Debug, PartialEq)]
struct ImpactTime(f64);

impl Eq for ImpactTime {}
impl PartialOrd for ImpactTime {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for ImpactTime {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&o.0)
    }
}

/// A body's swept spheres and the box around them (min, max corners).
type Swept = (Vec<SphereProxy>, Vector3<f64>, Vector3<f64>);

/// The group's candidate pairs, kept so that an event costs what the bodies
/// it moved cost: each pair's latest result and time of impact, each body's
/// partners, its swept spheres, and a queue of impacts ordered by (time,
/// pair), the order in which the events are taken.
struct PairBook {
    results: BTreeMap<PairKey, PairResult>,
    /// Each body's candidate partners, ascending.
    partners: Vec<Vec<u32>>,
    /// Impact time of each pair whose time is known (`None`: no impact).
    toi: HashMap<PairKey, Option<f64>>,
    queue: BTreeSet<(ImpactTime, PairKey)>,
    /// Pairs whose time of impact is still to be found.
    dirty: BTreeSet<PairKey>,
    /// Each body's swept spheres and the box around them (`None`: fallen).
    spheres: Vec<Option<Swept>>,
}

impl PairBook {
    fn new(
        g: &Region,
        seg: &[Segment],
        end: &[BodyState],
        pairs: Vec<PairKey>,
        results: Vec<PairResult>,
    ) -> Self {
        let n = g.bodies.len();
        let mut book = PairBook {
            results: BTreeMap::new(),
            partners: vec![Vec::new(); n],
            toi: HashMap::new(),
            queue: BTreeSet::new(),
            dirty: BTreeSet::new(),
            spheres: vec![None; n],
        };
        for i in 0..n {
            book.sweep(g, i, seg, end);
        }
        for (k, r) in pairs.into_iter().zip(results) {
            book.insert(k, r);
        }
        book
    }

    fn insert(&mut self, (a, b): PairKey, r: PairResult) {
        for (x, y) in [(a, b), (b, a)] {
            let list = &mut self.partners[x as usize];
            if let Err(at) = list.binary_search(&y) {
                list.insert(at, y);
            }
        }
        self.results.insert((a, b), r);
        self.dirty.insert((a, b));
    }

    /// Drops every pair of body `i`.
    fn forget(&mut self, i: usize) {
        for j in std::mem::take(&mut self.partners[i]) {
            let k = ((i as u32).min(j), (i as u32).max(j));
            let list = &mut self.partners[j as usize];
            if let Ok(at) = list.binary_search(&(i as u32)) {
                list.remove(at);
            }
            self.results.remove(&k);
            self.dirty.remove(&k);
            if let Some(Some(t)) = self.toi.remove(&k) {
                self.queue.remove(&(ImpactTime(t), k));
            }
        }
    }

    /// Body `i`'s spheres swept along its current segment.
    fn sweep(&mut self, g: &Region, i: usize, seg: &[Segment], end: &[BodyState]) {
        if g.bodies[i].activity == Activity::Fallen {
            self.spheres[i] = None;
            return;
        }
        let mut s = Vec::new();
        g.push_swept(&mut s, i as u32, i, &seg[i].state, &end[i]);
        let r = |p: &SphereProxy| Vector3::repeat(p.radius);
        let lo = s
            .iter()
            .map(|p| p.center - r(p))
            .fold(Vector3::repeat(f64::INFINITY), |m, x| m.inf(&x));
        let hi = s
            .iter()
            .map(|p| p.center + r(p))
            .fold(Vector3::repeat(f64::NEG_INFINITY), |m, x| m.sup(&x));
        self.spheres[i] = Some((s, lo, hi));
    }

    /// Candidate pairs of the bodies in `changed` (sorted) against every
    /// body of the group, each pair once, ascending: the broadphase after an
    /// event, at the cost of the bodies it moved.
    fn candidates(&self, g: &Region, changed: &[usize]) -> Vec<PairKey> {
        let mut pairs = Vec::new();
        for &i in changed {
            let Some((si, lo_i, hi_i)) = &self.spheres[i] else {
                continue;
            };
            for (j, other) in self.spheres.iter().enumerate() {
                let Some((sj, lo_j, hi_j)) = other else {
                    continue;
                };
                if j == i
                    || (j < i && changed.binary_search(&j).is_ok())
                    || !(0..3).all(|k| lo_i[k] <= hi_j[k] && lo_j[k] <= hi_i[k])
                {
                    continue;
                }
                let hit = si.iter().any(|p| {
                    sj.iter().any(|q| {
                        let reach = p.radius + q.radius;
                        (p.center - q.center).norm_squared() <= reach * reach
                    })
                });
                let k = ((i as u32).min(j as u32), (i as u32).max(j as u32));
                if hit && g.needs_test(k.0, k.1) {
                    pairs.push(k);
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        pairs
    }

    /// The earliest impact over the pairs not accepted: finds the times of
    /// the pairs still dirty first. Ties go to the lower pair, so the order
    /// never depends on the order of the work.
    fn earliest(
        &mut self,
        g: &mut Region,
        seg: &[Segment],
        h: f64,
        since: &SolvedSince,
        accepted: &BTreeSet<PairKey>,
    ) -> Option<(PairKey, f64)> {
        for k in std::mem::take(&mut self.dirty) {
            if accepted.contains(&k) {
                continue;
            }
            let tau = g.time_of_impact(k, &self.results[&k], seg, h, since);
            self.toi.insert(k, tau);
            if let Some(t) = tau {
                self.queue.insert((ImpactTime(t), k));
            }
        }
        self.queue.first().map(|&(t, k)| (k, t.0))
    }

    /// The latest segment start of the bodies connected to body `i` by
    /// candidate pairs (itself included).
    fn latest_start(&self, seg: &[Segment], i: usize) -> f64 {
        let mut seen = BTreeSet::from([i as u32]);
        let mut frontier = vec![i as u32];
        let mut latest = seg[i].time;
        while let Some(j) = frontier.pop() {
            for &k in &self.partners[j as usize] {
                if seen.insert(k) {
                    latest = latest.max(seg[k as usize].time);
                    frontier.push(k);
                }
            }
        }
        latest
    }

    /// Takes pair `k` out of the running for this step.
    fn accept(&mut self, k: PairKey) {
        if let Some(Some(t)) = self.toi.get(&k) {
            self.queue.remove(&(ImpactTime(*t), k));
        }
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
}

impl GroupInput {
    /// Seconds its step is expected to take, for the schedule.
    pub fn predicted_s(&self) -> f64 {
        self.predicted_s
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
}

impl GroupOutput {
    /// V-Clip tasks and island solves the group's step ran.
    pub fn tasks(&self) -> (u64, u64) {
        (self.counters.pair_tests, self.counters.islands)
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
    } = input;
    let clock = std::time::Instant::now();
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
    };
    let state = GroupState {
        seg,
        end,
        pairs,
        since: since.into_iter().collect(),
        separating: separating.into_iter().collect(),
        together,
        spin_resolves: SpinResolves(spin_resolves),
    };
    let output = step_group(region, state, exec).map(|mut out| {
        out.busy_s = clock.elapsed().as_secs_f64();
        out
    });
    GroupReply(Some(output.map_err(GroupFailure::from)))
}

/// The group step: every impact event of the group in time order. An event
/// rolls the bodies that must move with it back to its instant τ, solves
/// their contacts there, re-integrates them to the step's end and retests
/// their pairs; the loop ends when no pair overlaps beyond what it carried.
pub(crate) fn step_group(
    mut g: Region,
    s: GroupState,
    exec: &mut dyn Executor,
) -> Result<GroupOutput, NumericalFailure> {
    let h = g.st.settings.dt;
    let t0 = g.st.t0;
    let n = g.bodies.len();
    let GroupState {
        mut seg,
        mut end,
        pairs,
        mut since,
        mut separating,
        together: mut solved_together,
        mut spin_resolves,
    } = s;
    // narrowphase: the group's pairs at the end of the step.
    let results = g.narrowphase_skipping_separating(exec, &pairs, &end, &separating);
    let clock = Instant::now();
    let nested_before = g.stage.nested();
    let moving = (0..n)
        .filter(|&i| g.moving(i) && g.bodies[i].is_dynamic())
        .count();
    let mut book = PairBook::new(&g, &seg, &end, pairs, results);
    // Each body's predicted spheres, grown as when the groups were formed:
    // a realised piece inside them can meet only what this group holds.
    let predicted: Vec<Option<Vec<SphereProxy>>> = book
        .spheres
        .iter()
        .map(|s| {
            s.as_ref().map(|(s, _, _)| {
                s.iter()
                    .map(|p| SphereProxy {
                        radius: p.radius * (1.0 + g.st.group_margin),
                        ..*p
                    })
                    .collect()
            })
        })
        .collect();
    let record =
        |g: &Region, pieces: &mut Vec<SphereProxy>, i: usize, from: &BodyState, to: &BodyState| {
            let mut piece = Vec::new();
            g.push_swept(&mut piece, g.ids[i], i, from, to);
            let inside = predicted[i].as_ref().is_some_and(|grown| {
                piece.len() == grown.len()
                    && piece
                        .iter()
                        .zip(grown)
                        .all(|(p, q)| (p.center - q.center).norm() + p.radius <= q.radius)
            });
            if !inside {
                pieces.extend(piece);
            }
        };
    // Which bodies have left their predicted path (rolled back or woken).
    let mut left = vec![false; n];
    let mut pieces: Vec<SphereProxy> = Vec::new();
    let mut events = 0usize;
    let mut accepted: BTreeSet<PairKey> = BTreeSet::new();
    let mut last_event: Option<(PairKey, f64)> = None;
    let budget = MIN_EVENTS_PER_STEP.max(EVENTS_PER_MOVING_BODY * moving);
    loop {
        let violation = book.earliest(&mut g, &seg, h, &since, &accepted);
        // An island due to be solved again (`SPIN_TRUST`) before the
        // next impact is an event of its own: its fastest spinner's group
        // rolls back and is solved as at an impact. Not before the latest
        // event of the bodies its pairs reach, where their segments start
        // (only those: what else the group holds must not move it).
        let due = spin_resolves
            .next()
            .map(|(at, i)| (at.max(book.latest_start(&seg, i)), i))
            .filter(|&(at, _)| violation.is_none_or(|(_, t)| at < t));
        let spin_resolve = due.is_some();
        let Some((mut pair, mut tau)) = due.map(|(at, i)| ((i as u32, i as u32), at)).or(violation)
        else {
            break;
        };
        if spin_resolve {
            spin_resolves.take(pair.0 as usize);
        } else if events >= budget {
            // Out of events: keep the small overlap rather than stall the step.
            accepted.insert(pair);
            book.accept(pair);
            g.counters.overlaps_accepted += 1;
            continue;
        }
        let (mut group_states, mut group_pairs, mut at_tau) =
            g.impact_group(exec, pair, tau, &book.partners, &seg, &solved_together);
        // An overlap beyond what a pair carried, found at τ in another
        // pair of the group, began before τ unseen: the end-of-step test
        // misses a body that dips into another and is out again by the
        // end (a 0.1 kg box bouncing at 5 m/s between a wall and a
        // hull went 1.3 mm into the hull). Its own impact comes first.
        for _ in 0..MAX_EARLIER_IMPACTS {
            let Some(earlier) =
                g.earlier_impact(pair, tau, (&group_pairs, &at_tau), &seg, &since, &accepted)
            else {
                break;
            };
            (pair, tau) = earlier;
            g.counters.toi_missed_overlaps += 1;
            (group_states, group_pairs, at_tau) =
                g.impact_group(exec, pair, tau, &book.partners, &seg, &solved_together);
        }
        if last_event == Some((pair, tau)) {
            // No progress: keep the small overlap rather than stall the step.
            accepted.insert(pair);
            book.accept(pair);
            g.counters.overlaps_accepted += 1;
            continue;
        }
        last_event = Some((pair, tau));
        if spin_resolve && pair.0 == pair.1 {
            g.counters.spin_resolves += 1;
        } else {
            events += 1;
        }
        let rolled: Vec<usize> = group_states.iter().map(|&(i, _)| i).collect();
        // Roll the bodies back to τ; a path that had already left its
        // prediction ends its piece there.
        for &(i, state) in &group_states {
            if left[i] {
                record(&g, &mut pieces, i, &seg[i].state, &state);
            }
            left[i] = true;
            seg[i].state = state;
            seg[i].time = tau;
            end[i] = state;
            let (f, t) = g.external(i, t0 + tau);
            seg[i].force = f;
            seg[i].torque = t;
        }
        for (k, r) in group_pairs.iter().zip(&at_tau) {
            let deepest = if r.penetrating { r.depth } else { 0.0 };
            since.insert(*k, Since { time: tau, deepest });
        }
        let touching_now = g.touching_from(&group_pairs, &at_tau);
        let woken = g.wake_touched(&touching_now, &mut seg, tau, t0);
        let mut members = rolled;
        members.extend(woken);
        members.sort_unstable();
        members.dedup();
        for &i in &members {
            left[i] = true;
        }
        let solved = g.contact_phase(exec, &touching_now, &members, &mut seg, h - tau);
        solved_together.record(&solved);
        spin_resolves.schedule(&solved, &members, tau, h);
        super::check_states(
            members.iter().map(|&i| (g.ids[i] as usize, &seg[i].state)),
            "solve_islands",
            t0 + tau,
        )?;
        separating.extend(g.separating_pairs(&touching_now, &seg));
        g.impacts.extend(touching_now);
        for &i in &members {
            end[i] = g.integrate_segment(i, &seg[i], h - tau);
        }
        g.counters.integrations += members.len() as u64;
        // The members' new paths may reach new bodies of the group: their
        // pairs are found and tested again; every other pair stands.
        let clock = Instant::now();
        for &i in &members {
            book.forget(i);
            book.sweep(&g, i, &seg, &end);
        }
        let redo = book.candidates(&g, &members);
        g.counters.candidate_pairs += redo.len() as u64;
        g.stage.broadphase += clock.elapsed().as_secs_f64();
        let redone = g.narrowphase_skipping_separating(exec, &redo, &end, &separating);
        for (k, r) in redo.into_iter().zip(redone) {
            book.insert(k, r);
        }
    }
    for i in 0..n {
        if left[i] {
            record(&g, &mut pieces, i, &seg[i].state, &end[i]);
        }
    }
    g.counters.toi_events += events as u64;
    g.stage.time_of_impact += clock.elapsed().as_secs_f64() - (g.stage.nested() - nested_before);
    let (pairs, results) = book.results.into_iter().unzip();
    Ok(GroupOutput {
        ids: g.ids,
        bodies: g.bodies,
        sleep_timer: g.sleep_timer,
        end,
        pairs,
        results,
        warm: g.warm.into_iter().collect(),
        impacts: g.impacts,
        pair_forces: g.pair_forces.into_iter().collect(),
        counters: g.counters,
        stage: g.stage,
        events: events as u64,
        pieces,
        busy_s: 0.0,
    })
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
