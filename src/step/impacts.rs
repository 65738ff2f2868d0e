//! A group's step (`step_group`): the end-of-step narrowphase of its pairs,
//! then every impact event in time order, with the event-local bookkeeping
//! (`PairBook`) that makes an event cost what the bodies it moved cost.
//! Reads only the group's own `Region` and `GroupState` (built by `group`).

use super::contact::{SolvedTogether, SpinResolves};
use super::event_path::EventPaths;
use super::executor::{Executor, GroupOutput, PairKey, PreparedPairs, Segment, Since};
use super::region::{PairMap, Region};
use super::stats::{NumericalFailure, check_states};
use super::timers::{Stage, StageTimer};
use super::toi::{PairAsk, Search, SolvedSince};
use crate::body::{Activity, BodyState};
use crate::collision::broadphase::SphereProxy;
use crate::collision::narrowphase::PairResult;
use nalgebra::Vector3;
use std::collections::{BTreeMap, BTreeSet};

/// Impact events one body may take part in during a step (as one of an
/// impact's two bodies) before the overlaps left on its pairs are accepted.
/// The count is each body's own, not its group's, so what a group decides
/// depends only on the bodies its events touch, and a group split into
/// parts decides as it would whole. A body chattering against a wall or
/// between two neighbours soon reaches it, while bodies landing in a pour
/// take one or two events each.
pub const EVENTS_PER_BODY: usize = 256;
/// How many times an impact may give way to an earlier one found in its
/// group (`Region::earlier_impact`) before it is taken as it is.
const MAX_EARLIER_IMPACTS: usize = 8;

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
    toi: PairMap<Option<f64>>,
    queue: BTreeSet<(ImpactTime, PairKey)>,
    /// Pairs whose time of impact is still to be found.
    dirty: BTreeSet<PairKey>,
    /// Searches stopped part way, each under the instant before which it
    /// can find no impact (`Search::not_before`): taken on only while that
    /// could come before the earliest impact found (`earliest`).
    waiting: BTreeSet<(ImpactTime, PairKey)>,
    searches: PairMap<Search>,
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
            toi: PairMap::default(),
            queue: BTreeSet::new(),
            dirty: BTreeSet::new(),
            waiting: BTreeSet::new(),
            searches: PairMap::default(),
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
            if let Some(search) = self.searches.remove(&k) {
                self.waiting.remove(&(ImpactTime(search.not_before()), k));
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

    /// The earliest impact over the pairs not accepted: begins the search of
    /// each pair still dirty, then takes on the searches that could still
    /// find an earlier impact (`waiting`) until none can. A search stopped
    /// part way gives the answer it would have given whole (the same
    /// samples), and one forgotten before it is needed (an event moved one
    /// of its bodies first) costs only what it took: most of a pour's
    /// searches are (the 1000-body pour's samples after the event that
    /// dropped their pair were 1.97 s of the 3.72 s of searches in its
    /// 0.5–0.6 s, while it pours in).
    /// Ties go to the lower pair, so the order never depends on the order
    /// of the work.
    fn earliest(
        &mut self,
        g: &mut Region,
        seg: &[Segment],
        h: f64,
        since: &SolvedSince,
        accepted: &BTreeSet<PairKey>,
        deps: &mut EventPaths,
    ) -> Option<(PairKey, f64)> {
        for k in std::mem::take(&mut self.dirty) {
            if accepted.contains(&k) {
                continue;
            }
            let started = deps.start();
            let r = &self.results[&k];
            let search = g.begin_time_of_impact(PairAsk { k, r, seg, since }, h);
            deps.search(bodies_of(k), started);
            self.wait_or_find(k, search);
        }
        loop {
            let earliest = self.queue.first().map(|&(t, _)| t.0);
            let Some(&(ImpactTime(from), k)) = self.waiting.first() else {
                break;
            };
            // Ties go to the lower pair: a search that may end at the
            // earliest instant itself is taken on.
            let limit = earliest.unwrap_or(f64::INFINITY);
            if from > limit {
                break;
            }
            self.waiting.pop_first();
            let search = self
                .searches
                .remove(&k)
                .expect("every waiting pair has its search");
            let started = deps.start();
            let search = g.continue_search(search, seg, limit);
            deps.search(bodies_of(k), started);
            self.wait_or_find(k, search);
        }
        self.queue.first().map(|&(t, k)| (k, t.0))
    }

    /// Pair `k`'s time of impact where its search has ended, else its
    /// search kept to be taken on.
    fn wait_or_find(&mut self, k: PairKey, search: Search) {
        match search {
            Search::Found(tau) => {
                self.toi.insert(k, tau);
                if let Some(t) = tau {
                    self.queue.insert((ImpactTime(t), k));
                }
            }
            search => {
                self.waiting.insert((ImpactTime(search.not_before()), k));
                self.searches.insert(k, search);
            }
        }
    }

    /// Times of impact already found for `keys` (the group's first stage,
    /// prepared beforehand): as `earliest` would have found them, no pair
    /// being accepted yet.
    fn known(&mut self, keys: &[PairKey], toi: Vec<Option<f64>>) {
        for (&k, tau) in keys.iter().zip(toi) {
            self.dirty.remove(&k);
            self.wait_or_find(k, Search::Found(tau));
        }
    }

    /// Takes pair `k` out of the running for this step.
    fn accept(&mut self, k: PairKey) {
        if let Some(Some(t)) = self.toi.get(&k) {
            self.queue.remove(&(ImpactTime(*t), k));
        }
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
    /// Whether the step returns the segments its bodies took
    /// (`GroupOutput::paths`): a part of a split group does.
    pub keep_paths: bool,
}

/// The group step: every impact event of the group in time order. An event
/// rolls the bodies that must move with it back to its instant τ, solves
/// their contacts there, re-integrates them to the step's end and retests
/// their pairs; the loop ends when no pair overlaps beyond what it carried.
/// The region's state moves into the output; what it captured stays with
/// the caller, also after a failure.
pub(crate) fn step_group(
    g: &mut Region,
    s: GroupState,
    exec: &mut dyn Executor,
) -> Result<GroupOutput, NumericalFailure> {
    let mut events = EventLoop::begin(g, s, exec);
    while events.take_next(g, exec)? {}
    Ok(events.finish(g))
}

/// The group's pairs at the end of the step (the narrowphase), with their
/// times of impact where they were answered beforehand (`prepared`).
fn end_of_step_pairs(
    g: &mut Region,
    exec: &mut dyn Executor,
    prepared: Option<PreparedPairs>,
    (pairs, end, separating): (&[PairKey], &[BodyState], &PairMap<Vector3<f64>>),
) -> (Vec<PairResult>, Option<Vec<Option<f64>>>) {
    match prepared {
        Some(p) => {
            g.counters.add(&p.counters);
            g.stage
                .add(&p.stage, &[Stage::Narrowphase, Stage::TimeOfImpact]);
            (p.results, Some(p.toi))
        }
        None => (
            g.narrowphase_skipping_separating(exec, pairs, end, separating),
            None,
        ),
    }
}

/// The pieces of the bodies' realised paths that leave their predicted
/// spheres (`GroupOutput::pieces`), which `group` tests against what the
/// group does not hold.
struct PathPieces {
    /// Each body's predicted spheres, grown as when the groups were
    /// formed: a realised piece inside them can meet only what this group
    /// holds (`None`: fallen).
    predicted: Vec<Option<Vec<SphereProxy>>>,
    pieces: Vec<SphereProxy>,
}

impl PathPieces {
    fn new(g: &Region, book: &PairBook) -> Self {
        let predicted = book
            .spheres
            .iter()
            .map(|s| {
                s.as_ref().map(|(s, _, _)| {
                    s.iter()
                        .map(|p| SphereProxy {
                            radius: p.radius * (1.0 + g.st.step_settings.group_margin),
                            ..*p
                        })
                        .collect()
                })
            })
            .collect();
        PathPieces {
            predicted,
            pieces: Vec::new(),
        }
    }

    /// Keeps body `i`'s path from `from` to `to` unless it lies inside its
    /// predicted spheres.
    fn record(&mut self, g: &Region, i: usize, from: &BodyState, to: &BodyState) {
        let mut piece = Vec::new();
        g.push_swept(&mut piece, g.ids[i], i, from, to);
        let inside = self.predicted[i].as_ref().is_some_and(|grown| {
            piece.len() == grown.len()
                && piece
                    .iter()
                    .zip(grown)
                    .all(|(p, q)| (p.center - q.center).norm() + p.radius <= q.radius)
        });
        if !inside {
            self.pieces.extend(piece);
        }
    }
}

/// What the event loop chose to do next (`EventLoop::choose`).
enum Choice {
    /// No impact or spin resolve is left in the step.
    Done,
    /// The earliest impact was accepted as it is (its bodies are out of
    /// events); look again.
    Accepted,
    /// Take the event of `pair` at `tau`: an impact, or a spin resolve (a
    /// body paired with itself).
    Take {
        pair: PairKey,
        tau: f64,
        spin_resolve: bool,
    },
}

/// An event's impact group at its instant τ (`Region::impact_group`): the
/// bodies rolled back with their states there, and their pairs' results.
struct Impact {
    pair: PairKey,
    tau: f64,
    states: Vec<(usize, BodyState)>,
    pairs: Vec<PairKey>,
    at_tau: Vec<PairResult>,
}

/// A pair's two bodies, as indices.
fn bodies_of((a, b): PairKey) -> (usize, usize) {
    (a as usize, b as usize)
}

/// The bodies of `pairs`, each pair's two.
fn bodies_of_pairs(pairs: &[PairKey]) -> impl Iterator<Item = usize> + '_ {
    pairs.iter().flat_map(|&k| <[usize; 2]>::from(bodies_of(k)))
}

/// The dynamic bodies of `pair`.
fn dynamic_bodies(g: &Region, pair: PairKey) -> Vec<usize> {
    <[usize; 2]>::from(bodies_of(pair))
        .into_iter()
        .filter(|&i| g.bodies[i].is_dynamic())
        .collect::<Vec<_>>()
}

/// What the group's impact loop carries from one event to the next.
struct EventLoop {
    h: f64,
    t0: f64,
    seg: Vec<Segment>,
    end: Vec<BodyState>,
    since: SolvedSince,
    separating: PairMap<Vector3<f64>>,
    solved_together: SolvedTogether,
    spin_resolves: SpinResolves,
    book: PairBook,
    pieces: PathPieces,
    /// Which bodies have left their predicted path (rolled back or woken).
    left: Vec<bool>,
    keep_paths: bool,
    /// The segments each body took, where asked for (`GroupOutput::paths`).
    paths: Vec<Vec<Segment>>,
    events: usize,
    accepted: BTreeSet<PairKey>,
    /// Every rule of the loop is a body's own, so that a group split into
    /// parts (`group::split_group`) decides each as the whole group would:
    /// the events each body took part in (`EVENTS_PER_BODY`), and the last
    /// event that moved it, by world ids (the no-progress rule).
    events_of: Vec<usize>,
    last_of: Vec<Option<(PairKey, f64)>>,
    /// The time of impact stage, from the first stage's end to the loop's.
    timer: StageTimer,
    prepared_tasks: u64,
    /// The loop's events and searches on their dependency path.
    deps: EventPaths,
}

impl EventLoop {
    /// The group step's first stage, the narrowphase of its pairs at the
    /// end of the step (unless they were answered beforehand, with their
    /// times of impact), and the loop's state before its first event.
    fn begin(g: &mut Region, s: GroupState, exec: &mut dyn Executor) -> Self {
        let h = g.st.settings.dt;
        let t0 = g.st.t0;
        let n = g.bodies.len();
        let GroupState {
            seg,
            end,
            pairs,
            since,
            separating,
            together: solved_together,
            spin_resolves,
            prepared,
            keep_paths,
        } = s;
        let prepared_tasks = prepared.as_ref().map_or(0, PreparedPairs::tasks);
        let (results, prepared_toi) =
            end_of_step_pairs(g, exec, prepared, (&pairs, &end, &separating));
        let keys = prepared_toi.as_ref().map(|_| pairs.clone());
        let timer = g.stage.start(Stage::TimeOfImpact);
        let mut book = PairBook::new(g, &seg, &end, pairs, results);
        if let (Some(keys), Some(toi)) = (keys, prepared_toi) {
            book.known(&keys, toi);
        }
        let pieces = PathPieces::new(g, &book);
        let paths: Vec<Vec<Segment>> = if keep_paths {
            seg.iter().map(|s| vec![*s]).collect()
        } else {
            Vec::new()
        };
        EventLoop {
            h,
            t0,
            seg,
            end,
            since,
            separating,
            solved_together,
            spin_resolves,
            book,
            pieces,
            left: vec![false; n],
            keep_paths,
            paths,
            events: 0,
            accepted: BTreeSet::new(),
            events_of: vec![0usize; n],
            last_of: vec![None; n],
            timer,
            prepared_tasks,
            deps: EventPaths::new(n, g.st.step_settings.time_events),
        }
    }

    /// Takes the group's next event, if any is left (false once none is).
    fn take_next(
        &mut self,
        g: &mut Region,
        exec: &mut dyn Executor,
    ) -> Result<bool, NumericalFailure> {
        let (pair, tau, spin_resolve) = match self.choose(g) {
            Choice::Done => return Ok(false),
            Choice::Accepted => return Ok(true),
            Choice::Take {
                pair,
                tau,
                spin_resolve,
            } => (pair, tau, spin_resolve),
        };
        let started = self.deps.start();
        let Some(impact) = self.impact_at(g, exec, pair, tau, spin_resolve) else {
            return Ok(true);
        };
        let pair = impact.pair;
        let world_event = ((g.ids[pair.0 as usize], g.ids[pair.1 as usize]), impact.tau);
        let own = dynamic_bodies(g, pair);
        if !own.is_empty() && own.iter().all(|&i| self.last_of[i] == Some(world_event)) {
            // No progress: keep the small overlap rather than stall the step.
            self.accept(g, pair);
            // It read the bodies of its impact group's pairs.
            let read = || (Vec::new(), bodies_of_pairs(&impact.pairs).collect());
            self.deps.event(started, read);
            return Ok(true);
        }
        self.count_event(g, &impact, spin_resolve, &own);
        self.roll_back(g, &impact);
        let members = self.solve_at_impact(g, exec, &impact, &own, world_event)?;
        let retested = self.retest_moved(g, exec, &members);
        // It moved what it rolled back or woke, and read the bodies of its
        // impact group's pairs and of the pairs it tested again.
        self.deps.event(started, || {
            let rolled = impact.states.iter().map(|&(i, _)| i);
            let read = bodies_of_pairs(&impact.pairs).chain(bodies_of_pairs(&retested));
            (rolled.chain(members).collect(), read.collect())
        });
        Ok(true)
    }

    /// Keeps the small overlap of `pair` rather than stall the step.
    fn accept(&mut self, g: &mut Region, pair: PairKey) {
        self.accepted.insert(pair);
        self.book.accept(pair);
        g.counters.overlaps_accepted += 1;
    }

    /// The next event: the earliest impact, or a spin resolve due before it.
    fn choose(&mut self, g: &mut Region) -> Choice {
        let violation = self.book.earliest(
            g,
            &self.seg,
            self.h,
            &self.since,
            &self.accepted,
            &mut self.deps,
        );
        // An island due to be solved again (`SPIN_TRUST`) before the
        // next impact is an event of its own: its fastest spinner's group
        // rolls back and is solved as at an impact. Not before the
        // segments of the bodies it rolls back start (their latest
        // events): first those solved with the spinner, then, once its
        // group is found, all of the group's.
        let before_impact = |at: f64| violation.is_none_or(|(_, t)| at < t);
        let due = self
            .spin_resolves
            .next(|i| {
                self.solved_together
                    .partners(i)
                    .iter()
                    .fold(self.seg[i].time, |t, &j| t.max(self.seg[j].time))
            })
            .filter(|&(at, _)| before_impact(at));
        let spin_resolve = due.is_some();
        let Some((pair, tau)) = due.map(|(at, i)| ((i as u32, i as u32), at)).or(violation) else {
            return Choice::Done;
        };
        let exhausted = dynamic_bodies(g, pair)
            .iter()
            .any(|&i| self.events_of[i] >= EVENTS_PER_BODY);
        if spin_resolve {
            self.spin_resolves.take(pair.0 as usize);
        } else if exhausted {
            // Out of events: keep the small overlap rather than stall the step.
            self.accept(g, pair);
            return Choice::Accepted;
        }
        Choice::Take {
            pair,
            tau,
            spin_resolve,
        }
    }

    /// The impact group of the event of `pair` at `tau`, or of an earlier
    /// impact found in it; `None` where a spin resolve must wait for the
    /// latest segment of its group to start.
    fn impact_at(
        &mut self,
        g: &mut Region,
        exec: &mut dyn Executor,
        mut pair: PairKey,
        mut tau: f64,
        spin_resolve: bool,
    ) -> Option<Impact> {
        let (mut group_states, mut group_pairs, mut at_tau) = self.group_at(g, exec, pair, tau);
        if spin_resolve {
            let latest = group_states
                .iter()
                .fold(tau, |t, &(i, _)| t.max(self.seg[i].time));
            if latest > tau {
                self.spin_resolves.defer(pair.0 as usize, latest);
                return None;
            }
        }
        // An overlap beyond what a pair carried, found at τ in another
        // pair of the group, began before τ unseen: the end-of-step test
        // misses a body that dips into another and is out again by the
        // end (a 0.1 kg box bouncing at 5 m/s between a wall and a
        // hull went 1.3 mm into the hull). Its own impact comes first.
        for _ in 0..MAX_EARLIER_IMPACTS {
            let Some(earlier) = g.earlier_impact(
                pair,
                tau,
                (&group_pairs, &at_tau),
                &self.seg,
                &self.since,
                &self.accepted,
            ) else {
                break;
            };
            (pair, tau) = earlier;
            g.counters.toi_missed_overlaps += 1;
            (group_states, group_pairs, at_tau) = self.group_at(g, exec, pair, tau);
        }
        Some(Impact {
            pair,
            tau,
            states: group_states,
            pairs: group_pairs,
            at_tau,
        })
    }

    /// The bodies that must move with an impact of `pair` at `tau`, with
    /// their states there, their pairs and those pairs' results at `tau`
    /// (`Region::impact_group` over the loop's partners and segments).
    fn group_at(
        &self,
        g: &mut Region,
        exec: &mut dyn Executor,
        pair: PairKey,
        tau: f64,
    ) -> (Vec<(usize, BodyState)>, Vec<PairKey>, Vec<PairResult>) {
        g.impact_group(
            exec,
            pair,
            tau,
            &self.book.partners,
            &self.seg,
            &self.solved_together,
        )
    }

    /// Counts the event: a spin resolve, or an impact by its approach.
    fn count_event(&mut self, g: &mut Region, impact: &Impact, spin_resolve: bool, own: &[usize]) {
        let pair = impact.pair;
        if spin_resolve && pair.0 == pair.1 {
            g.counters.spin_resolves += 1;
        } else {
            self.events += 1;
            for &i in own {
                self.events_of[i] += 1;
            }
            let speed = approach_speed(
                g,
                pair,
                &impact.states,
                &impact.pairs,
                &impact.at_tau,
                &self.seg,
            );
            g.counters.toi_events_by_approach[approach_band(speed, g.st.settings)] += 1;
            g.counters.count_event_rollback(impact.states.len());
            if self.since.get(&pair).is_some_and(|s| s.touched) {
                g.counters.overlap_repairs += 1;
            }
        }
    }

    /// Rolls the impact group's bodies back to τ (a path that had already
    /// left its prediction ends its piece there), and notes what each of
    /// its pairs carried at τ.
    fn roll_back(&mut self, g: &Region, impact: &Impact) {
        let tau = impact.tau;
        for &(i, state) in &impact.states {
            if self.left[i] {
                self.pieces.record(g, i, &self.seg[i].state, &state);
            }
            self.left[i] = true;
            self.seg[i].state = state;
            self.seg[i].time = tau;
            self.end[i] = state;
            let (f, t) = g.external(i, self.t0 + tau);
            self.seg[i].force = f;
            self.seg[i].torque = t;
        }
        for (k, r) in impact.pairs.iter().zip(&impact.at_tau) {
            let deepest = if r.penetrating { r.depth } else { 0.0 };
            let touched = !r.contacts.is_empty();
            self.since.insert(
                *k,
                Since {
                    time: tau,
                    deepest,
                    touched,
                },
            );
        }
    }

    /// Wakes what the impact group touches at τ, solves their contacts
    /// there and re-integrates them to the step's end; returns the bodies
    /// it moved (sorted).
    fn solve_at_impact(
        &mut self,
        g: &mut Region,
        exec: &mut dyn Executor,
        impact: &Impact,
        own: &[usize],
        world_event: (PairKey, f64),
    ) -> Result<Vec<usize>, NumericalFailure> {
        let (h, t0, tau) = (self.h, self.t0, impact.tau);
        let rolled: Vec<usize> = impact.states.iter().map(|&(i, _)| i).collect();
        let touching_now = g.touching_from(&impact.pairs, &impact.at_tau);
        let woken = g.wake_touched(&touching_now, &mut self.seg, tau, t0);
        let mut members = rolled;
        members.extend(woken);
        members.sort_unstable();
        members.dedup();
        for &i in members.iter().chain(own) {
            self.left[i] = true;
            self.last_of[i] = Some(world_event);
        }
        let solved = g.contact_phase(exec, &touching_now, &members, &mut self.seg, h - tau);
        self.solved_together.record(&solved);
        self.spin_resolves.schedule(&solved, &members, tau, h);
        if self.keep_paths {
            for &i in &members {
                self.paths[i].push(self.seg[i]);
            }
        }
        check_states(
            members
                .iter()
                .map(|&i| (g.ids[i] as usize, &self.seg[i].state)),
            "solve_islands",
            t0 + tau,
        )?;
        self.separating
            .extend(g.separating_pairs(&touching_now, &self.seg));
        g.impacts.extend(touching_now);
        for &i in &members {
            self.end[i] = g.integrate_segment(i, &self.seg[i], h - tau);
        }
        g.counters.integrations += members.len() as u64;
        Ok(members)
    }

    /// The members' new paths may reach new bodies of the group: their
    /// pairs are found and tested again; every other pair stands. Returns
    /// the pairs tested.
    fn retest_moved(
        &mut self,
        g: &mut Region,
        exec: &mut dyn Executor,
        members: &[usize],
    ) -> Vec<PairKey> {
        let broadphase = g.stage.start(Stage::Broadphase);
        for &i in members {
            self.book.forget(i);
            self.book.sweep(g, i, &self.seg, &self.end);
        }
        let redo = self.book.candidates(g, members);
        g.counters.candidate_pairs += redo.len() as u64;
        g.stage.stop(broadphase);
        let redone = g.narrowphase_skipping_separating(exec, &redo, &self.end, &self.separating);
        for (&k, r) in redo.iter().zip(redone) {
            self.book.insert(k, r);
        }
        redo
    }

    /// The group's output once no event is left: the region's state moves
    /// into it, with the paths and pieces the bodies took.
    fn finish(mut self, g: &mut Region) -> GroupOutput {
        for i in 0..self.left.len() {
            if self.left[i] {
                self.pieces.record(g, i, &self.seg[i].state, &self.end[i]);
            }
        }
        g.counters.toi_events += self.events as u64;
        let book = self.book;
        g.count_speculative_ghosts(|(a, b)| {
            book.results
                .get(&(a.0, b.0))
                .is_some_and(|r| !r.contacts.is_empty())
        });
        g.stage.stop(self.timer);
        let (pairs, results) = book.results.into_iter().unzip();
        let left = self.left;
        let mut paths = self.paths;
        let paths = (0..paths.len())
            .filter(|&i| left[i])
            .map(|i| (g.ids[i], std::mem::take(&mut paths[i])))
            .collect();
        use std::mem::take;
        GroupOutput {
            paths,
            ids: take(&mut g.ids),
            bodies: take(g.bodies),
            sleep_timer: take(g.sleep_timer),
            end: self.end,
            pairs,
            results,
            warm: take(g.warm).into_iter().collect(),
            impacts: take(g.impacts),
            pair_forces: take(&mut g.gathered.pair_forces).into_iter().collect(),
            counters: take(g.counters),
            stage: take(g.stage),
            events: self.events as u64,
            pieces: self.pieces.pieces,
            busy_s: 0.0,
            prepared_tasks: self.prepared_tasks,
            event_loop: self.deps.seconds(),
        }
    }
}

/// How fast a pair approaches at its impact: the fastest closing speed of
/// its contact points at τ (`states` are the rolled-back bodies' states
/// there; a body not among them keeps its segment's), zero if none closes.
fn approach_speed(
    g: &Region,
    pair: PairKey,
    states: &[(usize, BodyState)],
    pairs: &[PairKey],
    results: &[PairResult],
    seg: &[Segment],
) -> f64 {
    let state_of = |i: usize| {
        states
            .iter()
            .find(|(j, _)| *j == i)
            .map_or(seg[i].state, |(_, s)| *s)
    };
    let velocity_at = |i: usize, p: &Vector3<f64>| g.point_velocity(i, &state_of(i), p);
    let Some(k) = pairs.iter().position(|&q| q == pair) else {
        return 0.0;
    };
    let (a, b) = (pair.0 as usize, pair.1 as usize);
    results[k]
        .contacts
        .iter()
        .map(|c| {
            -c.normal
                .dot(&(velocity_at(a, &c.point) - velocity_at(b, &c.point)))
        })
        .fold(0.0, f64::max)
}

/// The band of `Counters::toi_events_by_approach` an approach falls in.
fn approach_band(speed: f64, settings: &crate::scene::Settings) -> usize {
    if speed < settings.restitution_threshold() {
        0
    } else if speed < 0.2 {
        1
    } else if speed < 1.0 {
        2
    } else {
        3
    }
}
