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

use super::contact::{SolvedTogether, SpinResolves};
use super::executor::{
    Executor, GroupFailure, GroupInput, GroupOutput, GroupParams, GroupReply, PairKey,
    PreparedPairs, Segment, StepStatic,
};
use super::impacts::{GroupState, step_group};
use super::region::{PairMap, Region, RegionState};
use super::stats::{Counters, NumericalFailure};
use super::timers::{Stage, StageSeconds};
use super::toi::{PairAsk, SolvedSince};
use super::touching::{Touching, WarmContact};
use crate::body::{Activity, BodyId, BodyState};
use crate::collision::broadphase::{self, SphereProxy};
use crate::collision::narrowphase::PairResult;
use crate::contact::island::DisjointSets;
use crate::contact::solver::IslandTask;
use nalgebra::Vector3;
use std::collections::{BTreeMap, BTreeSet};

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

/// Whether body `i` is a node of the groups: a dynamic body still in the
/// world (fixed and driven bodies take no impulse and connect nothing).
fn grouped(world: &Region, i: u32) -> bool {
    let b = &world.bodies[i as usize];
    b.is_dynamic() && b.activity != Activity::Fallen
}

/// Partitions the world's candidate pairs into groups, ordered by id.
pub(crate) fn plan_groups(world: &Region, start: &StepStart) -> Vec<GroupPlan> {
    let n = world.bodies.len();
    let dynamic = |i: u32| grouped(world, i);
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

/// Seconds a group's step is expected to take: what its bodies' groups
/// took last step, a body never grouped before a pair test's worth (10 µs).
fn predicted_s(start: &StepStart, plan: &GroupPlan) -> f64 {
    plan.members
        .iter()
        .map(|&i| start.body_cost[i as usize].max(1e-5))
        .sum()
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
    let predicted_s = predicted_s(start, plan);
    GroupInput {
        predicted_s,
        prepared: None,
        keep_paths: false,
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
        keep_paths,
    } = input;
    let clock = std::time::Instant::now();
    // A first stage run beforehand is part of what the group cost.
    let prepared_s = prepared.as_ref().map_or(0.0, |p| p.busy_s);
    let mut together = SolvedTogether::new(ids.len());
    together.record_islands(islands);
    let mut owned = RegionState {
        bodies,
        features: features.into_iter().collect(),
        warm: warm.into_iter().collect(),
        sleep_timer,
        sleep_group,
        ..Default::default()
    };
    let mut region = owned.region(st, ids);
    region.keep_answers = keep_paths;
    let state = GroupState {
        seg,
        end,
        pairs,
        since: since.into_iter().collect(),
        separating: separating.into_iter().collect(),
        together,
        spin_resolves: SpinResolves(spin_resolves),
        prepared,
        keep_paths,
    };
    let output = step_group(&mut region, state, exec).map(|mut out| {
        out.busy_s = clock.elapsed().as_secs_f64() + prepared_s;
        out
    });
    GroupReply(
        Some(output.map_err(GroupFailure::from)),
        region.gathered.captured,
    )
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

/// Dynamic members from which a group is split into the parts its pairs'
/// first stage says interact (`split_group`). A pile is one group by its
/// swept spheres (every body near another), but most of its bodies meet
/// few of the others within a step, so it falls into many small parts.
/// Below this a group is cheap enough whole.
pub const SPLIT_MIN_MEMBERS: usize = 16;
/// The fewest bodies of a group that the executor splits of its own
/// accord (`Executor::split_groups`): a pile. Smaller groups that hold the
/// others up are mostly bodies pouring in, whose parts meet so often that
/// the runs lost cost more than the sharing gains.
pub const SPLIT_AUTO_MIN_MEMBERS: usize = 256;

/// Gap (m) at the step's end within which a pair one of whose bodies has a
/// predicted impact stays in one part: the impact sends its bodies off
/// their paths, often into such neighbours, and parts that meet step again.
/// A wider gap means fewer such reruns but larger parts, which leave less
/// to share out (`docs/benchmarks.md` §4, *Split groups*).
pub const SPLIT_NEAR_IMPACT: f64 = 5e-4;

/// A group split into parts (`split_group`): what the parts' runs are
/// checked against (`check_parts`).
struct Family {
    /// Its dynamic members (sorted).
    members: Vec<u32>,
    /// Each of its pairs (index into `StepStart::pairs`) with its first
    /// stage: the end-of-step result and time of impact along the
    /// predicted paths.
    first: BTreeMap<usize, (PairResult, Option<f64>)>,
    /// Wall seconds its first stage took (shared over its parts by pairs).
    busy_s: f64,
}

impl Family {
    /// The part of its first stage a plan of its members steps from.
    fn prepared(&self, pairs: &[usize]) -> PreparedPairs {
        let (results, toi) = pairs.iter().map(|k| self.first[k].clone()).unzip();
        PreparedPairs {
            results,
            toi,
            busy_s: self.busy_s * pairs.len() as f64 / self.first.len().max(1) as f64,
            ..Default::default()
        }
    }
}

/// What the step's groups leave.
pub(crate) struct GroupsDone {
    /// The groups' runs, in group-id order.
    pub runs: Vec<GroupOutput>,
    /// Groups stepped again from the step's start (`Counters::group_reruns`).
    pub reruns: u64,
    /// End-of-step results of the pairs between the parts of split groups
    /// (world keys), which no part held.
    pub between: Vec<(PairKey, PairResult)>,
    /// What the split groups' first stages and the checks between their
    /// parts counted and took (their nested stages).
    pub counters: Counters,
    pub stage: StageSeconds,
}

/// The parts of a large group (`SPLIT_MIN_MEMBERS`): the connected
/// components of its bodies under what its first stage says interacts
/// within the step along the predicted paths: bodies solved together or
/// touching at the step's start, a resting system whole, each pair that
/// has a time of impact or ends the step touching, and each pair within
/// `SPLIT_NEAR_IMPACT` of a body with a time of impact. Its other pairs
/// lie between parts; `check_parts` tests them against the paths the
/// parts took, and parts whose bodies meet merge and step again.
fn split_group(
    world: &Region,
    start: &StepStart,
    plan: &GroupPlan,
    family: &Family,
) -> Vec<GroupPlan> {
    let n = world.bodies.len();
    let dynamic = |i: u32| grouped(world, i);
    let mut sets = DisjointSets::new(n);
    for bodies in &start.together {
        for w in bodies.windows(2) {
            sets.union(w[0] as u32, w[1] as u32);
        }
    }
    for &(a, b) in &start.touching {
        if dynamic(a) && dynamic(b) {
            sets.union(a, b);
        }
    }
    for &i in &plan.members {
        if world.bodies[i as usize].activity == Activity::Sleeping {
            sets.union(i, world.sleep_group[i as usize]);
        }
    }
    // The bodies of a predicted impact, which it sends off their paths.
    let mut hit = vec![false; n];
    for (&k, (_, toi)) in &family.first {
        if toi.is_some() {
            let (a, b) = start.pairs[k];
            hit[a as usize] = true;
            hit[b as usize] = true;
        }
    }
    for (&k, (r, toi)) in &family.first {
        let (a, b) = start.pairs[k];
        let near_hit = (hit[a as usize] || hit[b as usize]) && r.distance < SPLIT_NEAR_IMPACT;
        if dynamic(a)
            && dynamic(b)
            && (toi.is_some() || r.penetrating || !r.contacts.is_empty() || near_hit)
        {
            sets.union(a, b);
        }
    }
    let mut parts: BTreeMap<u32, GroupPlan> = BTreeMap::new();
    for &i in &plan.members {
        parts.entry(sets.find(i)).or_default().members.push(i);
    }
    for &k in &plan.pairs {
        let (a, b) = start.pairs[k];
        let root = match (dynamic(a), dynamic(b)) {
            (true, true) if sets.find(a) != sets.find(b) => continue,
            (true, _) => sets.find(a),
            (false, true) => sets.find(b),
            (false, false) => continue,
        };
        let part = parts.get_mut(&root).expect("a pair's body is a member");
        part.pairs.push(k);
        for x in [a, b] {
            if !dynamic(x) {
                part.neighbours.push(x);
            }
        }
    }
    let mut plans: Vec<GroupPlan> = parts.into_values().collect();
    for p in &mut plans {
        p.neighbours.extend(&plan.neighbours);
        p.neighbours.sort_unstable();
        p.neighbours.dedup();
    }
    plans
}

/// The pairs of `family` among `members` (sorted world ids): both dynamic
/// bodies among them, or its one dynamic body.
fn family_pairs(world: &Region, start: &StepStart, family: &Family, members: &[u32]) -> Vec<usize> {
    let inside = |x: u32| members.binary_search(&x).is_ok();
    let dynamic = |i: u32| grouped(world, i);
    family
        .first
        .keys()
        .copied()
        .filter(|&k| {
            let (a, b) = start.pairs[k];
            [a, b].iter().all(|&x| !dynamic(x) || inside(x)) && [a, b].iter().any(|&x| inside(x))
        })
        .collect()
}

/// Tests the pairs between the parts of a split group against the paths
/// the parts took: each pair whose bodies' realised swept spheres meet and
/// one of which left its prediction (`paths_meet`), unless neither part
/// ran since the last check (`fresh`: their paths are the ones checked
/// then). Adds the parts that met (indices into the plans) to `meets` and
/// the end-of-step results of the pairs between parts that did not to
/// `between`.
#[allow(clippy::too_many_arguments)]
fn check_parts(
    st: &StepStatic,
    world: &Region,
    start: &StepStart,
    family: &Family,
    (owner, fresh): (&[Option<usize>], &[bool]),
    paths: &[Option<&[Segment]>],
    meets: &mut Vec<(usize, usize)>,
    between: &mut BTreeMap<PairKey, PairResult>,
    done: &mut GroupsDone,
) {
    let part = |i: u32| owner[i as usize].expect("a member has a part");
    if !family.members.iter().any(|&i| fresh[part(i)]) {
        return;
    }
    let h = st.settings.dt;
    let left = |i: u32| paths[i as usize].is_some();
    let dynamic = |i: u32| grouped(world, i);
    // Pairs between parts along the predicted paths: the first stage's
    // answer stands where neither body left its prediction.
    for (&k, (r, _)) in &family.first {
        let (a, b) = start.pairs[k];
        if dynamic(a) && dynamic(b) && part(a) != part(b) && !left(a) && !left(b) {
            between.insert((a, b), r.clone());
        }
    }
    let mut proxies = Vec::new();
    for &i in &family.members {
        let w = i as usize;
        match paths[w] {
            Some(path) => {
                for (j, piece) in path.iter().enumerate() {
                    let until = path.get(j + 1).map_or(h, |p| p.time);
                    let to = world.integrate_segment(w, piece, until - piece.time);
                    world.push_swept(&mut proxies, i, w, &piece.state, &to);
                }
            }
            None => world.push_swept(&mut proxies, i, w, &start.seg[w].state, &start.end[w]),
        }
    }
    let pairs = broadphase::candidate_pairs(&proxies, |a, b| {
        let (p, q) = (part(a), part(b));
        p != q && (fresh[p] || fresh[q]) && (left(a) || left(b))
    });
    for (a, b) in pairs {
        let path =
            |i: u32| paths[i as usize].unwrap_or(std::slice::from_ref(&start.seg[i as usize]));
        match paths_meet(st, world, start, (a, b), [path(a), path(b)], done) {
            Some(r) => {
                between.insert((a, b), r);
            }
            None => meets.push((part(a), part(b))),
        }
    }
}

/// Whether two bodies' realised paths (their segments in time order) meet
/// within the step as the group step would have seen it: an impact on any
/// stretch where both keep their segments (`time_of_impact_within`), or
/// the two touching at an instant where one of them was rolled back (an
/// event there would have solved them together). `None` where they meet,
/// else the pair's result at the step's end.
fn paths_meet(
    st: &StepStatic,
    world: &Region,
    start: &StepStart,
    (a, b): PairKey,
    paths: [&[Segment]; 2],
    done: &mut GroupsDone,
) -> Option<PairResult> {
    let h = st.settings.dt;
    let mut bodies = vec![
        world.bodies[a as usize].clone(),
        world.bodies[b as usize].clone(),
    ];
    for (body, path) in bodies.iter_mut().zip(paths) {
        if path.len() > 1 {
            body.activity = Activity::Awake;
        }
    }
    let mut state = RegionState {
        bodies,
        features: world
            .features
            .get(&(a, b))
            .map(|f| ((0, 1), f.clone()))
            .into_iter()
            .collect(),
        sleep_timer: vec![world.sleep_timer[a as usize], world.sleep_timer[b as usize]],
        sleep_group: vec![world.sleep_group[a as usize], world.sleep_group[b as usize]],
        ..Default::default()
    };
    let mut g = state.region(st, vec![a, b]);
    let since: SolvedSince = start
        .since
        .get(&(a, b))
        .map(|s| ((0, 1), *s))
        .into_iter()
        .collect();
    let mut times: Vec<f64> = paths
        .iter()
        .flat_map(|p| p.iter().map(|s| s.time))
        .filter(|&t| t > 0.0 && t < h)
        .chain([0.0, h])
        .collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    let piece =
        |path: &[Segment], t: f64| *path.iter().rev().find(|s| s.time <= t).unwrap_or(&path[0]);
    let mut result = None;
    for w in times.windows(2) {
        let (from, to) = (w[0], w[1]);
        let seg = [piece(paths[0], from), piece(paths[1], from)];
        if from > 0.0 {
            let r = g.query_at(0, 1, &seg, from);
            if r.penetrating || !r.contacts.is_empty() {
                result = None;
                break;
            }
        }
        let r = g.query_at(0, 1, &seg, to);
        let q = PairAsk {
            k: (0, 1),
            r: &r,
            seg: &seg,
            since: &since,
        };
        if g.time_of_impact_within(q, (from, to)).is_some() {
            result = None;
            break;
        }
        result = Some(r);
    }
    done.counters.add(&state.counters);
    done.stage
        .add(&state.stage, &[Stage::Narrowphase, Stage::Broadphase]);
    result
}

/// Runs every group of the step and re-runs merged ones until no realised
/// path leaves its group; returns the runs in group-id order. A large
/// group is split first (`split_group`) and its parts' paths checked
/// against each other (`check_parts`). The islands the group steps
/// captured here (`GroupReply`) are appended to `captured`, in the order
/// of the replies, every round's (a run later merged away included).
pub(crate) fn step_groups<'s>(
    st: &'s StepStatic<'s>,
    world: &Region<'s>,
    start: &StepStart,
    exec: &mut dyn Executor,
    captured: &mut Vec<IslandTask>,
) -> Result<GroupsDone, NumericalFailure> {
    let n = world.bodies.len();
    let from = GroupsFrom {
        st,
        world,
        start,
        index: StartIndex::of(world, start),
        params: GroupParams::of(st),
    };
    let mut done = GroupsDone {
        runs: Vec::new(),
        reruns: 0,
        between: Vec::new(),
        counters: Counters::default(),
        stage: StageSeconds::default(),
    };
    let (mut plans, families) = from.plans_with_parts(exec, &mut done);
    let mut runs: Vec<Option<GroupOutput>> = (0..plans.len()).map(|_| None).collect();
    // Results of the pairs between parts checked so far (`check_parts`).
    let mut between: BTreeMap<PairKey, PairResult> = BTreeMap::new();
    loop {
        let fresh = from.run_pending(&plans, &families, &mut runs, exec, captured)?;
        let owner = owners(n, &plans);
        let meets =
            from.check_families(&families, (&owner, &fresh), &runs, &mut between, &mut done);
        let leaks = find_leaks(n, start, &plans, &runs, &owner);
        if leaks.is_empty() && meets.is_empty() {
            done.between = between.into_iter().collect();
            break;
        }
        (plans, runs) = from.merge_met(&families, (plans, runs), meets, leaks, &mut done.reruns);
    }
    done.runs = runs
        .into_iter()
        .map(|r| r.expect("every group ran"))
        .collect();
    exec.groups_stepped();
    Ok(done)
}

impl StartIndex {
    /// The indices of the world's entries at the start of the impact stage.
    fn of(world: &Region, start: &StepStart) -> Self {
        let n = world.bodies.len();
        StartIndex {
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
        }
    }
}

/// What every group of the step is planned, cut and stepped from.
struct GroupsFrom<'a, 's> {
    st: &'s StepStatic<'s>,
    world: &'a Region<'s>,
    start: &'a StepStart,
    index: StartIndex,
    params: GroupParams,
}

/// The large groups split into parts (`split_group`), and the family each
/// body belongs to, if any.
struct Families {
    list: Vec<Family>,
    of: Vec<Option<usize>>,
}

impl Families {
    /// The family all of a plan's members belong to, if one does.
    fn one_family(&self, plan: &GroupPlan) -> Option<usize> {
        let f = self.of[plan.members[0] as usize]?;
        plan.members
            .iter()
            .all(|&i| self.of[i as usize] == Some(f))
            .then_some(f)
    }
}

/// The group (index into `plans`) each body is a member of, if any.
fn owners(n: usize, plans: &[GroupPlan]) -> Vec<Option<usize>> {
    let mut owner: Vec<Option<usize>> = vec![None; n];
    for (p, plan) in plans.iter().enumerate() {
        for &i in &plan.members {
            owner[i as usize] = Some(p);
        }
    }
    owner
}

/// The realised paths the runs returned, by body (`GroupOutput::paths`).
fn realised_paths(n: usize, runs: &[Option<GroupOutput>]) -> Vec<Option<&[Segment]>> {
    let mut paths: Vec<Option<&[Segment]>> = vec![None; n];
    for run in runs.iter().flatten() {
        for (i, path) in &run.paths {
            paths[*i as usize] = Some(path);
        }
    }
    paths
}

impl GroupsFrom<'_, '_> {
    /// The step's group plans, sorted by id, with the large groups split
    /// into parts after their first stage (through the executor).
    fn plans_with_parts(
        &self,
        exec: &mut dyn Executor,
        done: &mut GroupsDone,
    ) -> (Vec<GroupPlan>, Families) {
        let (st, world, start) = (self.st, self.world, self.start);
        let n = world.bodies.len();
        // The large groups' first stage, through the executor, then their parts.
        let whole = plan_groups(world, start);
        // `--split-groups` splits them all; otherwise the executor chooses
        // (and measures its choice).
        let chosen = if st.step_settings.split_groups {
            vec![true; whole.len()]
        } else {
            exec.split_groups(
                &whole
                    .iter()
                    .map(|p| (predicted_s(start, p), p.members.len()))
                    .collect::<Vec<_>>(),
            )
        };
        let large: Vec<usize> = (0..whole.len())
            .filter(|&p| whole[p].members.len() >= SPLIT_MIN_MEMBERS && chosen[p])
            .collect();
        let inputs = large
            .iter()
            .map(|&p| group_input(world, start, &self.index, &whole[p]))
            .collect();
        let mut first: BTreeMap<usize, PreparedPairs> = large
            .into_iter()
            .zip(exec.prepare_groups(st, &self.params, inputs))
            .collect();
        let mut families = Families {
            list: Vec::new(),
            of: vec![None; n],
        };
        let mut plans = Vec::new();
        for (p, plan) in whole.into_iter().enumerate() {
            let Some(prepared) = first.remove(&p) else {
                plans.push(plan);
                continue;
            };
            done.counters.add(&prepared.counters);
            done.stage.add(&prepared.stage, &[Stage::Narrowphase]);
            let family = Family {
                members: plan.members.clone(),
                first: plan
                    .pairs
                    .iter()
                    .copied()
                    .zip(prepared.results.into_iter().zip(prepared.toi))
                    .collect(),
                busy_s: prepared.busy_s,
            };
            for &i in &plan.members {
                families.of[i as usize] = Some(families.list.len());
            }
            plans.extend(split_group(world, start, &plan, &family));
            families.list.push(family);
        }
        plans.sort_by_key(GroupPlan::id);
        (plans, families)
    }

    /// Steps every group still to step (`runs[p]` is `None`), through the
    /// executor (inline, or scattered over the workers); answers come back
    /// in group order. Returns which groups ran now.
    fn run_pending(
        &self,
        plans: &[GroupPlan],
        families: &Families,
        runs: &mut [Option<GroupOutput>],
        exec: &mut dyn Executor,
        captured: &mut Vec<IslandTask>,
    ) -> Result<Vec<bool>, NumericalFailure> {
        let todo: Vec<usize> = (0..plans.len()).filter(|&p| runs[p].is_none()).collect();
        let mut fresh = vec![false; plans.len()];
        for &p in &todo {
            fresh[p] = true;
        }
        let inputs = todo
            .iter()
            .map(|&p| {
                let plan = &plans[p];
                let mut input = group_input(self.world, self.start, &self.index, plan);
                if let Some(f) = families.one_family(plan) {
                    input.prepared = Some(families.list[f].prepared(&plan.pairs));
                }
                input.keep_paths = plan
                    .members
                    .iter()
                    .any(|&i| families.of[i as usize].is_some());
                input
            })
            .collect();
        let mut replies = exec.step_groups(self.st, &self.params, inputs);
        for reply in &mut replies {
            captured.append(&mut reply.1);
        }
        for (p, reply) in todo.into_iter().zip(replies) {
            let output = reply.0.expect("every group answered")?;
            runs[p] = Some(output);
        }
        Ok(fresh)
    }

    /// Checks the pairs between the parts of every split group against
    /// the paths the parts took (`check_parts`); returns the parts that
    /// met. What was checked between parts that have not run again stands
    /// in `between`.
    fn check_families(
        &self,
        families: &Families,
        (owner, fresh): (&[Option<usize>], &[bool]),
        runs: &[Option<GroupOutput>],
        between: &mut BTreeMap<PairKey, PairResult>,
        done: &mut GroupsDone,
    ) -> Vec<(usize, usize)> {
        let paths = realised_paths(self.world.bodies.len(), runs);
        between.retain(|&(a, b), _| match (owner[a as usize], owner[b as usize]) {
            (Some(p), Some(q)) => p != q && !fresh[p] && !fresh[q],
            _ => false,
        });
        let mut meets = Vec::new();
        for family in &families.list {
            check_parts(
                self.st,
                self.world,
                self.start,
                family,
                (owner, fresh),
                &paths,
                &mut meets,
                between,
                done,
            );
        }
        meets
    }

    /// Merges the groups that met: they become one (the lowest index
    /// keeps the plan), and outside bodies join the group that met them.
    /// Returns the new plans in id order with the runs that still stand
    /// (`None`: to step again, counted in `reruns`).
    fn merge_met(
        &self,
        families: &Families,
        (plans, runs): (Vec<GroupPlan>, Vec<Option<GroupOutput>>),
        meets: Vec<(usize, usize)>,
        leaks: Vec<(usize, Leak)>,
        reruns: &mut u64,
    ) -> (Vec<GroupPlan>, Vec<Option<GroupOutput>>) {
        let (mut sets, joins) = meeting_sets(plans.len(), meets, leaks);
        step_families_whole(&mut sets, &plans, families);
        let (merged, changed) = merged_plans(self.world, &plans, &mut sets, &joins);
        let (plans, runs) = self.merged_runs(families, merged, &changed, runs, reruns);
        in_id_order(plans, runs)
    }

    /// The merged plans, their members, neighbours and pairs sorted; a
    /// group that changed takes its split families' pairs among its
    /// members and steps again, another keeps its run.
    fn merged_runs(
        &self,
        families: &Families,
        merged: BTreeMap<u32, GroupPlan>,
        changed: &BTreeSet<u32>,
        mut old_runs: Vec<Option<GroupOutput>>,
        reruns: &mut u64,
    ) -> (Vec<GroupPlan>, Vec<Option<GroupOutput>>) {
        let mut plans = Vec::new();
        let mut runs = Vec::new();
        for (root, mut m) in merged {
            m.members.sort_unstable();
            m.members.dedup();
            if changed.contains(&root) {
                // The pairs between merged parts of a split group are the
                // merged group's own now.
                let involved: BTreeSet<usize> = m
                    .members
                    .iter()
                    .filter_map(|&i| families.of[i as usize])
                    .collect();
                for f in involved {
                    m.pairs.extend(family_pairs(
                        self.world,
                        self.start,
                        &families.list[f],
                        &m.members,
                    ));
                }
            }
            m.neighbours.sort_unstable();
            m.neighbours.dedup();
            m.pairs.sort_unstable();
            m.pairs.dedup();
            plans.push(m);
            if changed.contains(&root) {
                *reruns += 1;
                runs.push(None);
            } else {
                runs.push(old_runs[root as usize].take());
            }
        }
        (plans, runs)
    }
}

/// The sets of groups that met (by index), and the outside bodies that
/// join each group.
fn meeting_sets(
    groups: usize,
    meets: Vec<(usize, usize)>,
    leaks: Vec<(usize, Leak)>,
) -> (DisjointSets, BTreeMap<usize, BTreeSet<u32>>) {
    let mut sets = DisjointSets::new(groups);
    let mut joins: BTreeMap<usize, BTreeSet<u32>> = BTreeMap::new();
    for (p, q) in meets {
        sets.union(p as u32, q as u32);
    }
    for (p, leak) in leaks {
        match leak {
            Leak::Group(q) => sets.union(p as u32, q as u32),
            Leak::Body(b) => {
                joins.entry(p).or_default().insert(b);
            }
        }
    }
    (sets, joins)
}

/// A split group whose parts merge into one holding more than half its
/// bodies steps whole: its parts would go on meeting, and each round's
/// runs of the growing part would be lost.
fn step_families_whole(sets: &mut DisjointSets, plans: &[GroupPlan], families: &Families) {
    let mut in_family: BTreeMap<(usize, u32), usize> = BTreeMap::new();
    for (p, plan) in plans.iter().enumerate() {
        for &i in &plan.members {
            if let Some(f) = families.of[i as usize] {
                *in_family.entry((f, sets.find(p as u32))).or_default() += 1;
            }
        }
    }
    for (f, family) in families.list.iter().enumerate() {
        let most = in_family
            .range((f, 0)..=(f, u32::MAX))
            .map(|(_, &k)| k)
            .max()
            .unwrap_or(0);
        if 2 * most > family.members.len() {
            let parts: Vec<usize> = (0..plans.len())
                .filter(|&p| families.of[plans[p].members[0] as usize] == Some(f))
                .collect();
            for w in parts.windows(2) {
                sets.union(w[0] as u32, w[1] as u32);
            }
        }
    }
}

/// The plans merged under each set's root, with the outside bodies that
/// joined them (a sleeping one with its whole resting system), and the
/// roots whose group changed.
fn merged_plans(
    world: &Region,
    plans: &[GroupPlan],
    sets: &mut DisjointSets,
    joins: &BTreeMap<usize, BTreeSet<u32>>,
) -> (BTreeMap<u32, GroupPlan>, BTreeSet<u32>) {
    let n = world.bodies.len();
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
    (merged, changed)
}

/// The plans and their runs in id order (a merged group takes its lowest
/// member).
fn in_id_order(
    plans: Vec<GroupPlan>,
    runs: Vec<Option<GroupOutput>>,
) -> (Vec<GroupPlan>, Vec<Option<GroupOutput>>) {
    let mut order: Vec<usize> = (0..plans.len()).collect();
    order.sort_by_key(|&p| plans[p].id());
    let mut taken: Vec<Option<(GroupPlan, Option<GroupOutput>)>> =
        plans.into_iter().zip(runs).map(Some).collect();
    let mut plans = Vec::new();
    let mut runs = Vec::new();
    for p in order {
        let (plan, run) = taken[p].take().expect("each plan once");
        plans.push(plan);
        runs.push(run);
    }
    (plans, runs)
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
