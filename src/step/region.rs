//! A set of bodies stepped together, in local indices: the whole world for
//! the stages every body takes (the contact solve at the step's start,
//! integration, the broadphase), or one interaction group for its impact
//! events (`group`). The stage code is written once, over a `Region`.
//!
//! Local index `i` is body `ids[i]` of the world; `ids` is increasing, so
//! every tie-break on local pair keys orders pairs exactly as on world ids,
//! and a group's result never depends on which other bodies the world holds.
//!
//! A region borrows the state it changes: the world's, for the step, in the
//! world-wide stages (`World::step`); a `RegionState` of its own, cut from
//! the world's, in a group's step (`group`).

use super::executor::{Executor, PairKey, Segment, StepStatic};
use super::kept::{self, Kept};
use super::stats::Counters;
use super::timers::{Stage, StageSeconds};
use super::touching::{Touching, WarmContact};
use crate::body::{Activity, Body, BodyId, BodyKind, BodyState, ObjectDef};
use crate::collision::broadphase::{self, SphereProxy};
use crate::collision::narrowphase::{
    self, CONTACT_TOLERANCE, CachedFeatures, NEAR_FROM, PairResult, PairTask,
};
use crate::contact::solver::IslandTask;
use crate::dynamics::integrate::integrate;
use crate::math;
use nalgebra::{Isometry3, Vector3};
use rustc_hash::FxBuildHasher;
use std::cell::RefCell;
use std::collections::{BTreeMap, BTreeSet, HashMap};

/// A map keyed by body pair. Fx, not std's SipHash: the step looks pairs up
/// hundreds of thousands of times (feature caches, separating pairs, times
/// of impact), its keys are not chosen by an adversary, and no result
/// depends on a map's order.
pub(crate) type PairMap<V> = HashMap<PairKey, V, FxBuildHasher>;

/// The stages' view of a set of bodies (see the module comment): the
/// state they change, borrowed from its owner (the world's `WorldState`
/// and `Diagnostics` for the world-wide stages, a `RegionState` for a
/// group), and what the region gathers within the step.
pub(crate) struct Region<'s> {
    pub st: &'s StepStatic<'s>,
    /// World id of each local body, increasing.
    pub ids: Vec<u32>,
    pub bodies: &'s mut Vec<Body>,
    /// V-Clip's cached closest features per pair (warm starts of queries).
    pub features: &'s mut PairMap<Vec<CachedFeatures>>,
    /// Resting forces of the last solve of each touching pair (warm start).
    pub warm: &'s mut BTreeMap<(BodyId, BodyId), Vec<WarmContact>>,
    pub sleep_timer: &'s mut Vec<f64>,
    /// Resting system a sleeping body belongs to (its lowest world id).
    pub sleep_group: &'s mut Vec<u32>,
    /// Contacts of the impacts solved in this step (the next step's
    /// separating-pair skip).
    pub impacts: &'s mut Vec<Touching>,
    pub counters: &'s mut Counters,
    pub stage: &'s mut StageSeconds,
    /// Whether its island answers, times of impact and pair tests are kept
    /// for a later run of the same events (`super::kept`): a part of a
    /// split group, which may step again merged with the parts it met.
    pub keep_answers: bool,
    /// What it gathers within the step (nothing, at first).
    pub gathered: Gathered,
}

/// What a region gathers within a step, the same for the world and for a
/// group: `Default` is a region's start (nothing gathered).
#[derive(Default)]
pub(crate) struct Gathered {
    /// Total resting normal force on each pair in its latest solve.
    pub pair_forces: BTreeMap<(BodyId, BodyId), f64>,
    /// Pairs a speculative contact pushed on in this step (it held a
    /// resting force or deferred a bounce), checked at the step's end
    /// (`Counters::speculative_ghosts`).
    pub speculative_pushes: BTreeSet<(BodyId, BodyId)>,
    /// Integrations along segments already done (`integrate_segment`).
    pub integrated: Integrated,
    /// Copies of the islands it built of `StepSettings::capture_min_rows`
    /// rows or more, in the order it built them (empty unless asked for).
    pub captured: Vec<IslandTask>,
}

/// The state a group's region changes, owned: cut from the world's
/// (`group::group_input`) on whichever rank steps the group.
#[derive(Default)]
pub(crate) struct RegionState {
    pub bodies: Vec<Body>,
    pub features: PairMap<Vec<CachedFeatures>>,
    pub warm: BTreeMap<(BodyId, BodyId), Vec<WarmContact>>,
    pub sleep_timer: Vec<f64>,
    pub sleep_group: Vec<u32>,
    pub impacts: Vec<Touching>,
    pub counters: Counters,
    pub stage: StageSeconds,
}

impl RegionState {
    /// The region of bodies `ids` (world ids, increasing) over this state,
    /// with nothing yet gathered in the step.
    pub fn region<'s>(&'s mut self, st: &'s StepStatic<'s>, ids: Vec<u32>) -> Region<'s> {
        Region {
            st,
            ids,
            bodies: &mut self.bodies,
            features: &mut self.features,
            warm: &mut self.warm,
            sleep_timer: &mut self.sleep_timer,
            sleep_group: &mut self.sleep_group,
            impacts: &mut self.impacts,
            counters: &mut self.counters,
            stage: &mut self.stage,
            keep_answers: false,
            gathered: Gathered::default(),
        }
    }
}

/// A pile's group step asks for hundreds of thousands of integrations,
/// many of them once (each bisection query's instant): the memo starts
/// again past this many entries (about 2 MB), which changes no answer. The
/// repeats come close together, so a memo this small keeps most of the
/// hits of an unbounded one without growing the process.
const INTEGRATED_KEPT: usize = 1 << 12;

/// The integrations a region has done, by body, segment and interval: the
/// same instant of the same segment is asked for by every pair of its body
/// (each time of impact integrates both bodies at both ends of its
/// interval, and the step's end is each body's end state), and a step
/// along a segment is a pure function of these, so a repeat is answered
/// with the same bits.
#[derive(Default)]
pub(crate) struct Integrated(RefCell<HashMap<[u64; 21], BodyState, FxBuildHasher>>);

/// A body state's pose, as narrowphase takes it.
pub(crate) fn pose(s: &BodyState) -> Isometry3<f64> {
    Isometry3::from_parts(s.position.into(), s.orientation)
}

impl<'s> Region<'s> {
    pub fn object(&self, i: usize) -> &'s ObjectDef {
        &self.st.objects[self.bodies[i].object.0 as usize]
    }

    pub fn moving(&self, i: usize) -> bool {
        let b = &self.bodies[i];
        b.activity == Activity::Awake && !matches!(b.kind, BodyKind::Fixed)
    }

    /// Gravity and the scene's force windows on body `i` at time `t`.
    pub fn external(&self, i: usize, t: f64) -> (Vector3<f64>, Vector3<f64>) {
        let o = self.object(i);
        let mut f = o.mass * self.st.settings.gravity;
        let mut tau = Vector3::zeros();
        for w in self.st.forces {
            if w.body.0 == self.ids[i] && w.start <= t && t < w.end {
                f += w.force;
                tau += w.torque;
            }
        }
        (f, tau)
    }

    pub fn integrate_segment(&self, i: usize, s: &Segment, h: f64) -> BodyState {
        let st = &s.state;
        let q = st.orientation.coords;
        let key = [
            i as f64,
            h,
            st.position.x,
            st.position.y,
            st.position.z,
            q.x,
            q.y,
            q.z,
            q.w,
            st.velocity.x,
            st.velocity.y,
            st.velocity.z,
            st.angular_momentum.x,
            st.angular_momentum.y,
            st.angular_momentum.z,
            s.force.x,
            s.force.y,
            s.force.z,
            s.torque.x,
            s.torque.y,
            s.torque.z,
        ]
        .map(f64::to_bits);
        if let Some(done) = self.gathered.integrated.0.borrow().get(&key) {
            return *done;
        }
        let done = integrate(
            &s.state,
            self.object(i),
            self.bodies[i].kind,
            &s.force,
            &s.torque,
            h,
        );
        let mut memo = self.gathered.integrated.0.borrow_mut();
        if memo.len() >= INTEGRATED_KEPT {
            memo.clear();
        }
        memo.insert(key, done);
        done
    }

    /// Body `i` as it is in `state` (a segment's, or one integrated along it).
    /// Velocity of body `i`'s material point at world position `p`, in `state`.
    pub fn point_velocity(&self, i: usize, state: &BodyState, p: &Vector3<f64>) -> Vector3<f64> {
        self.body_at(i, *state).point_velocity(self.object(i), p)
    }

    pub fn body_at(&self, i: usize, state: BodyState) -> Body {
        Body {
            state,
            ..self.bodies[i].clone()
        }
    }

    /// Candidate pairs from spheres swept between each body's segment start and
    /// its end state (fast bodies cannot skip a pair this way), with the
    /// spheres they came from.
    pub fn broadphase(
        &mut self,
        seg: &[Segment],
        end: &[BodyState],
    ) -> (Vec<PairKey>, Vec<SphereProxy>) {
        let timer = self.stage.start(Stage::Broadphase);
        let proxies = self.swept_spheres(seg, end);
        let resting = std::cell::Cell::new(0u64);
        let pairs = broadphase::candidate_pairs(&proxies, |a, b| {
            let keep = self.needs_test(a, b);
            resting.set(resting.get() + u64::from(!keep));
            keep
        });
        self.counters.candidate_pairs += pairs.len() as u64;
        self.counters.pairs_skipped_resting += resting.get();
        self.stage.stop(timer);
        (pairs, proxies)
    }

    /// A pair needs a test when one of its bodies moves and one takes
    /// impulses: two fixed, two resting, or a driven and a fixed body never
    /// need one.
    pub fn needs_test(&self, a: u32, b: u32) -> bool {
        let (a, b) = (a as usize, b as usize);
        (self.moving(a) || self.moving(b))
            && (self.bodies[a].is_dynamic() || self.bodies[b].is_dynamic())
    }

    /// Every body's bounding spheres, swept from its segment start to its end
    /// state, grouped by body.
    pub fn swept_spheres(&self, seg: &[Segment], end: &[BodyState]) -> Vec<SphereProxy> {
        let mut proxies = Vec::new();
        for (i, b) in self.bodies.iter().enumerate() {
            if b.activity == Activity::Fallen {
                continue;
            }
            self.push_swept(&mut proxies, i as u32, i, &seg[i].state, &end[i]);
        }
        proxies
    }

    /// Body `i`'s spheres swept from `from` to `to`, tagged `tag`.
    pub fn push_swept(
        &self,
        proxies: &mut Vec<SphereProxy>,
        tag: u32,
        i: usize,
        from: &BodyState,
        to: &BodyState,
    ) {
        let o = self.object(i);
        let (p0, q0) = (from.position, from.orientation);
        let (p1, q1) = (to.position, to.orientation);
        let angle = math::angle_between(&q0, &q1);
        for s in &o.spheres {
            let c0 = p0 + q0 * s.center;
            let c1 = p1 + q1 * s.center;
            // The chord from c0 to c1 misses the arc of a rotating offset by
            // at most |offset|·(1 − cos(θ/2)) ≤ |offset|·θ²/8; add it.
            let bulge = s.center.norm() * angle * angle / 8.0;
            proxies.push(SphereProxy {
                body: tag,
                center: 0.5 * (c0 + c1),
                radius: s.radius + 0.5 * (c1 - c0).norm() + bulge + CONTACT_TOLERANCE,
            });
        }
    }

    /// Of the given touching pairs (at the step's start, or at an impact),
    /// those whose every contact point separates at the velocities in `seg`
    /// (relative normal velocity > 0), with a contact normal (out of b
    /// towards a). SPEC 2.6 does not test such pairs in the next frame; here
    /// they get a cheaper test that can only skip when it proves the pair
    /// apart (`narrowphase_skipping_separating`).
    pub fn separating_pairs(
        &self,
        touching: &[Touching],
        seg: &[Segment],
    ) -> PairMap<Vector3<f64>> {
        if !self.st.step_settings.skip_separating {
            return PairMap::default();
        }
        let velocity_at = |i: usize, p: &Vector3<f64>| self.point_velocity(i, &seg[i].state, p);
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
    pub fn narrowphase_skipping_separating(
        &mut self,
        exec: &mut dyn Executor,
        pairs: &[PairKey],
        states: &[BodyState],
        separating: &PairMap<Vector3<f64>>,
    ) -> Vec<PairResult> {
        let timer = self.stage.start(Stage::Narrowphase);
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
        let tested: Vec<PairKey> = pairs
            .iter()
            .zip(&skipped)
            .filter(|(_, skip)| !**skip)
            .map(|(k, _)| *k)
            .collect();
        let skips = pairs.len() - tested.len();
        self.counters.pairs_skipped_separating += skips as u64;
        self.stage.stop(timer);
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

    pub fn narrowphase_at(
        &mut self,
        exec: &mut dyn Executor,
        pairs: &[PairKey],
        states: &[BodyState],
    ) -> Vec<PairResult> {
        let tasks: Vec<PairTask> = pairs
            .iter()
            .map(|&(a, b)| self.pair_task(a, b, &states[a as usize], &states[b as usize]))
            .collect();
        self.narrowphase_tasks(exec, tasks)
    }

    pub fn narrowphase_tasks(
        &mut self,
        exec: &mut dyn Executor,
        tasks: Vec<PairTask>,
    ) -> Vec<PairResult> {
        let timer = self.stage.start(Stage::Narrowphase);
        self.counters.pair_tests += tasks.len() as u64;
        let results = if self.keep_answers {
            // A part of a split group (`super::kept`): a pair test is a
            // function of its task.
            thread_local! {
                static KEPT: std::cell::RefCell<Kept<PairResult>> = Default::default();
            }
            let questions = tasks.iter().map(|t| Some(kept::question(t))).collect();
            let objects = self.st.objects;
            kept::again_or_anew(
                &KEPT,
                tasks,
                questions,
                |tasks| exec.narrowphase(objects, tasks),
                |r| 64 * (4 + r.contacts.len() + r.features.len()),
            )
        } else {
            exec.narrowphase(self.st.objects, tasks)
        };
        for r in &results {
            self.counters.vclip_iterations += r.iterations as u64;
        }
        self.stage.stop(timer);
        results
    }

    /// A V-Clip task for local pair (a, b) in the given states. Tasks carry
    /// world ids: a worker's answer must not depend on the region it came from.
    pub fn pair_task(&self, a: u32, b: u32, sa: &BodyState, sb: &BodyState) -> PairTask {
        PairTask {
            a: BodyId(self.ids[a as usize]),
            b: BodyId(self.ids[b as usize]),
            object_a: self.bodies[a as usize].object.0,
            object_b: self.bodies[b as usize].object.0,
            pose_a: pose(sa),
            pose_b: pose(sb),
            warm: self.features.get(&(a, b)).cloned().unwrap_or_default(),
            contact_tolerance: CONTACT_TOLERANCE,
            near_distance: self.near_distance(a as usize, b as usize, sa, sb),
        }
    }

    /// How far apart a pair's near points are asked for: what the pair can
    /// close within a step at twice its present speed (each body's centre
    /// speed and spin at its outer radius), past `NEAR_FROM`, capped at
    /// `Settings::near_distance`. A resting pile's pairs ask for none; a
    /// pair that speeds up more than that within a step meets in an exact
    /// impact event, as in the exact model.
    fn near_distance(&self, a: usize, b: usize, sa: &BodyState, sb: &BodyState) -> f64 {
        let cap = self.st.settings.near_distance();
        if cap == 0.0 {
            return 0.0;
        }
        let spin = |i: usize, s: &BodyState| {
            let o = self.object(i);
            self.body_at(i, *s).angular_velocity(o).norm() * o.outer_radius()
        };
        let speed = (sa.velocity - sb.velocity).norm() + spin(a, sa) + spin(b, sb);
        let h = self.st.settings.dt;
        let reach = 2.0 * speed * h + NEAR_FROM;
        reach.min(cap)
    }

    pub fn touching_from(&self, pairs: &[PairKey], results: &[PairResult]) -> Vec<Touching> {
        pairs
            .iter()
            .zip(results)
            .filter(|(_, r)| !r.contacts.is_empty() || !r.near.is_empty())
            .map(|(&(a, b), r)| Touching {
                a: BodyId(a),
                b: BodyId(b),
                points: r.contacts.clone(),
                near: r.near.clone(),
            })
            .collect()
    }
}
