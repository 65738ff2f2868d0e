//! The world step: SPEC 2.1's frame loop, stage by stage.
//!
//! ```text
//! build_islands   contacts touching now → systems (islands), sorted by lowest body id
//! solve_islands   impact impulses + resting/friction forces per island (Dantzig LCP)
//! integrate       every awake body to the end of the step (constant force)
//! broadphase      swept bounding spheres → candidate pairs
//! build_groups    the moving bodies, split into groups that can reach each other
//! narrowphase     per group: V-Clip on its pairs at the end of the step → contacts, overlaps
//! time_of_impact  per group: an overlap rolls back only the bodies that must move
//!                 with it to the touching instant found by bisection, solves the
//!                 impact there and re-integrates them; groups whose new paths meet
//!                 merge and step again
//! publish_frame   (caller) trajectory sample, render poses
//! ```
//!
//! The stages are written over a `Region` (`region`): the whole world for
//! the stages every body takes (`frame`), one group for its narrowphase and
//! impacts (`group` forms and merges the groups, `impacts` steps one). The
//! time of impact itself is `toi`, the contact solve `contact`, resting
//! systems `sleep`, what is counted `stats` and what is timed `timers`.
//!
//! The pure work (V-Clip on pairs, LCP on islands, whole group steps) goes
//! through an `Executor` (`executor`, with all it carries): inline on one
//! rank (`Inline`), or scattered over MPI ranks by `cluster`.
//! Results come back in task order, and groups are merged by id, so the
//! outcome never depends on which rank did what.

mod contact;
mod event_path;
mod executor;
mod first_stage;
mod frame;
mod group;
mod impacts;
mod kept;
pub mod profile;
mod region;
mod settings;
mod sleep;
pub mod stats;
mod timers;
mod toi;
mod touching;

pub use crate::scene::bounds::MAX_SPEED;
pub use contact::{MAX_SPIN_RESOLVES_PER_STEP, SPIN_TRUST};
pub use executor::{
    Executor, GroupFailure, GroupInput, GroupOutput, GroupParams, GroupReply, PreparedPairs,
    StepStatic,
};
pub use first_stage::prepare_pairs;
pub use group::{SPLIT_AUTO_MIN_MEMBERS, SPLIT_MIN_MEMBERS, run_group};
pub use impacts::EVENTS_PER_BODY;
pub use settings::{GROUP_MARGIN, StepSettings};
pub use sleep::{SLEEP_ANGULAR, SLEEP_LINEAR};
pub use stats::{Counters, NumericalFailure};
pub use timers::{Stage, StageSeconds};
pub use toi::{RATCHET_GAP, TOI_GAP};
pub(crate) use touching::{Touching, WarmContact};

use crate::body::{Activity, Body, BodyId, BodyKind, ObjectDef};
use crate::collision::narrowphase::{self, CachedFeatures, PairResult, PairTask};
use crate::contact::solver::{self, IslandResult, IslandTask};
use crate::scene::Scene;
use nalgebra::{Point3, Vector3};
use profile::{BlockRound, Profiler, StageKind, StepSink, TaskCost, TimedBlocks};
use region::{Gathered, Region};
use serde::Serialize;
use serde::de::DeserializeOwned;
use stats::{Distribution, GroupWork, RankSummary};
use std::collections::{BTreeMap, BTreeSet};
use std::time::Instant;

/// Runs every stage on this rank.
#[derive(Default)]
pub struct Inline {
    clock: stats::StageClock,
    busy_s: f64,
    narrowphase_tasks: u64,
    island_tasks: u64,
    dist: Distribution,
    /// Records the outermost stage calls' tasks, where the run asks for
    /// the speed-up on several ranks (`Inline::profiled`).
    profiler: Option<Profiler>,
    /// With a profiler: the block rounds of the islands a group step under
    /// way solved, which its task takes.
    group_rounds: Option<Vec<BlockRound>>,
}

impl Inline {
    /// An `Inline` whose stage calls `sink` sees, step by step.
    pub fn profiled(sink: Box<dyn StepSink>) -> Self {
        Inline {
            profiler: Some(Profiler::new(sink)),
            group_rounds: Some(Vec::new()),
            ..Default::default()
        }
    }

    /// Solves each island with its block rounds timed (`TimedBlocks`): an
    /// outermost call records each island as a task, one inside a group
    /// step adds the rounds to the group's.
    fn solve_islands_timed(&mut self, tasks: &[IslandTask]) -> Vec<IslandResult> {
        let mut answers = Vec::with_capacity(tasks.len());
        for task in tasks {
            let started = Instant::now();
            let mut timed = TimedBlocks::default();
            let answer = solver::solve_island_with(task, &mut timed);
            if let Some(p) = &mut self.profiler {
                let seconds = started.elapsed().as_secs_f64();
                let (asked, answered) = (p.wire(task), p.wire(&answer));
                p.add(TaskCost {
                    estimate: task.cost_units(),
                    by_blocks: solver::sweeps_by_blocks(task),
                    rounds: timed.rounds,
                    ..TaskCost::sent(seconds, asked, answered)
                });
            } else if let Some(rounds) = &mut self.group_rounds {
                rounds.extend(timed.rounds);
            }
            answers.push(answer);
        }
        if let Some(p) = &mut self.profiler {
            p.end_call(StageKind::IslandSolves);
        }
        answers
    }

    /// Runs `f` on each task; with a profiler, as one stage call of `kind`.
    fn each<T: Serialize + DeserializeOwned, R: Serialize + DeserializeOwned>(
        &mut self,
        kind: StageKind,
        tasks: &[T],
        mut f: impl FnMut(&T) -> R,
    ) -> Vec<R> {
        let Some(profiler) = &mut self.profiler else {
            return tasks.iter().map(f).collect();
        };
        let answers = tasks
            .iter()
            .map(|t| {
                let started = Instant::now();
                let answer = f(t);
                profiler.task(started, t, &answer);
                answer
            })
            .collect();
        profiler.end_call(kind);
        answers
    }
}

impl Executor for Inline {
    fn narrowphase(&mut self, objects: &[ObjectDef], tasks: Vec<PairTask>) -> Vec<PairResult> {
        self.clock.enter();
        let clock = Instant::now();
        self.narrowphase_tasks += tasks.len() as u64;
        self.dist.narrowphase_local += 1;
        let r = self.each(StageKind::Narrowphase, &tasks, |t| {
            narrowphase::query_pair(objects, t)
        });
        self.busy_s += clock.elapsed().as_secs_f64();
        self.dist.distributable_s += self.clock.leave();
        r
    }
    fn solve_islands(&mut self, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
        self.clock.enter();
        let clock = Instant::now();
        self.island_tasks += tasks.len() as u64;
        self.dist.solve_local += 1;
        let r = if self.group_rounds.is_some() {
            self.solve_islands_timed(&tasks)
        } else {
            self.each(StageKind::IslandSolves, &tasks, solver::solve_island)
        };
        self.busy_s += clock.elapsed().as_secs_f64();
        self.dist.distributable_s += self.clock.leave();
        r
    }
    fn step_groups(
        &mut self,
        st: &StepStatic,
        _params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<GroupReply> {
        // Busy time and tasks are counted by the stages the groups call.
        self.clock.enter();
        self.dist.groups_local += 1;
        // Taken out while the groups step: the calls they make are theirs.
        let mut profiler = self.profiler.take();
        let replies = inputs
            .into_iter()
            .map(|input| {
                let asked = profiler.as_mut().map(|p| p.wire(&input));
                let estimate = input.predicted_s();
                let started = Instant::now();
                let reply = group::run_group(st, input, self);
                if let (Some(p), Some(asked)) = (&mut profiler, asked) {
                    let seconds = started.elapsed().as_secs_f64();
                    let answered = p.wire(&reply);
                    p.add(TaskCost {
                        estimate,
                        rounds: self.group_rounds.replace(Vec::new()).unwrap_or_default(),
                        ..TaskCost::sent(seconds, asked, answered)
                    });
                }
                reply
            })
            .collect();
        if let Some(p) = &mut profiler {
            p.end_call(StageKind::GroupSteps);
        }
        self.profiler = profiler;
        self.dist.distributable_s += self.clock.leave();
        replies
    }
    fn prepare_groups(
        &mut self,
        st: &StepStatic,
        _params: &GroupParams,
        inputs: Vec<GroupInput>,
    ) -> Vec<PreparedPairs> {
        self.clock.enter();
        let clock = Instant::now();
        let prepared = self.each(StageKind::PreparePairs, &inputs, |input| {
            first_stage::prepare_pairs(st, input, (0, input.pair_count()), &mut Inline::default())
        });
        self.narrowphase_tasks += prepared.iter().map(PreparedPairs::tasks).sum::<u64>();
        self.busy_s += clock.elapsed().as_secs_f64();
        self.dist.distributable_s += self.clock.leave();
        prepared
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
        let mut dist = self.dist.clone();
        if let Some(p) = &mut self.profiler {
            p.close(&mut dist);
        }
        (vec![me], dist)
    }
    fn groups_stepped(&mut self) {
        if let Some(p) = &mut self.profiler {
            p.end_step();
        }
    }
}

/// A body that fell below `fall_z`, and when: the end of the step that
/// found it there (`summary.json`'s `fallen`).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Fall {
    pub body: BodyId,
    /// Simulated seconds, steps × dt.
    pub time: f64,
}

/// The simulated world: the static scene, the state each step changes, how
/// the step works, and what the steps measured.
pub struct World {
    pub scene: Scene,
    pub state: WorldState,
    /// How the run asks the step to work.
    pub settings: StepSettings,
    pub diagnostics: Diagnostics,
}

/// What a step changes and the next step reads. All of it but `impacts`
/// is checkpointed (`output::checkpoint`).
pub struct WorldState {
    pub bodies: Vec<Body>,
    /// Completed steps; time = steps × dt exactly (no accumulated rounding).
    pub steps: u64,
    /// The contacts touching at the end of the last step: the next step's
    /// `build_islands` starts from them.
    pub(crate) touching: Vec<Touching>,
    /// Contacts of the impacts solved during the last step, for the
    /// separating-pair skip (only an optimisation: not checkpointed).
    pub(crate) impacts: Vec<Touching>,
    /// V-Clip's cached closest features per pair (warm starts of queries).
    pub(crate) features: region::PairMap<Vec<CachedFeatures>>,
    /// Seconds each body has been slow (it may rest after
    /// `StepSettings::sleep_after`).
    pub(crate) sleep_timer: Vec<f64>,
    /// Resting system a sleeping body belongs to (its lowest body id).
    pub(crate) sleep_group: Vec<u32>,
    /// Resting forces of the last solve of each touching pair (warm start).
    pub(crate) warm: BTreeMap<(BodyId, BodyId), Vec<WarmContact>>,
    /// The bodies that fell below `fall_z`, in the order they fell (by
    /// body id within a step).
    pub fallen: Vec<Fall>,
}

/// What the steps measured, for the summary, the tests and the schedule:
/// no body's motion depends on it. The counters, the largest penetration
/// and the last forces are checkpointed so that a resumed run's summary
/// reads like an uninterrupted one.
#[derive(Default)]
pub struct Diagnostics {
    /// Wall seconds per stage.
    pub stage: StageSeconds,
    pub counters: Counters,
    /// Largest overlap seen at the end of any step, metres.
    pub max_penetration: f64,
    /// Total resting normal force of the last contact solve, and the force
    /// on each touching body pair (a, b, newtons).
    pub last_normal_force_sum: f64,
    pub last_pair_forces: Vec<(BodyId, BodyId, f64)>,
    /// Copies of the islands the last step built of
    /// `StepSettings::capture_min_rows` rows or more, in the order it built
    /// them (those of the group steps run on this rank included), for the
    /// caller to write (`--capture-islands`); empty unless asked for.
    pub captured_islands: Vec<IslandTask>,
    /// What the group steps cost (the schedule's prediction; not
    /// checkpointed).
    group_work: GroupWork,
}

impl WorldState {
    /// The scene's bodies at t = 0: nothing touching, nothing cached,
    /// each body its own resting system.
    fn new(bodies: Vec<Body>) -> WorldState {
        let n = bodies.len();
        WorldState {
            bodies,
            steps: 0,
            touching: Vec::new(),
            impacts: Vec::new(),
            features: Default::default(),
            sleep_timer: vec![0.0; n],
            sleep_group: (0..n as u32).collect(),
            warm: BTreeMap::new(),
            fallen: Vec::new(),
        }
    }
}

impl Diagnostics {
    /// Nothing measured yet, for a world of `n` bodies.
    fn new(n: usize) -> Diagnostics {
        Diagnostics {
            group_work: GroupWork::new(n),
            ..Default::default()
        }
    }
}

impl World {
    pub fn new(scene: Scene) -> World {
        let n = scene.bodies.len();
        let state = WorldState::new(scene.bodies.clone());
        World {
            scene,
            state,
            settings: StepSettings::default(),
            diagnostics: Diagnostics::new(n),
        }
    }

    /// What the run's group steps have cost so far.
    pub fn group_work(&self) -> &GroupWork {
        &self.diagnostics.group_work
    }

    pub fn time(&self) -> f64 {
        self.state.steps as f64 * self.scene.settings.dt
    }

    pub fn object(&self, body: usize) -> &ObjectDef {
        &self.scene.objects[self.state.bodies[body].object.0 as usize]
    }

    /// Kinetic plus gravitational potential energy of the dynamic bodies still simulated.
    pub fn energy(&self) -> f64 {
        let g = self.scene.settings.gravity;
        self.state
            .bodies
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
        self.state.bodies.iter().all(|b| match b.kind {
            BodyKind::Dynamic => b.activity != Activity::Awake,
            BodyKind::Fixed => true,
            BodyKind::Driven {
                velocity,
                angular_velocity,
            } => velocity == Vector3::zeros() && angular_velocity == Vector3::zeros(),
        })
    }

    /// Advances the world by one step of `dt`. The world-wide stages
    /// borrow its state; also after a numerical failure the world keeps
    /// what the step left (the states are those before the failing stage).
    pub fn step(&mut self, exec: &mut dyn Executor) -> Result<(), NumericalFailure> {
        let st = GroupParams::new(self.time(), self.settings).statics(&self.scene);
        let (s, d) = (&mut self.state, &mut self.diagnostics);
        let fallen_before = d.counters.bodies_fallen;
        let mut world = Region {
            st: &st,
            ids: (0..s.bodies.len() as u32).collect(),
            bodies: &mut s.bodies,
            features: &mut s.features,
            warm: &mut s.warm,
            sleep_timer: &mut s.sleep_timer,
            sleep_group: &mut s.sleep_group,
            impacts: &mut s.impacts,
            counters: &mut d.counters,
            stage: &mut d.stage,
            keep_answers: false,
            gathered: Gathered::default(),
        };
        let carried = frame::Carried {
            touching: &mut s.touching,
            steps: &mut s.steps,
            max_penetration: &mut d.max_penetration,
            work: &mut d.group_work,
        };
        let result = frame::step_world(&mut world, exec, carried);
        let Gathered {
            pair_forces,
            captured,
            ..
        } = world.gathered;
        d.captured_islands = captured;
        d.last_normal_force_sum = pair_forces.values().sum();
        d.last_pair_forces = pair_forces
            .into_iter()
            .map(|((a, b), f)| (a, b, f))
            .collect();
        if d.counters.bodies_fallen > fallen_before {
            self.record_falls();
        }
        result
    }

    /// Notes the time of the bodies the step just taken found below
    /// `fall_z` (`Region::update_rest_and_falls`, at the step's end, counts
    /// each in `bodies_fallen` as it marks it fallen).
    fn record_falls(&mut self) {
        let time = self.time();
        let s = &mut self.state;
        let known: BTreeSet<BodyId> = s.fallen.iter().map(|f| f.body).collect();
        for (i, b) in s.bodies.iter().enumerate() {
            let body = BodyId(i as u32);
            if b.activity == Activity::Fallen && !known.contains(&body) {
                s.fallen.push(Fall { body, time });
            }
        }
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
        for b in &self.state.bodies {
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
        (self.state.bodies[body].pose() * Point3::from(local)).coords
    }
}
