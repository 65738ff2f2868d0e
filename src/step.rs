//! The world step: SPEC 2.1's frame loop, stage by stage.
//!
//! ```text
//! build_islands   contacts touching now → systems (islands), sorted by lowest body id
//! solve_islands   impact impulses + resting/friction forces per island (Dantzig LCP)
//! integrate       every awake body to the end of the step (constant force)
//! broadphase      swept bounding spheres → candidate pairs
//! narrowphase     V-Clip on candidate pairs at the end of the step → contacts, overlaps
//! time_of_impact  an overlap rolls back only the bodies that can reach each other
//!                 (a connected group of swept spheres) to the touching instant found
//!                 by bisection, solves the impact there and re-integrates the group
//! publish_frame   (caller) trajectory sample, render poses
//! ```
//!
//! The pure work (V-Clip on pairs, LCP on islands) goes through an
//! `Executor`: inline on one rank, or scattered over MPI ranks by `cluster`.
//! Results come back in task order, so the outcome never depends on which
//! rank did what.

use crate::body::{Activity, Body, BodyId, BodyKind, BodyState, ObjectDef};
use crate::collision::broadphase::{self, SphereProxy};
use crate::collision::manifold::{ContactPoint, NormalTurn};
use crate::collision::narrowphase::{
    self, CONTACT_TOLERANCE, CachedFeatures, PairResult, PairTask,
};
use crate::contact::island;
use crate::contact::solver::{
    self, IslandBody, IslandContact, IslandResult, IslandTask, SolveStats,
};
use crate::dynamics::integrate::integrate;
use crate::output::summary::{Distribution, RankSummary};
use crate::scene::Scene;
use nalgebra::{Isometry3, Point3, Vector3};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::time::Instant;

/// Runs the distributable stages. One rank: `Inline`; several: `cluster`.
pub trait Executor {
    fn narrowphase(&mut self, objects: &[ObjectDef], tasks: Vec<PairTask>) -> Vec<PairResult>;
    fn solve_islands(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult>;
    /// Ends the run on every rank; returns the per-rank accounts and how often
    /// each stage was distributed.
    fn finish(&mut self) -> (Vec<RankSummary>, Distribution);
}

/// Runs every stage on this rank.
#[derive(Default)]
pub struct Inline {
    busy_s: f64,
    narrowphase_tasks: u64,
    island_tasks: u64,
    dist: Distribution,
}

impl Executor for Inline {
    fn narrowphase(&mut self, objects: &[ObjectDef], tasks: Vec<PairTask>) -> Vec<PairResult> {
        let clock = Instant::now();
        self.narrowphase_tasks += tasks.len() as u64;
        self.dist.narrowphase_local += 1;
        let r = tasks
            .iter()
            .map(|t| narrowphase::query_pair(objects, t))
            .collect();
        self.busy_s += clock.elapsed().as_secs_f64();
        r
    }
    fn solve_islands(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
        let clock = Instant::now();
        self.island_tasks += tasks.len() as u64;
        self.dist.solve_local += 1;
        let r = tasks.iter().map(solver::solve_island).collect();
        self.busy_s += clock.elapsed().as_secs_f64();
        r
    }
    fn finish(&mut self) -> (Vec<RankSummary>, Distribution) {
        let me = RankSummary {
            rank: 0,
            role: "coordinator".into(),
            busy_s: self.busy_s,
            tasks: self.narrowphase_tasks + self.island_tasks,
            narrowphase_tasks: self.narrowphase_tasks,
            island_tasks: self.island_tasks,
            speed: 1.0,
            ..Default::default()
        };
        (vec![me], self.dist.clone())
    }
}

/// What one contact solve leaves for the rest of the step.
struct Solved {
    /// Bodies solved together, per island of two or more (`SolvedTogether`).
    together: Vec<Vec<usize>>,
    /// Per island whose solve holds a resting force: its fastest-spinning
    /// body and that body's spin (rad/s), for `SPIN_TRUST`.
    spinning: Vec<(usize, f64)>,
}

/// When each island that holds a resting force while a body in it spins is
/// solved again (`SPIN_TRUST`), keyed by that body: (time in the step, body).
#[derive(Default)]
struct SpinResolves(Vec<(f64, usize)>);

impl SpinResolves {
    /// Schedules the islands of a solve at `tau` that will turn past
    /// `SPIN_TRUST` before the step's end `h`; first drops what was due for
    /// the bodies just solved (`members`, sorted), whose forces are new.
    fn schedule(&mut self, solved: &Solved, members: &[usize], tau: f64, h: f64) {
        self.0.retain(|(_, i)| members.binary_search(i).is_err());
        for &(i, spin) in &solved.spinning {
            let at = tau + (SPIN_TRUST / spin).max(h / MAX_SPIN_RESOLVES_PER_STEP);
            // The last tenth of a shortest interval is not worth a solve.
            if at < h * (1.0 - 0.1 / MAX_SPIN_RESOLVES_PER_STEP) {
                self.0.push((at, i));
            }
        }
    }

    /// Drops what was due for body `i` (its island is being solved now).
    fn take(&mut self, i: usize) {
        self.0.retain(|&(_, j)| j != i);
    }

    /// The earliest due, if any: (time, body).
    fn next(&self) -> Option<(f64, usize)> {
        self.0
            .iter()
            .copied()
            .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
    }
}

/// Which bodies got their segment's forces from one contact solve (an
/// island of two or more moving bodies), as of the latest solve of each.
struct SolvedTogether {
    island: Vec<usize>,
    members: Vec<Vec<usize>>,
}

impl SolvedTogether {
    fn new(n: usize) -> Self {
        SolvedTogether {
            island: vec![usize::MAX; n],
            members: Vec::new(),
        }
    }

    fn record(&mut self, solved: &Solved) {
        for bodies in solved.together.iter().cloned() {
            for &i in &bodies {
                self.island[i] = self.members.len();
            }
            self.members.push(bodies);
        }
    }

    /// The bodies solved with `i` in its latest solve (itself included).
    fn partners(&self, i: usize) -> &[usize] {
        self.members
            .get(self.island[i])
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }
}

/// Resting-system thresholds: a system whose bodies all stay this slow for
/// `sleep_after` seconds stops being integrated, tested and solved.
pub const SLEEP_LINEAR: f64 = 5e-3;
pub const SLEEP_ANGULAR: f64 = 5e-2;
/// Angle (radians) a body may turn on the constant forces of one contact
/// solve before its island is solved again. The resting solve predicts each
/// contact's motion to second order (Baraff's curvature term); what it
/// leaves is of third order in ω·h, and for fast spinners that is not
/// small: a prism spinning at 30 rad/s on one corner had its gap curving in
/// at 175 m/s², and the force that held it, kept for the whole 10 ms step
/// while the corner swung off the floor, added 4.85 J in one step (2.6e-3 of
/// the scene's energy scale); a 0.1 kg box spinning at 8 rad/s on a tipping
/// hull sank 7.5 µm in the 8 ms after its contact was solved. At 0.05 rad
/// the third-order slip is about r·θ³/6, 2 µm on a 0.1 m lever.
pub const SPIN_TRUST: f64 = 0.05;
/// At most this many such re-solves of one island in a step (the shortest
/// interval between two is dt divided by this).
pub const MAX_SPIN_RESOLVES_PER_STEP: f64 = 8.0;
/// Time-of-impact bisection stops once the gap is below this (metres).
pub const TOI_GAP: f64 = 0.01 * CONTACT_TOLERANCE;
/// Near the contact tolerance a point may sink only this much past what it
/// carried before its impact is placed (`allowed_depth`), so a pair that
/// closes again after every impact ratchets past the tolerance 10× slower
/// than by `TOI_GAP`.
pub const RATCHET_GAP: f64 = 0.1 * TOI_GAP;

/// How deep a contact point that was `carried` deep when its pair was last
/// solved may be before an impact is placed: `TOI_GAP` deeper, but not past
/// `CONTACT_TOLERANCE − RATCHET_GAP` unless it already was, and never less
/// than `RATCHET_GAP` deeper (each event must make progress). Before
/// session 9 every point had its `TOI_GAP`: a pair starting a step 9.95 µm
/// deep ended it at 10.05 µm unseen, and one that closed again after each
/// impact ratcheted 0.1 µm per event (fragile 1 in docs/stability.md: 9 of
/// 1200 sweep scenes ended up to 0.14 µm past the tolerance).
fn allowed_depth(carried: f64) -> f64 {
    let ceiling = CONTACT_TOLERANCE - RATCHET_GAP;
    carried + (ceiling - carried).clamp(RATCHET_GAP, TOI_GAP)
}

/// Impact events a step may take before it accepts the overlaps left: at
/// least `MIN_EVENTS_PER_STEP`, and `EVENTS_PER_MOVING_BODY` for each moving
/// body. An event re-solves one contact island, so its cost does not grow
/// with the scene, while the number of impacts in a step does: 1000 nuts
/// and bolts landing take up to 733 events in a step, and the old fixed
/// budget of 256 left 4644 overlaps up to 4.6 cm deep in the first 0.6 s.
pub const MIN_EVENTS_PER_STEP: usize = 256;
pub const EVENTS_PER_MOVING_BODY: usize = 4;
/// How many times an impact may give way to an earlier one found in its
/// group (`World::earlier_impact`) before it is taken as it is.
const MAX_EARLIER_IMPACTS: usize = 8;

/// Wall seconds per stage (summary's `stage_seconds`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct StageSeconds {
    pub integrate: f64,
    pub broadphase: f64,
    pub narrowphase: f64,
    pub time_of_impact: f64,
    pub build_islands: f64,
    pub solve_islands: f64,
    pub communication: f64,
    pub render: f64,
}

impl StageSeconds {
    /// Stages that time-of-impact handling calls into.
    fn nested(&self) -> f64 {
        self.broadphase + self.narrowphase + self.build_islands + self.solve_islands
    }
}

/// What the simulator did and what it skipped, counted over the run.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Counters {
    pub steps: u64,
    pub integrations: u64,
    pub integrations_skipped_resting: u64,
    pub candidate_pairs: u64,
    pub pair_tests: u64,
    /// Candidate pairs not tested because neither body moves (two fixed
    /// bodies, two bodies of a resting system, a fixed and a resting body).
    pub pairs_skipped_resting: u64,
    /// End-of-step pair tests skipped (SPEC 2.6): pairs that touched at the
    /// step's start, were separating after its contact solve, and are proven
    /// apart by more than the contact tolerance along their old normal.
    pub pairs_skipped_separating: u64,
    pub vclip_iterations: u64,
    pub toi_events: u64,
    pub toi_bisection_queries: u64,
    /// Impacts found at another impact's instant, in a pair that had begun
    /// to overlap before it unseen (see `World::earlier_impact`).
    pub toi_missed_overlaps: u64,
    /// Contact islands solved again because a body in them turned by
    /// `SPIN_TRUST` on the forces of their last solve (`World::step`).
    pub spin_resolves: u64,
    pub max_events_in_step: u64,
    pub steps_with_events: u64,
    pub overlaps_accepted: u64,
    pub islands: u64,
    pub contacts: u64,
    pub solve: SolveStats,
    pub bodies_fallen: u64,
    pub wakes: u64,
}

#[derive(Debug, Clone)]
pub struct NumericalFailure {
    pub body: BodyId,
    pub stage: &'static str,
    pub time: f64,
    pub detail: String,
}

impl std::fmt::Display for NumericalFailure {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(
            f,
            "numerical failure at t = {:.6} s in stage {}: body {} {}",
            self.time, self.stage, self.body.0, self.detail
        )
    }
}

/// Contacts of one touching body pair at the current time.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Touching {
    pub(crate) a: BodyId,
    pub(crate) b: BodyId,
    pub(crate) points: Vec<ContactPoint>,
}

/// The resting force one contact point held in the last solve of its pair:
/// where (in A's body frame) and how much. The next solve of the pair starts
/// its iterative solve from these (`IslandContact::warm_force`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct WarmContact {
    pub(crate) local: Vector3<f64>,
    pub(crate) normal: f64,
    pub(crate) friction: Vector3<f64>,
}

/// A contact point of an island task: its body pair and where it is in A's
/// body frame (the key its resting force is kept under for the warm start).
type ContactWhere = ((BodyId, BodyId), Vector3<f64>);

/// A point of a new contact takes the warm start of the nearest point of the
/// pair's last solve within this share of A's outer radius (resting
/// contacts move by far less than this in a step; a point farther away is a
/// new one and starts from zero).
const WARM_MATCH: f64 = 0.05;

/// The simulated world: static scene data plus the changing state.
pub struct World {
    pub scene: Scene,
    pub bodies: Vec<Body>,
    /// Completed steps; time = steps × dt exactly (no accumulated rounding).
    pub steps: u64,
    pub stage: StageSeconds,
    pub counters: Counters,
    /// Largest overlap seen at the end of any step, metres.
    pub max_penetration: f64,
    /// Enables resting systems (on by default; analytic tests may switch it off).
    pub sleep_enabled: bool,
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
    pub(crate) touching: Vec<Touching>,
    /// Contacts of the impacts solved during the last step, for the
    /// separating-pair skip (only an optimisation: not checkpointed).
    impacts: Vec<Touching>,
    pub(crate) features: HashMap<(u32, u32), Vec<CachedFeatures>>,
    pub(crate) sleep_timer: Vec<f64>,
    /// Resting system a sleeping body belongs to (its lowest body id).
    pub(crate) sleep_group: Vec<u32>,
    /// Total resting normal force of the last contact solve, and the force
    /// on each touching body pair (a, b, newtons), for tests and diagnostics.
    pub last_normal_force_sum: f64,
    pub last_pair_forces: Vec<(BodyId, BodyId, f64)>,
    /// Resting forces of the last solve of each touching pair (warm start).
    pub(crate) warm: BTreeMap<(BodyId, BodyId), Vec<WarmContact>>,
}

/// A body's motion over the current step: start state at `time` (seconds into
/// the step) with constant force and torque until the end of the step.
#[derive(Clone, Copy)]
struct Segment {
    state: BodyState,
    time: f64,
    force: Vector3<f64>,
    torque: Vector3<f64>,
}

/// When each pair's contacts were last solved (the step's start, or an
/// impact's τ, seconds into the step) and its deepest overlap then: an
/// overlap its points already had then is carried, not new
/// (`World::sinking`). Pairs not listed carried none.
type SolvedSince = HashMap<(u32, u32), Since>;

#[derive(Clone, Copy)]
struct Since {
    time: f64,
    deepest: f64,
}

/// A body state's pose, as narrowphase takes it.
fn pose(s: &BodyState) -> Isometry3<f64> {
    Isometry3::from_parts(s.position.into(), s.orientation)
}

impl World {
    pub fn new(scene: Scene) -> World {
        let n = scene.bodies.len();
        let bodies = scene.bodies.clone();
        World {
            scene,
            bodies,
            steps: 0,
            stage: StageSeconds::default(),
            counters: Counters::default(),
            max_penetration: 0.0,
            sleep_enabled: true,
            sleep_after: 0.5,
            skip_separating: true,
            warm_start: true,
            iterative_min_rows: solver::ITERATIVE_MIN_ROWS,
            touching: Vec::new(),
            impacts: Vec::new(),
            features: HashMap::new(),
            sleep_timer: vec![0.0; n],
            sleep_group: (0..n as u32).collect(),
            last_normal_force_sum: 0.0,
            last_pair_forces: Vec::new(),
            warm: BTreeMap::new(),
        }
    }

    pub fn time(&self) -> f64 {
        self.steps as f64 * self.scene.settings.dt
    }

    pub fn object(&self, body: usize) -> &ObjectDef {
        &self.scene.objects[self.bodies[body].object.0 as usize]
    }

    /// Kinetic plus gravitational potential energy of the dynamic bodies still simulated.
    pub fn energy(&self) -> f64 {
        let g = self.scene.settings.gravity;
        self.bodies
            .iter()
            .filter(|b| b.is_dynamic() && b.activity != Activity::Fallen)
            .map(|b| {
                let o = &self.scene.objects[b.object.0 as usize];
                b.kinetic_energy(o) - o.mass * g.dot(&b.state.position)
            })
            .sum()
    }

    /// True when every dynamic body rests or has fallen off.
    pub fn at_rest(&self) -> bool {
        self.bodies.iter().all(|b| match b.kind {
            BodyKind::Dynamic => b.activity != Activity::Awake,
            BodyKind::Fixed => true,
            BodyKind::Driven {
                velocity,
                angular_velocity,
            } => velocity == Vector3::zeros() && angular_velocity == Vector3::zeros(),
        })
    }

    fn moving(&self, i: usize) -> bool {
        let b = &self.bodies[i];
        b.activity == Activity::Awake && !matches!(b.kind, BodyKind::Fixed)
    }

    fn external(&self, i: usize, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let o = self.object(i);
        let mut f = o.mass * self.scene.settings.gravity;
        let mut tau = Vector3::zeros();
        for w in &self.scene.forces {
            if w.body.index() == i && w.start <= t && t < w.end {
                f += w.force;
                tau += w.torque;
            }
        }
        (f, tau)
    }

    /// Advances the world by one step of `dt`.
    pub fn step(&mut self, exec: &mut dyn Executor) -> Result<(), NumericalFailure> {
        let h = self.scene.settings.dt;
        let t0 = self.time();
        let n = self.bodies.len();
        self.wake_for_forces(t0, h);

        // External forces at the start of the step (constant over it).
        let mut seg: Vec<Segment> = (0..n)
            .map(|i| {
                let (force, torque) = if self.bodies[i].is_dynamic() && self.moving(i) {
                    self.external(i, t0)
                } else {
                    (Vector3::zeros(), Vector3::zeros())
                };
                Segment {
                    state: self.bodies[i].state,
                    time: 0.0,
                    force,
                    torque,
                }
            })
            .collect();

        // Contacts touching at the very start (bodies placed in contact).
        if self.steps == 0 && self.touching.is_empty() {
            let now: Vec<BodyState> = seg.iter().map(|s| s.state).collect();
            let pairs = self.broadphase(&seg, &now);
            let results = self.narrowphase_at(exec, &pairs, &now);
            self.touching = self.touching_from(&pairs, &results);
        }

        // build_islands + solve_islands on the contacts touching now.
        let touching = std::mem::take(&mut self.touching);
        let mut since: SolvedSince = touching
            .iter()
            .map(|t| {
                let deepest = t.points.iter().map(|p| -p.separation).fold(0.0, f64::max);
                ((t.a.0, t.b.0), Since { time: 0.0, deepest })
            })
            .collect();
        let all_moving: Vec<usize> = (0..n).filter(|&i| self.moving(i)).collect();
        let mut solved_together = SolvedTogether::new(n);
        let solved = self.contact_phase(exec, &touching, &all_moving, &mut seg, h);
        solved_together.record(&solved);
        let mut spin_resolves = SpinResolves::default();
        spin_resolves.schedule(&solved, &all_moving, 0.0, h);
        self.check_states(
            seg.iter().map(|s| &s.state).enumerate(),
            "solve_islands",
            t0,
        )?;
        // Pairs touching now or hit during the last step ("colliding in the
        // previous frame") that now separate.
        let previous_impacts = std::mem::take(&mut self.impacts);
        let mut separating = self.separating_pairs(&previous_impacts, &seg);
        separating.extend(self.separating_pairs(&touching, &seg));

        // integrate
        let clock = Instant::now();
        let mut end: Vec<BodyState> = seg.iter().map(|s| s.state).collect();
        for &i in &all_moving {
            end[i] = self.integrate_segment(i, &seg[i], h);
        }
        self.counters.integrations += all_moving.len() as u64;
        self.counters.integrations_skipped_resting += (0..n)
            .filter(|&i| self.bodies[i].activity == Activity::Sleeping)
            .count() as u64;
        self.stage.integrate += clock.elapsed().as_secs_f64();

        // broadphase + narrowphase at the end of the step.
        let mut pairs = self.broadphase(&seg, &end);
        let mut results = self.narrowphase_skipping_separating(exec, &pairs, &end, &separating);

        // time_of_impact: roll back the groups that overlap. Its stage time is
        // the loop's wall time less the stages it calls (counted under theirs).
        let clock = Instant::now();
        let nested_before = self.stage.nested();
        let mut events = 0usize;
        let mut accepted: Vec<(u32, u32)> = Vec::new();
        let mut last_event: Option<((u32, u32), f64)> = None;
        let mut toi_cache: HashMap<(u32, u32), Option<f64>> = HashMap::new();
        let budget = MIN_EVENTS_PER_STEP.max(EVENTS_PER_MOVING_BODY * all_moving.len());
        loop {
            let violation =
                self.earliest_impact(&pairs, &results, &seg, h, &accepted, &mut toi_cache, &since);
            // An island due to be solved again (`SPIN_TRUST`) before the
            // next impact is an event of its own: its fastest spinner's group
            // rolls back and is solved as at an impact. Not before the latest
            // event, where that event's group starts its segments.
            let due = spin_resolves
                .next()
                .map(|(at, i)| (at.max(last_event.map_or(0.0, |(_, t)| t)), i))
                .filter(|&(at, _)| violation.is_none_or(|(_, t)| at < t));
            let spin_resolve = due.is_some();
            let Some((mut pair, mut tau)) =
                due.map(|(at, i)| ((i as u32, i as u32), at)).or(violation)
            else {
                break;
            };
            if spin_resolve {
                spin_resolves.take(pair.0 as usize);
            } else if events >= budget {
                // Out of events: keep the small overlap rather than stall the step.
                accepted.push(pair);
                self.counters.overlaps_accepted += 1;
                continue;
            }
            let (mut group_states, mut group_pairs, mut at_tau) =
                self.impact_group(exec, pair, tau, &pairs, &seg, &solved_together);
            // An overlap beyond what a pair carried, found at τ in another
            // pair of the group, began before τ unseen: the end-of-step test
            // misses a body that dips into another and is out again by the
            // end (a 0.1 kg box bouncing at 5 m/s between a wall and a
            // hull went 1.3 mm into the hull). Its own impact comes first.
            for _ in 0..MAX_EARLIER_IMPACTS {
                let Some(earlier) = self.earlier_impact(
                    pair,
                    tau,
                    (&group_pairs, &at_tau),
                    &seg,
                    &since,
                    &accepted,
                ) else {
                    break;
                };
                (pair, tau) = earlier;
                self.counters.toi_missed_overlaps += 1;
                (group_states, group_pairs, at_tau) =
                    self.impact_group(exec, pair, tau, &pairs, &seg, &solved_together);
            }
            if last_event == Some((pair, tau)) {
                // No progress: keep the small overlap rather than stall the step.
                accepted.push(pair);
                self.counters.overlaps_accepted += 1;
                continue;
            }
            last_event = Some((pair, tau));
            if spin_resolve && pair.0 == pair.1 {
                self.counters.spin_resolves += 1;
            } else {
                events += 1;
            }
            let group: Vec<usize> = group_states.iter().map(|&(i, _)| i).collect();
            // Roll the group back to τ.
            for &(i, state) in &group_states {
                seg[i].state = state;
                seg[i].time = tau;
                end[i] = state;
                if self.bodies[i].is_dynamic() {
                    let (f, t) = self.external(i, t0 + tau);
                    seg[i].force = f;
                    seg[i].torque = t;
                }
            }
            for (k, r) in group_pairs.iter().zip(&at_tau) {
                let deepest = if r.penetrating { r.depth } else { 0.0 };
                since.insert(*k, Since { time: tau, deepest });
            }
            let touching_now = self.touching_from(&group_pairs, &at_tau);
            let woken = self.wake_touched(&touching_now, &mut seg, tau, t0);
            let mut members = group.clone();
            members.extend(woken);
            members.sort_unstable();
            members.dedup();
            let mut is_member = vec![false; n];
            for &i in &members {
                is_member[i] = true;
            }
            let solved = self.contact_phase(exec, &touching_now, &members, &mut seg, h - tau);
            solved_together.record(&solved);
            spin_resolves.schedule(&solved, &members, tau, h);
            self.check_states(
                members.iter().map(|&i| (i, &seg[i].state)),
                "solve_islands",
                t0 + tau,
            )?;
            separating.extend(self.separating_pairs(&touching_now, &seg));
            self.impacts.extend(touching_now);
            for &i in &members {
                end[i] = self.integrate_segment(i, &seg[i], h - tau);
            }
            self.counters.integrations += members.len() as u64;
            toi_cache.retain(|&(a, b), _| !is_member[a as usize] && !is_member[b as usize]);
            // The group's new paths may reach new bodies: redo the broadphase
            // for its members, and the narrowphase for the pairs that involve them.
            let new_pairs = self.broadphase_after_event(&seg, &end, &pairs, &is_member);
            let mut old: HashMap<(u32, u32), PairResult> =
                pairs.iter().copied().zip(results).collect();
            let redo: Vec<(u32, u32)> = new_pairs
                .iter()
                .copied()
                .filter(|&(a, b)| {
                    is_member[a as usize] || is_member[b as usize] || !old.contains_key(&(a, b))
                })
                .collect();
            let redone = self.narrowphase_skipping_separating(exec, &redo, &end, &separating);
            let mut fresh: HashMap<(u32, u32), PairResult> = redo.into_iter().zip(redone).collect();
            results = new_pairs
                .iter()
                .map(|k| {
                    fresh
                        .remove(k)
                        .or_else(|| old.remove(k))
                        .unwrap_or_default()
                })
                .collect();
            pairs = new_pairs;
        }
        self.counters.toi_events += events as u64;
        self.counters.max_events_in_step = self.counters.max_events_in_step.max(events as u64);
        if events > 0 {
            self.counters.steps_with_events += 1;
        }
        self.stage.time_of_impact +=
            clock.elapsed().as_secs_f64() - (self.stage.nested() - nested_before);

        // Commit the end states.
        for i in 0..n {
            if self.bodies[i].activity == Activity::Awake {
                self.bodies[i].state = end[i];
            }
        }
        for (k, r) in pairs.iter().zip(&results) {
            self.max_penetration = self.max_penetration.max(r.depth);
            if !r.features.is_empty() {
                self.features.insert(*k, r.features.clone());
            }
        }
        self.touching = self.touching_from(&pairs, &results);
        let touching: BTreeSet<(BodyId, BodyId)> =
            self.touching.iter().map(|t| (t.a, t.b)).collect();
        self.warm.retain(|k, _| touching.contains(k));
        self.steps += 1;
        self.counters.steps += 1;
        self.check_states(
            self.bodies.iter().map(|b| &b.state).enumerate(),
            "integrate",
            t0 + h,
        )?;
        self.wake_touched_at_end();
        self.update_rest_and_falls(h);
        Ok(())
    }

    fn integrate_segment(&self, i: usize, s: &Segment, h: f64) -> BodyState {
        let b = &self.bodies[i];
        integrate(&s.state, self.object(i), b.kind, &s.force, &s.torque, h)
    }

    /// Candidate pairs from spheres swept between each body's segment start and
    /// its end state (fast bodies cannot skip a pair this way).
    fn broadphase(&mut self, seg: &[Segment], end: &[BodyState]) -> Vec<(u32, u32)> {
        let clock = Instant::now();
        let proxies = self.swept_spheres(seg, end);
        let resting = std::cell::Cell::new(0u64);
        let pairs = broadphase::candidate_pairs(&proxies, |a, b| {
            let keep = self.needs_test(a, b);
            resting.set(resting.get() + u64::from(!keep));
            keep
        });
        self.counters.candidate_pairs += pairs.len() as u64;
        self.counters.pairs_skipped_resting += resting.get();
        self.stage.broadphase += clock.elapsed().as_secs_f64();
        pairs
    }

    /// The broadphase after an impact event moved only the bodies marked in
    /// `changed`: pairs among the others stand, so only the changed bodies'
    /// spheres are tested (same result as `broadphase`, without the sort).
    fn broadphase_after_event(
        &mut self,
        seg: &[Segment],
        end: &[BodyState],
        previous: &[(u32, u32)],
        changed: &[bool],
    ) -> Vec<(u32, u32)> {
        let clock = Instant::now();
        let proxies = self.swept_spheres(seg, end);
        let pairs =
            broadphase::update_pairs(&proxies, previous, changed, |a, b| self.needs_test(a, b));
        self.counters.candidate_pairs += pairs.len() as u64;
        self.stage.broadphase += clock.elapsed().as_secs_f64();
        pairs
    }

    /// Pairs where neither body moves (two fixed, two resting, …) need no test.
    fn needs_test(&self, a: u32, b: u32) -> bool {
        self.moving(a as usize) || self.moving(b as usize)
    }

    /// Every body's bounding spheres, swept from its segment start to its end
    /// state, grouped by body.
    fn swept_spheres(&self, seg: &[Segment], end: &[BodyState]) -> Vec<SphereProxy> {
        let mut proxies = Vec::new();
        for (i, b) in self.bodies.iter().enumerate() {
            if b.activity == Activity::Fallen {
                continue;
            }
            let o = &self.scene.objects[b.object.0 as usize];
            let (p0, q0) = (seg[i].state.position, seg[i].state.orientation);
            let (p1, q1) = (end[i].position, end[i].orientation);
            let angle = q0.angle_to(&q1);
            for s in &o.spheres {
                let c0 = p0 + q0 * s.center;
                let c1 = p1 + q1 * s.center;
                // The chord from c0 to c1 misses the arc of a rotating offset by
                // at most |offset|·(1 − cos(θ/2)) ≤ |offset|·θ²/8; add it.
                let bulge = s.center.norm() * angle * angle / 8.0;
                proxies.push(SphereProxy {
                    body: i as u32,
                    center: 0.5 * (c0 + c1),
                    radius: s.radius + 0.5 * (c1 - c0).norm() + bulge + CONTACT_TOLERANCE,
                });
            }
        }
        proxies
    }

    /// Of the given touching pairs (at the step's start, or at an impact),
    /// those whose every contact point separates at the velocities in `seg`
    /// (relative normal velocity > 0), with a contact normal (out of b
    /// towards a). SPEC 2.6 does not test such pairs in the next frame; here
    /// they get a cheaper test that can only skip when it proves the pair
    /// apart (`narrowphase_skipping_separating`).
    fn separating_pairs(
        &self,
        touching: &[Touching],
        seg: &[Segment],
    ) -> HashMap<(u32, u32), Vector3<f64>> {
        if !self.skip_separating {
            return HashMap::new();
        }
        let velocity_at = |i: usize, p: &Vector3<f64>| {
            self.body_at(i, seg[i].state)
                .point_velocity(self.object(i), p)
        };
        touching
            .iter()
            .filter(|t| {
                t.points.iter().all(|p| {
                    let v = velocity_at(t.a.index(), &p.point) - velocity_at(t.b.index(), &p.point);
                    p.normal.dot(&v) > 0.0
                })
            })
            .filter_map(|t| Some(((t.a.0, t.b.0), t.points.first()?.normal)))
            .collect()
    }

    /// The end-of-step narrowphase, except for separating pairs whose two
    /// bodies lie on either side of a plane normal to their old contact
    /// normal, further apart than the contact tolerance: such a pair cannot
    /// touch (so V-Clip would give no contacts), and checking every vertex
    /// against one direction costs less than V-Clip over all close part
    /// pairs. The test uses the end poses, so a body that turned while
    /// separating (a corner swinging back) fails it and is tested in full;
    /// fast pairs still get the time-of-impact sampling. Results equal the
    /// full narrowphase's for the simulation's purposes (no contacts, no
    /// overlap); the skipped pair's cached V-Clip features stay as they were.
    fn narrowphase_skipping_separating(
        &mut self,
        exec: &mut dyn Executor,
        pairs: &[(u32, u32)],
        states: &[BodyState],
        separating: &HashMap<(u32, u32), Vector3<f64>>,
    ) -> Vec<PairResult> {
        let clock = Instant::now();
        let skipped: Vec<bool> = pairs
            .iter()
            .map(|&(a, b)| {
                separating.get(&(a, b)).is_some_and(|n| {
                    let (a, b) = (a as usize, b as usize);
                    let side_a = (self.object(a), &pose(&states[a]));
                    let side_b = (self.object(b), &pose(&states[b]));
                    narrowphase::separation_along(side_a, side_b, n) > CONTACT_TOLERANCE
                })
            })
            .collect();
        let tested: Vec<(u32, u32)> = pairs
            .iter()
            .zip(&skipped)
            .filter(|(_, skip)| !**skip)
            .map(|(k, _)| *k)
            .collect();
        let skips = pairs.len() - tested.len();
        self.counters.pairs_skipped_separating += skips as u64;
        self.stage.narrowphase += clock.elapsed().as_secs_f64();
        let mut results = self.narrowphase_at(exec, &tested, states).into_iter();
        skipped
            .iter()
            .map(|&skip| {
                if skip {
                    PairResult {
                        distance: f64::INFINITY,
                        ..Default::default()
                    }
                } else {
                    results.next().unwrap_or_default()
                }
            })
            .collect()
    }

    fn narrowphase_at(
        &mut self,
        exec: &mut dyn Executor,
        pairs: &[(u32, u32)],
        states: &[BodyState],
    ) -> Vec<PairResult> {
        let tasks: Vec<PairTask> = pairs
            .iter()
            .map(|&(a, b)| self.pair_task(a, b, &states[a as usize], &states[b as usize]))
            .collect();
        self.narrowphase_tasks(exec, tasks)
    }

    fn narrowphase_tasks(
        &mut self,
        exec: &mut dyn Executor,
        tasks: Vec<PairTask>,
    ) -> Vec<PairResult> {
        let clock = Instant::now();
        self.counters.pair_tests += tasks.len() as u64;
        let results = exec.narrowphase(&self.scene.objects, tasks);
        for r in &results {
            self.counters.vclip_iterations += r.iterations as u64;
        }
        self.stage.narrowphase += clock.elapsed().as_secs_f64();
        results
    }

    fn pair_task(&self, a: u32, b: u32, sa: &BodyState, sb: &BodyState) -> PairTask {
        PairTask {
            a: BodyId(a),
            b: BodyId(b),
            object_a: self.bodies[a as usize].object.0,
            object_b: self.bodies[b as usize].object.0,
            pose_a: pose(sa),
            pose_b: pose(sb),
            warm: self.features.get(&(a, b)).cloned().unwrap_or_default(),
            contact_tolerance: CONTACT_TOLERANCE,
        }
    }

    fn touching_from(&self, pairs: &[(u32, u32)], results: &[PairResult]) -> Vec<Touching> {
        pairs
            .iter()
            .zip(results)
            .filter(|(_, r)| !r.contacts.is_empty())
            .map(|(&(a, b), r)| Touching {
                a: BodyId(a),
                b: BodyId(b),
                points: r.contacts.clone(),
            })
            .collect()
    }

    /// Finds the earliest time of impact over the overlapping pairs (and over
    /// fast pairs that might pass through each other between samples).
    fn earliest_impact(
        &mut self,
        pairs: &[(u32, u32)],
        results: &[PairResult],
        seg: &[Segment],
        h: f64,
        accepted: &[(u32, u32)],
        cache: &mut HashMap<(u32, u32), Option<f64>>,
        since: &SolvedSince,
    ) -> Option<((u32, u32), f64)> {
        let mut best: Option<((u32, u32), f64)> = None;
        for (k, r) in pairs.iter().zip(results) {
            if accepted.contains(k) {
                continue;
            }
            let tau = match cache.get(k) {
                Some(&cached) => cached,
                None => {
                    let tau = self.time_of_impact(*k, r, seg, h, since);
                    cache.insert(*k, tau);
                    tau
                }
            };
            if let Some(tau) = tau {
                // Earliest first; ties by pair, so the order never depends on iteration.
                if best.is_none_or(|(bk, bt)| tau < bt || (tau == bt && *k < bk)) {
                    best = Some((*k, tau));
                }
            }
        }
        best
    }

    /// Time of impact of one pair in this step, if it overlaps (or a fast
    /// pair crossed) beyond what it carried into its segment.
    fn time_of_impact(
        &mut self,
        k: (u32, u32),
        r: &PairResult,
        seg: &[Segment],
        h: f64,
        since: &SolvedSince,
    ) -> Option<f64> {
        let (a, b) = (k.0 as usize, k.1 as usize);
        let start = seg[a].time.max(seg[b].time);
        let since = since.get(&k).copied();
        let interval = if self.overlaps_more((a, b), r, h, seg, since) {
            Some(
                self.first_overlap_sample(a, b, seg, start, h, since)
                    .unwrap_or((start, h)),
            )
        } else {
            // No overlap at the end: a fast pair may still have crossed.
            self.first_overlap_sample(a, b, seg, start, h, since)
        };
        interval.map(|(lo, hi)| self.bisect(a, b, seg, lo, hi, since))
    }

    /// An overlap that calls for a rollback: beyond the contact tolerance (or
    /// with no contact points to resolve it), with a contact point past the
    /// depth it may reach since the pair was last solved (`sinking`). An overlap
    /// carried in (rounding, or one left by a step that could not resolve
    /// it) is mended by the overlap recovery, not by rolling back to a
    /// moment that has already passed.
    fn overlaps_more(
        &self,
        (a, b): (usize, usize),
        r: &PairResult,
        t: f64,
        seg: &[Segment],
        since: Option<Since>,
    ) -> bool {
        r.needs_rollback(CONTACT_TOLERANCE)
            && (r.contacts.is_empty() || self.sinking((a, b), r, t, seg, since) > 0.0)
    }

    /// How far the pair's deepest-sinking contact point at `t` (result `r`)
    /// is past its `allowed_depth`, of what the same two body points carried
    /// at `since`, when the pair was last solved (positive calls for an
    /// impact); a point apart then carried no overlap, and none
    /// carried more than the pair's deepest point then (the old measure, so
    /// every rollback it called for is still called for). Before
    /// session 7 the pair's deepest overlap then was the measure for every
    /// point, so a new point of a pair already 7 µm deep landed 7 µm deep
    /// unseen: a bolt rolling on the 40-gon rim of its shaft's end, each
    /// rim corner in turn landing so and the overlap recovery lifting it out
    /// again, gained energy and wobbled for 50 s (docs/stability.md,
    /// fragile 6).
    ///
    /// Each point's two body points (A's and B's, at the point at `t`) are
    /// taken back to `since` with their bodies; their gap then, along the
    /// normal turned back with the feature it belongs to (`NormalTurn`), is
    /// the gap at `t` plus n·(x_A − x_B) at `since` (to the overlap times
    /// the turn, 1e-8 m at most).
    fn sinking(
        &self,
        (a, b): (usize, usize),
        r: &PairResult,
        t: f64,
        seg: &[Segment],
        since: Option<Since>,
    ) -> f64 {
        // `r.depth` is already the deepest of the contact points.
        let Some(Since {
            time: t0,
            deepest: carried,
        }) = since
        else {
            return r.depth - allowed_depth(0.0);
        };
        if r.contacts.is_empty() {
            return r.depth - allowed_depth(carried);
        }
        let at = |i: usize, t: f64| self.integrate_segment(i, &seg[i], t - seg[i].time);
        let (sa, sb, sa0, sb0) = (at(a, t), at(b, t), at(a, t0), at(b, t0));
        let back_a = sa0.orientation * sa.orientation.inverse();
        let back_b = sb0.orientation * sb.orientation.inverse();
        r.contacts
            .iter()
            .map(|c| {
                let xa0 = sa0.position + back_a * (c.point - sa.position);
                let xb0 = sb0.position + back_b * (c.point - sb.position);
                let n0 = match c.turns {
                    NormalTurn::WithA => back_a * c.normal,
                    NormalTurn::WithB => back_b * c.normal,
                    NormalTurn::Edges(ea, eb) => {
                        let m = (back_a * ea).cross(&(back_b * eb));
                        let m = m / m.norm();
                        if m.dot(&c.normal) >= 0.0 { m } else { -m }
                    }
                };
                let gap0 = c.separation + n0.dot(&(xa0 - xb0));
                -c.separation - allowed_depth((-gap0).clamp(0.0, carried))
            })
            .fold(r.depth - allowed_depth(carried), f64::max)
    }

    /// For pairs that move by more than their thickness during the step,
    /// samples the path densely enough that one cannot pass through the other
    /// unseen; returns the interval before the first overlapping sample.
    fn first_overlap_sample(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        start: f64,
        h: f64,
        since: Option<Since>,
    ) -> Option<(f64, f64)> {
        // Each body at both ends of the interval: its travel, its swing and
        // the approach-speed bound all come from these four states.
        let ends =
            |i: usize| [start, h].map(|t| self.integrate_segment(i, &seg[i], t - seg[i].time));
        let (ends_a, ends_b) = (ends(a), ends(b));
        // Relative travel of the centres, plus how far each body's corners
        // can swing about its centre: a spinning body whose centre barely
        // moves can still sweep a corner through a thin neighbour (a random
        // scene lost 10 mm that way between two samples of a pair that was
        // never sampled).
        let swing = |i: usize, ends: &[BodyState; 2]| -> f64 {
            ends.iter()
                .map(|s| self.spin_bound(i, s))
                .fold(0.0, f64::max)
                * self.object(i).outer_radius()
        };
        let centres =
            (ends_a[1].position - ends_a[0].position) - (ends_b[1].position - ends_b[0].position);
        let travel = centres.norm() + (swing(a, &ends_a) + swing(b, &ends_b)) * (h - start);
        let thickness = self
            .object(a)
            .min_thickness
            .min(self.object(b).min_thickness);
        if travel <= 0.5 * thickness {
            return None;
        }
        // Samples every half thickness of relative travel, and further where
        // the pair is far apart: from a gap g no point can close it before
        // g / (bound on the approach speed) has passed (conservative
        // advancement), so nothing is skipped there either.
        let samples = ((travel / (0.5 * thickness)).ceil() as usize).min(10_000);
        let spacing = (h - start) / samples as f64;
        let speed = self.approach_speed_bound((a, &ends_a), (b, &ends_b));
        let mut prev = start;
        let mut t = (start + spacing).min(h);
        loop {
            let (r, task) = self.query_task_at(a, b, seg, t);
            if self.overlaps_more((a, b), &r, t, seg, since) {
                return Some((prev, t));
            }
            if t >= h {
                return None;
            }
            // A lower bound on the gap: V-Clip's distance over the part pairs
            // it tested, and for the others the gap between the bodies'
            // enclosing spheres (exact enough where conservative advancement
            // pays: far apart).
            let gap = if r.penetrating {
                0.0
            } else {
                let centres =
                    (task.pose_a.translation.vector - task.pose_b.translation.vector).norm();
                let spheres =
                    centres - self.object(a).outer_radius() - self.object(b).outer_radius();
                r.distance.min(spheres.max(0.0))
            };
            prev = t;
            t = (t + spacing.max(gap / speed)).min(h);
        }
    }

    /// Upper bound of body `i`'s angular speed in state `s`: |L| / I_min
    /// (|ω| itself may peak inside a segment as a body wobbles; |L| cannot).
    fn spin_bound(&self, i: usize, s: &BodyState) -> f64 {
        match self.bodies[i].kind {
            BodyKind::Dynamic => s.angular_momentum.norm() / self.object(i).principal_moments.min(),
            BodyKind::Fixed => 0.0,
            BodyKind::Driven {
                angular_velocity, ..
            } => angular_velocity.norm(),
        }
    }

    /// Upper bound of the speed at which any point of `a` approaches any
    /// point of `b` over an interval, from each body's states at its two
    /// ends: relative linear speed plus each body's largest angular speed
    /// |L| / I_min times its outer radius. With force and torque constant
    /// over a segment, |v| and |L| are convex in time and peak at its ends
    /// (|ω| itself may not, as a body wobbles).
    fn approach_speed_bound(
        &self,
        (a, ends_a): (usize, &[BodyState; 2]),
        (b, ends_b): (usize, &[BodyState; 2]),
    ) -> f64 {
        let reach = |i: usize, s: &BodyState| self.spin_bound(i, s) * self.object(i).outer_radius();
        (0..2)
            .map(|k| {
                let (sa, sb) = (&ends_a[k], &ends_b[k]);
                (sa.velocity - sb.velocity).norm() + reach(a, sa) + reach(b, sb)
            })
            .fold(1e-12, f64::max)
    }

    /// The pair at time `t`, with contact points (their depth tells an
    /// overlap carried into the segment from a new one).
    /// V-Clip alone at time `t`: `None` when the pair overlaps, else its gap.
    fn gap_at(&mut self, a: usize, b: usize, seg: &[Segment], t: f64) -> Option<f64> {
        let sa = self.integrate_segment(a, &seg[a], t - seg[a].time);
        let sb = self.integrate_segment(b, &seg[b], t - seg[b].time);
        self.counters.toi_bisection_queries += 1;
        let task = self.pair_task(a as u32, b as u32, &sa, &sb);
        narrowphase::overlap_probe(&self.scene.objects, &task)
    }

    fn query_at(&mut self, a: usize, b: usize, seg: &[Segment], t: f64) -> PairResult {
        self.query_task_at(a, b, seg, t).0
    }

    fn query_task_at(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        t: f64,
    ) -> (PairResult, PairTask) {
        let sa = self.integrate_segment(a, &seg[a], t - seg[a].time);
        let sb = self.integrate_segment(b, &seg[b], t - seg[b].time);
        self.counters.toi_bisection_queries += 1;
        let task = self.pair_task(a as u32, b as u32, &sa, &sb);
        (narrowphase::query_pair(&self.scene.objects, &task), task)
    }

    /// Bisection for the touching instant (SPEC 2.6, fig. 3.16): `lo` is known
    /// apart (or with no contact point deeper than when the pair was last
    /// solved, `since`), `hi` overlapping deeper. Halves until the interval is what the pair's
    /// relative speed covers in a 0.1 µm gap (`TOI_GAP`), or a separated `lo`
    /// is within that gap. At 4.4 m/s (a 1 m drop) that is 23 ns: impact times
    /// stay well within 1e-6 s over many bounces, for about
    /// log2(v·dt / 0.1 µm) ≈ 19 V-Clip queries per impact.
    ///
    /// When V-Clip finds the pair apart at `lo` by more than `TOI_GAP`, any
    /// overlap is "after the impact", and V-Clip alone decides each half: no
    /// contact points, whose separating-axis search over edge pairs costs
    /// far more than V-Clip (7× the whole bisection on the load profile's
    /// 224-face spheres). The answer is then an instant where the pair is
    /// apart by at most `TOI_GAP`. That pass makes no progress when the
    /// pair, just solved at `lo`, still closes: then, as for a pair
    /// touching or overlapping at `lo`, the depth of the contact points
    /// decides, and a point may sink to its `allowed_depth` (`TOI_GAP`
    /// deeper than it was at `since`, less near the tolerance) before the
    /// impact is placed.
    fn bisect(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        lo: f64,
        hi: f64,
        since: Option<Since>,
    ) -> f64 {
        // Forces are constant over a segment, so speeds peak at its ends.
        let speed = self
            .relative_speed_bound(a, b, seg, lo)
            .max(self.relative_speed_bound(a, b, seg, hi))
            .max(1e-9);
        let resolution = (TOI_GAP / speed).max(1e-13 * self.scene.settings.dt);
        // Only for a pair clearly apart at `lo`. One touching there (V-Clip's
        // verdict flipping at rounding level as a body slides along a wall)
        // got impacts 0.15 µs apart, each at the first instant V-Clip called
        // it apart, until the step's 256 events ran out; its real sinking
        // 2.5 ms later was never reached (random sweep seed 4, scene 89).
        if self.gap_at(a, b, seg, lo).is_some_and(|gap| gap > TOI_GAP) {
            let tau = self.bisect_apart(a, b, seg, lo, hi, resolution);
            if tau > lo {
                return tau;
            }
        }
        self.bisect_depth(a, b, seg, lo, hi, since, resolution)
    }

    /// Bisection on "does V-Clip find an overlap"; `lo` is apart.
    fn bisect_apart(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        mut lo: f64,
        mut hi: f64,
        resolution: f64,
    ) -> f64 {
        while hi - lo > resolution {
            let mid = 0.5 * (lo + hi);
            match self.gap_at(a, b, seg, mid) {
                None => hi = mid,
                Some(gap) => {
                    lo = mid;
                    if gap <= TOI_GAP {
                        break;
                    }
                }
            }
        }
        lo
    }

    /// Bisection on "has a contact point sunk past its allowed depth since
    /// `since`" (`sinking`).
    #[allow(clippy::too_many_arguments)]
    fn bisect_depth(
        &mut self,
        a: usize,
        b: usize,
        seg: &[Segment],
        mut lo: f64,
        mut hi: f64,
        since: Option<Since>,
        resolution: f64,
    ) -> f64 {
        for _ in 0..64 {
            if hi - lo <= resolution {
                break;
            }
            let mid = 0.5 * (lo + hi);
            let r = self.query_at(a, b, seg, mid);
            // `overlaps_more`, or a point sunk past its allowed depth within
            // the tolerance: together, one `sinking` call.
            if r.penetrating
                && (r.contacts.is_empty() || self.sinking((a, b), &r, mid, seg, since) > 0.0)
            {
                hi = mid;
            } else {
                lo = mid;
                if !r.penetrating && r.distance <= TOI_GAP {
                    break;
                }
            }
        }
        lo
    }

    /// The earliest impact before `tau` of a pair of the group found
    /// overlapping at τ beyond what it carried into its segment (the pair
    /// `chosen` and the pairs accepted in this step aside), by bisection
    /// from its segment's start.
    fn earlier_impact(
        &mut self,
        chosen: (u32, u32),
        tau: f64,
        (group_pairs, at_tau): (&[(u32, u32)], &[PairResult]),
        seg: &[Segment],
        since: &SolvedSince,
        accepted: &[(u32, u32)],
    ) -> Option<((u32, u32), f64)> {
        let mut best: Option<((u32, u32), f64)> = None;
        for (&k, r) in group_pairs.iter().zip(at_tau) {
            let (a, b) = (k.0 as usize, k.1 as usize);
            let since = since.get(&k).copied();
            // An accepted pair made no progress at its own impact: asking
            // for it again would stall the step (the pair it was found
            // through would bring it back forever).
            if k == chosen
                || accepted.contains(&k)
                || !self.overlaps_more((a, b), r, tau, seg, since)
            {
                continue;
            }
            let start = seg[a].time.max(seg[b].time);
            if start >= tau {
                continue;
            }
            let t = self.bisect(a, b, seg, start, tau, since);
            if t < tau && best.is_none_or(|(bk, bt)| t < bt || (t == bt && k < bk)) {
                best = Some((k, t));
            }
        }
        best
    }

    /// Body `i` as it is in `state` (a segment's, or one integrated along it).
    fn body_at(&self, i: usize, state: BodyState) -> Body {
        Body {
            state,
            ..self.bodies[i].clone()
        }
    }

    /// Upper bound of how fast any point of `a` approaches any point of `b`
    /// at time `t` (linear plus angular speed times outer radius).
    fn relative_speed_bound(&self, a: usize, b: usize, seg: &[Segment], t: f64) -> f64 {
        let bound = |i: usize| {
            let s = self.integrate_segment(i, &seg[i], t - seg[i].time);
            let o = self.object(i);
            (
                s.velocity,
                self.body_at(i, s).angular_velocity(o).norm() * o.outer_radius(),
            )
        };
        let (va, wa) = bound(a);
        let (vb, wb) = bound(b);
        (va - vb).norm() + wa + wb
    }

    /// Bodies that must roll back with an impact of `pair` at τ: the pair's
    /// moving bodies and every moving body in contact with them at τ, and so
    /// on (the contact island at τ, which the impact's LCP must hold whole).
    /// Found outwards from the pair, querying each candidate pair of a member
    /// at τ; returns the members (sorted) with their states at τ, every pair
    /// queried (each pair of a member) and its result at τ.
    ///
    /// Every other body keeps its path: none touches the group at τ, and
    /// where the group's new paths reach one later in the step, that pair's
    /// own time of impact (recomputed from τ for every pair of a member)
    /// makes it an event of its own. Events therefore stay in time order,
    /// and an impact in a pile re-solves its contact island only, not every
    /// body whose swept spheres chain to it (in a pour of 1000 that chain
    /// held about half of the bodies).
    fn impact_group(
        &mut self,
        exec: &mut dyn Executor,
        pair: (u32, u32),
        tau: f64,
        pairs: &[(u32, u32)],
        seg: &[Segment],
        solved_together: &SolvedTogether,
    ) -> (Vec<(usize, BodyState)>, Vec<(u32, u32)>, Vec<PairResult>) {
        let n = self.bodies.len();
        let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); n];
        for &(a, b) in pairs {
            neighbours[a as usize].push(b);
            neighbours[b as usize].push(a);
        }
        // Bodies in the group or queued for it.
        let mut claimed = vec![false; n];
        let mut group: Vec<usize> = Vec::new();
        let mut frontier: Vec<usize> = Vec::new();
        for i in [pair.0 as usize, pair.1 as usize] {
            if self.moving(i) && !claimed[i] {
                claimed[i] = true;
                frontier.push(i);
            }
        }
        let mut at_tau: HashMap<usize, BodyState> = HashMap::new();
        let mut state = |world: &World, i: usize| {
            *at_tau
                .entry(i)
                .or_insert_with(|| world.integrate_segment(i, &seg[i], tau - seg[i].time))
        };
        let mut queried: std::collections::HashSet<(u32, u32)> = Default::default();
        let (mut group_pairs, mut results) = (Vec::new(), Vec::new());
        while !frontier.is_empty() {
            // Bodies whose segment forces came from one contact solve hold
            // each other's reactions: they roll back together, or one keeps
            // a force whose reaction the other no longer has (momentum
            // appears from nowhere).
            let mut k = 0;
            while k < frontier.len() {
                for &j in solved_together.partners(frontier[k]) {
                    if !claimed[j] && self.moving(j) {
                        claimed[j] = true;
                        frontier.push(j);
                    }
                }
                k += 1;
            }
            frontier.sort_unstable();
            group.extend(&frontier);
            // This layer's pairs, each once, in a fixed order.
            let mut layer: Vec<(u32, u32)> = Vec::new();
            for &i in &frontier {
                for &j in &neighbours[i] {
                    let k = ((i as u32).min(j), (i as u32).max(j));
                    if queried.insert(k) {
                        layer.push(k);
                    }
                }
            }
            let tasks: Vec<PairTask> = layer
                .iter()
                .map(|&(a, b)| {
                    let (sa, sb) = (state(self, a as usize), state(self, b as usize));
                    self.pair_task(a, b, &sa, &sb)
                })
                .collect();
            let layer_results = self.narrowphase_tasks(exec, tasks);
            let mut next: Vec<usize> = Vec::new();
            for (&(a, b), r) in layer.iter().zip(&layer_results) {
                if r.contacts.is_empty() && !r.penetrating {
                    continue;
                }
                for j in [a as usize, b as usize] {
                    if !claimed[j] && self.moving(j) {
                        claimed[j] = true;
                        next.push(j);
                    }
                }
            }
            next.sort_unstable();
            group_pairs.extend(layer);
            results.extend(layer_results);
            frontier = next;
        }
        group.sort_unstable();
        let states = group.into_iter().map(|i| (i, state(self, i))).collect();
        (states, group_pairs, results)
    }

    /// Islands of the given contacts, solved; applies impulses to the segment
    /// start states of `members` and sets their forces for the rest of the step.
    fn contact_phase(
        &mut self,
        exec: &mut dyn Executor,
        touching: &[Touching],
        members: &[usize],
        seg: &mut [Segment],
        h: f64,
    ) -> Solved {
        let clock = Instant::now();
        let n = self.bodies.len();
        let links: Vec<(BodyId, BodyId)> = touching.iter().map(|t| (t.a, t.b)).collect();
        let islands = island::build_islands(n, &links, |b| {
            let i = b.index();
            self.bodies[i].is_dynamic() && self.moving(i) && members.binary_search(&i).is_ok()
        });
        let restitution_threshold =
            0.5 * self.scene.settings.gravity.norm() * self.scene.settings.dt;
        let mut tasks = Vec::with_capacity(islands.len());
        // Per island, each contact's pair and point in A's body frame.
        let mut contact_pairs: Vec<Vec<ContactWhere>> = Vec::with_capacity(islands.len());
        for (bodies, contact_ids) in &islands {
            let mut pairs_here = Vec::new();
            let mut index: Vec<BodyId> = bodies.clone();
            let mut contacts = Vec::new();
            for &ci in contact_ids {
                let t = &touching[ci];
                for id in [t.a, t.b] {
                    if !index.contains(&id) {
                        index.push(id);
                    }
                }
                let ia = index.iter().position(|&x| x == t.a).unwrap() as u32;
                let ib = index.iter().position(|&x| x == t.b).unwrap() as u32;
                let (oa, ob) = (self.object(t.a.index()), self.object(t.b.index()));
                let rules = &self.scene.settings;
                let frame_a = pose(&seg[t.a.index()].state).inverse();
                let mut last = if self.warm_start {
                    self.warm.get(&(t.a, t.b)).cloned().unwrap_or_default()
                } else {
                    Vec::new()
                };
                let reach = WARM_MATCH * oa.outer_radius();
                for p in &t.points {
                    let local = frame_a.transform_point(&p.point.into()).coords;
                    // Each point of the last solve warms one new point at most.
                    let nearest = last
                        .iter()
                        .enumerate()
                        .map(|(k, w)| (k, (w.local - local).norm()))
                        .filter(|&(_, d)| d <= reach)
                        .min_by(|x, y| x.1.total_cmp(&y.1))
                        .map(|(k, _)| last.swap_remove(k));
                    let (warm_force, warm_friction) =
                        nearest.map_or((0.0, Vector3::zeros()), |w| (w.normal, w.friction));
                    pairs_here.push(((t.a, t.b), local));
                    contacts.push(IslandContact {
                        a: ia,
                        b: ib,
                        point: p.point,
                        normal: p.normal,
                        restitution: rules
                            .restitution_rule
                            .combine(oa.restitution, ob.restitution),
                        friction: rules.friction_rule.combine(oa.friction, ob.friction),
                        separation: p.separation,
                        warm_force,
                        warm_friction,
                        turns: p.turns,
                    });
                }
            }
            let bodies: Vec<IslandBody> = index
                .iter()
                .map(|id| {
                    let i = id.index();
                    let b = &self.bodies[i];
                    let o = self.object(i);
                    let s = &seg[i];
                    let dynamic =
                        b.is_dynamic() && self.moving(i) && members.binary_search(&i).is_ok();
                    let body = self.body_at(i, s.state);
                    let inv_inertia = if dynamic {
                        body.inv_inertia_world(o)
                    } else {
                        nalgebra::Matrix3::zeros()
                    };
                    IslandBody {
                        id: *id,
                        inv_mass: if dynamic { 1.0 / o.mass } else { 0.0 },
                        inv_inertia,
                        position: s.state.position,
                        velocity: s.state.velocity,
                        angular_velocity: body.angular_velocity(o),
                        external_dv: if dynamic {
                            s.force * (h / o.mass)
                        } else {
                            Vector3::zeros()
                        },
                        external_dw: if dynamic {
                            inv_inertia * s.torque * h
                        } else {
                            Vector3::zeros()
                        },
                    }
                })
                .collect();
            self.counters.contacts += contacts.len() as u64;
            contact_pairs.push(pairs_here);
            tasks.push(IslandTask {
                bodies,
                contacts,
                dt: h,
                restitution_threshold,
                iterative_min_rows: self.iterative_min_rows as u32,
            });
        }
        self.counters.islands += tasks.len() as u64;
        self.stage.build_islands += clock.elapsed().as_secs_f64();

        let clock = Instant::now();
        let ids: Vec<Vec<BodyId>> = tasks
            .iter()
            .map(|t| t.bodies.iter().map(|b| b.id).collect())
            .collect();
        let results = exec.solve_islands(tasks);
        self.last_normal_force_sum = 0.0;
        let mut pair_forces: BTreeMap<(BodyId, BodyId), f64> = Default::default();
        for (pairs, r) in contact_pairs.iter().zip(&results) {
            for (pair, _) in pairs {
                self.warm.remove(pair);
            }
            for (((pair, local), f), friction) in
                pairs.iter().zip(&r.contact_force).zip(&r.contact_friction)
            {
                *pair_forces.entry(*pair).or_default() += f;
                self.warm.entry(*pair).or_default().push(WarmContact {
                    local: *local,
                    normal: *f,
                    friction: *friction,
                });
            }
        }
        self.last_pair_forces = pair_forces
            .into_iter()
            .map(|((a, b), f)| (a, b, f))
            .collect();
        for (ids, r) in ids.iter().zip(&results) {
            self.counters.solve.add(&r.stats);
            self.last_normal_force_sum += r.normal_force_sum;
            for (k, id) in ids.iter().enumerate() {
                let i = id.index();
                if !(self.bodies[i].is_dynamic() && members.binary_search(&i).is_ok()) {
                    continue;
                }
                let o = self.object(i);
                let s = &mut seg[i];
                s.state.velocity += r.impulse[k] / o.mass;
                s.state.angular_momentum += r.angular_impulse[k];
                s.force += r.force[k];
                s.torque += r.torque[k];
            }
        }
        self.stage.solve_islands += clock.elapsed().as_secs_f64();
        // An island whose solve holds a resting force, with its fastest
        // spinner: that force is trusted for `SPIN_TRUST` of turn.
        let spinning = islands
            .iter()
            .zip(&results)
            .filter(|(_, r)| r.contact_force.iter().any(|&f| f > 0.0))
            .filter_map(|((bodies, _), _)| {
                bodies
                    .iter()
                    .map(|b| b.index())
                    .filter(|i| members.binary_search(i).is_ok())
                    .map(|i| {
                        let spin = self
                            .body_at(i, seg[i].state)
                            .angular_velocity(self.object(i));
                        (i, spin.norm())
                    })
                    .max_by(|x, y| x.1.total_cmp(&y.1).then(y.0.cmp(&x.0)))
            })
            .collect();
        let together = islands
            .iter()
            .filter(|(bodies, _)| bodies.len() > 1)
            .map(|(bodies, _)| bodies.iter().map(|b| b.index()).collect())
            .collect();
        Solved { together, spinning }
    }

    fn wake_group(&mut self, group: u32) -> Vec<usize> {
        let mut woken = Vec::new();
        for i in 0..self.bodies.len() {
            if self.bodies[i].activity == Activity::Sleeping && self.sleep_group[i] == group {
                self.bodies[i].activity = Activity::Awake;
                self.sleep_timer[i] = 0.0;
                woken.push(i);
            }
        }
        if !woken.is_empty() {
            self.counters.wakes += 1;
        }
        woken
    }

    /// Wakes resting systems touched during an impact; they join it at τ.
    fn wake_touched(
        &mut self,
        touching: &[Touching],
        seg: &mut [Segment],
        tau: f64,
        t0: f64,
    ) -> Vec<usize> {
        let mut woken = Vec::new();
        for t in touching {
            for id in [t.a, t.b] {
                let i = id.index();
                if self.bodies[i].activity == Activity::Sleeping {
                    let g = self.sleep_group[i];
                    woken.extend(self.wake_group(g));
                }
            }
        }
        for &i in &woken {
            seg[i].time = tau;
            let (f, t) = self.external(i, t0 + tau);
            seg[i].force = f;
            seg[i].torque = t;
        }
        woken.sort_unstable();
        woken
    }

    /// A moving body touching a resting system at the end of a step wakes it
    /// for the next step.
    fn wake_touched_at_end(&mut self) {
        let groups: Vec<u32> = self
            .touching
            .iter()
            .flat_map(|t| {
                let (a, b) = (t.a.index(), t.b.index());
                let mut g = Vec::new();
                if self.bodies[a].activity == Activity::Sleeping && self.moving(b) {
                    g.push(self.sleep_group[a]);
                }
                if self.bodies[b].activity == Activity::Sleeping && self.moving(a) {
                    g.push(self.sleep_group[b]);
                }
                g
            })
            .collect();
        for g in groups {
            self.wake_group(g);
        }
    }

    fn wake_for_forces(&mut self, t0: f64, h: f64) {
        let groups: Vec<u32> = self
            .scene
            .forces
            .iter()
            .filter(|w| {
                let changes = |x: f64| x > t0 - h && x <= t0;
                (changes(w.start) || changes(w.end))
                    && self.bodies[w.body.index()].activity == Activity::Sleeping
            })
            .map(|w| self.sleep_group[w.body.index()])
            .collect();
        for g in groups {
            self.wake_group(g);
        }
    }

    /// Resting systems and falls (SPEC 2.6).
    fn update_rest_and_falls(&mut self, h: f64) {
        let fall_z = self.scene.settings.fall_z;
        for i in 0..self.bodies.len() {
            let b = &self.bodies[i];
            if b.is_dynamic() && b.activity == Activity::Awake && b.state.position.z < fall_z {
                self.bodies[i].activity = Activity::Fallen;
                self.counters.bodies_fallen += 1;
            }
        }
        if !self.sleep_enabled {
            return;
        }
        let n = self.bodies.len();
        for i in 0..n {
            let b = &self.bodies[i];
            if b.is_dynamic() && b.activity == Activity::Awake {
                let w = b.angular_velocity(self.object(i));
                if b.state.velocity.norm() < SLEEP_LINEAR && w.norm() < SLEEP_ANGULAR {
                    self.sleep_timer[i] += h;
                } else {
                    self.sleep_timer[i] = 0.0;
                }
            }
        }
        // A system sleeps only as a whole, and never while it touches a moving driven body.
        let links: Vec<(BodyId, BodyId)> = self.touching.iter().map(|t| (t.a, t.b)).collect();
        let mut sets = island::DisjointSets::new(n);
        let mut blocked = vec![false; n];
        for &(a, b) in &links {
            let (ia, ib) = (a.index(), b.index());
            let dyn_a = self.bodies[ia].is_dynamic();
            let dyn_b = self.bodies[ib].is_dynamic();
            if dyn_a && dyn_b {
                sets.union(a.0, b.0);
            }
            if matches!(self.bodies[ia].kind, BodyKind::Driven { .. }) {
                blocked[ib] = true;
            }
            if matches!(self.bodies[ib].kind, BodyKind::Driven { .. }) {
                blocked[ia] = true;
            }
        }
        let mut ready: HashMap<u32, bool> = HashMap::new();
        for i in 0..n {
            let b = &self.bodies[i];
            if !(b.is_dynamic() && b.activity == Activity::Awake) {
                continue;
            }
            let root = sets.find(i as u32);
            let ok = self.sleep_timer[i] >= self.sleep_after && !blocked[i];
            let e = ready.entry(root).or_insert(true);
            *e &= ok;
        }
        for i in 0..n {
            let b = &self.bodies[i];
            if !(b.is_dynamic() && b.activity == Activity::Awake) {
                continue;
            }
            let root = sets.find(i as u32);
            if ready.get(&root) == Some(&true) {
                let body = &mut self.bodies[i];
                body.activity = Activity::Sleeping;
                body.state.velocity = Vector3::zeros();
                body.state.angular_momentum = Vector3::zeros();
                self.sleep_group[i] = root;
            }
        }
    }

    /// Stops the run when a state is non-finite or faster than 10⁶ m/s,
    /// naming the stage that produced it: `solve_islands` right after a
    /// contact solve (impulses), `integrate` at the end of the step (forces,
    /// including a scene's own `[[forces]]`, acting over it).
    fn check_states<'a>(
        &self,
        states: impl Iterator<Item = (usize, &'a BodyState)>,
        stage: &'static str,
        t: f64,
    ) -> Result<(), NumericalFailure> {
        for (i, s) in states {
            let finite = s.position.iter().all(|x| x.is_finite())
                && s.velocity.iter().all(|x| x.is_finite())
                && s.angular_momentum.iter().all(|x| x.is_finite())
                && s.orientation.coords.iter().all(|x| x.is_finite());
            let detail = if !finite {
                "has a non-finite state".to_string()
            } else if s.velocity.norm() > 1e6 {
                format!("exploded (speed {:.3e} m/s)", s.velocity.norm())
            } else {
                continue;
            };
            return Err(NumericalFailure {
                body: BodyId(i as u32),
                stage,
                time: t,
                detail,
            });
        }
        Ok(())
    }

    /// A 64-bit FNV-1a hash of the exact bits of every body's state, as hex.
    pub fn state_hash(&self) -> String {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let mut eat = |x: f64| {
            for byte in x.to_bits().to_le_bytes() {
                h ^= byte as u64;
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        };
        for b in &self.bodies {
            let s = &b.state;
            s.position.iter().for_each(|&x| eat(x));
            s.orientation.coords.iter().for_each(|&x| eat(x));
            s.velocity.iter().for_each(|&x| eat(x));
            s.angular_momentum.iter().for_each(|&x| eat(x));
        }
        format!("{h:016x}")
    }

    /// World point helper for tests.
    pub fn world_point(&self, body: usize, local: Vector3<f64>) -> Vector3<f64> {
        (self.bodies[body].pose() * Point3::from(local)).coords
    }
}
