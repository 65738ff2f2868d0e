//! The contact phase (SPEC 2.4): contacts touching now → islands
//! (`build_islands`), one LCP each (`solve_islands`, through the executor),
//! impulses and resting forces written back to the bodies' segments; warm
//! starts from each pair's last solve; and the bookkeeping an impact loop
//! needs of each solve (who was solved together, who spins).

use super::executor::{Executor, Segment};
use super::kept::{self, Kept};
use super::region::{Region, pose};
use super::timers::Stage;
use super::touching::{Touching, WarmContact};
use crate::body::BodyId;
use crate::collision::manifold::ContactPoint;
use crate::contact::island;
use crate::contact::solver::{
    IslandBody, IslandContact, IslandResult, IslandTask, SPECULATIVE_GAP,
};
use nalgebra::Vector3;
use std::collections::BTreeMap;

/// What one contact solve leaves for the rest of the step.
pub(crate) struct Solved {
    /// Bodies solved together, per island of two or more (`SolvedTogether`).
    pub together: Vec<Vec<usize>>,
    /// Per island whose solve holds a resting force: its fastest-spinning
    /// body and that body's spin (rad/s), for `SPIN_TRUST`.
    pub spinning: Vec<(usize, f64)>,
}

/// When each island that holds a resting force while a body in it spins is
/// solved again (`SPIN_TRUST`), keyed by that body: (time in the step, body).
#[derive(Clone, Debug, Default)]
pub(crate) struct SpinResolves(pub Vec<(f64, usize)>);

impl SpinResolves {
    /// Schedules the islands of a solve at `tau` that will turn past
    /// `SPIN_TRUST` before the step's end `h`; first drops what was due for
    /// the bodies just solved (`members`, sorted), whose forces are new.
    pub fn schedule(&mut self, solved: &Solved, members: &[usize], tau: f64, h: f64) {
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
    pub fn take(&mut self, i: usize) {
        self.0.retain(|&(_, j)| j != i);
    }

    /// The earliest due, if any: (time, body), each no earlier than
    /// `not_before` of its body.
    pub fn next(&self, not_before: impl Fn(usize) -> f64) -> Option<(f64, usize)> {
        self.0
            .iter()
            .map(|&(at, i)| (at.max(not_before(i)), i))
            .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
    }

    /// Puts body `i`'s re-solve back, due at `at`.
    pub fn defer(&mut self, i: usize, at: f64) {
        self.take(i);
        self.0.push((at, i));
    }
}

/// Which bodies got their segment's forces from one contact solve (an
/// island of two or more moving bodies), as of the latest solve of each.
#[derive(Clone, Debug)]
pub(crate) struct SolvedTogether {
    island: Vec<usize>,
    members: Vec<Vec<usize>>,
}

impl SolvedTogether {
    pub fn new(n: usize) -> Self {
        SolvedTogether {
            island: vec![usize::MAX; n],
            members: Vec::new(),
        }
    }

    /// Records islands solved together (bodies of each, local indices).
    pub fn record_islands(&mut self, islands: Vec<Vec<usize>>) {
        for bodies in islands {
            for &i in &bodies {
                self.island[i] = self.members.len();
            }
            self.members.push(bodies);
        }
    }

    pub fn record(&mut self, solved: &Solved) {
        self.record_islands(solved.together.clone());
    }

    /// The bodies solved with `i` in its latest solve (itself included).
    pub fn partners(&self, i: usize) -> &[usize] {
        self.members
            .get(self.island[i])
            .map(Vec::as_slice)
            .unwrap_or(&[])
    }
}

/// Angle (radians) a body may turn on the constant forces of one contact
/// solve before its island is solved again. The resting solve predicts each
/// contact's motion to second order (Baraff's curvature term); what it
/// leaves is of third order in ω·h, and for fast spinners it adds energy or
/// lets a corner sink. At 0.05 rad the third-order slip is about r·θ³/6,
/// 2 µm on a 0.1 m lever.
pub const SPIN_TRUST: f64 = 0.05;
/// At most this many such re-solves of one island in a step (the shortest
/// interval between two is dt divided by this).
pub const MAX_SPIN_RESOLVES_PER_STEP: f64 = 8.0;

/// A contact point of an island task: its body pair and where it is in A's
/// body frame (the key its resting force is kept under for the warm start).
type ContactWhere = ((BodyId, BodyId), Vector3<f64>);

/// A point of a new contact takes the warm start of the nearest point of the
/// pair's last solve within this share of A's outer radius (resting
/// contacts move by far less than this in a step; a point farther away is a
/// new one and starts from zero).
const WARM_MATCH: f64 = 0.05;

/// The touching pairs' points to solve (a pair with near points takes the
/// ones its island keeps, `solved_points`), and which pairs have any
/// (`touching_index[link]`: the pair of each link the islands are built of).
struct PointsToSolve<'t> {
    touching: &'t [Touching],
    points: Vec<Vec<ContactPoint>>,
    touching_index: Vec<usize>,
}

/// A contact phase's islands (bodies, contact links) and, per island, its
/// task and what its answer is written back with.
struct BuiltIslands {
    islands: Vec<(Vec<BodyId>, Vec<usize>)>,
    tasks: Vec<IslandTask>,
    /// Per island, each contact's pair and point in A's body frame.
    contact_pairs: Vec<Vec<ContactWhere>>,
    /// Per island, which of its contacts are speculative.
    near_flags: Vec<Vec<bool>>,
    /// Per island, its bodies' local indices (tasks carry world ids).
    locals: Vec<Vec<BodyId>>,
}

impl Region<'_> {
    /// Islands of the given contacts, solved; applies impulses to the segment
    /// start states of `members` and sets their forces for the rest of the step.
    pub(crate) fn contact_phase(
        &mut self,
        exec: &mut dyn Executor,
        touching: &[Touching],
        members: &[usize],
        seg: &mut [Segment],
        h: f64,
    ) -> Solved {
        let timer = self.stage.start(Stage::BuildIslands);
        let BuiltIslands {
            islands,
            tasks,
            contact_pairs,
            near_flags,
            locals,
        } = self.build_island_tasks(touching, members, seg, h);
        self.stage.stop(timer);
        // Kept for the caller to write (`--capture-islands`), in no stage's time.
        if let Some(min_rows) = self.st.step_settings.capture_min_rows {
            let large = tasks.iter().filter(|t| t.rows() >= min_rows);
            self.gathered.captured.extend(large.cloned());
        }

        let timer = self.stage.start(Stage::SolveIslands);
        let results = if self.keep_answers {
            solve_again_or_anew(exec, tasks)
        } else {
            exec.solve_islands(tasks)
        };
        self.keep_warm_starts(&contact_pairs, &near_flags, &results);
        self.apply_impulses(&locals, &results, members, seg);
        self.stage.stop(timer);
        self.solved(&islands, &results, members, seg)
    }

    /// The islands of the touching contacts among `members` and their
    /// tasks (`build_islands`), counted.
    fn build_island_tasks(
        &mut self,
        touching: &[Touching],
        members: &[usize],
        seg: &[Segment],
        h: f64,
    ) -> BuiltIslands {
        let n = self.bodies.len();
        // Island sizes matter only to near points (none in the exact model).
        let piles = touching
            .iter()
            .any(|t| !t.near.is_empty())
            .then(|| PileSizes::of(self, touching, members));
        let points: Vec<Vec<ContactPoint>> = touching
            .iter()
            .map(|t| match &piles {
                Some(piles) if !t.near.is_empty() => self.solved_points(t, seg, piles, h),
                _ => t.points.clone(),
            })
            .collect();
        let links: Vec<(BodyId, BodyId)> = touching
            .iter()
            .zip(&points)
            .filter(|(_, p)| !p.is_empty())
            .map(|(t, _)| (t.a, t.b))
            .collect();
        let touching_index: Vec<usize> = (0..touching.len())
            .filter(|&k| !points[k].is_empty())
            .collect();
        let islands = island::build_islands(n, &links, |b| {
            let i = b.index();
            self.bodies[i].is_dynamic() && self.moving(i) && members.binary_search(&i).is_ok()
        });
        let restitution_threshold = self.st.settings.restitution_threshold();
        let contacts_of = PointsToSolve {
            touching,
            points,
            touching_index,
        };
        let mut built = BuiltIslands {
            tasks: Vec::with_capacity(islands.len()),
            contact_pairs: Vec::with_capacity(islands.len()),
            near_flags: Vec::with_capacity(islands.len()),
            locals: Vec::with_capacity(islands.len()),
            islands: Vec::new(),
        };
        for (bodies, contact_ids) in &islands {
            let (index, contacts, pairs_here) =
                self.island_contacts(bodies, contact_ids, &contacts_of, seg);
            let bodies = self.island_bodies(&index, members, seg, h);
            self.counters.contacts += contacts.len() as u64;
            built
                .near_flags
                .push(contacts.iter().map(|c| c.near).collect());
            built.contact_pairs.push(pairs_here);
            built.locals.push(index);
            built.tasks.push(IslandTask {
                bodies,
                contacts,
                dt: h,
                restitution_threshold,
                iterative_min_rows: self.st.step_settings.iterative_min_rows as u32,
                island_blocks: self.st.settings.island_blocks,
            });
        }
        self.counters.islands += built.tasks.len() as u64;
        built.islands = islands;
        built
    }

    /// An island's bodies (its own, then the others its contacts reach, by
    /// local index) and its contacts, each with its pair and its point in
    /// A's body frame, warm-started from the pair's last solve.
    fn island_contacts(
        &mut self,
        bodies: &[BodyId],
        contact_ids: &[usize],
        contacts_of: &PointsToSolve,
        seg: &[Segment],
    ) -> (Vec<BodyId>, Vec<IslandContact>, Vec<ContactWhere>) {
        let (touching, points) = (contacts_of.touching, &contacts_of.points);
        let mut pairs_here = Vec::new();
        let mut index: Vec<BodyId> = bodies.to_vec();
        let mut contacts = Vec::new();
        for &ci in contact_ids {
            let ci = contacts_of.touching_index[ci];
            let t = &touching[ci];
            for id in [t.a, t.b] {
                if !index.contains(&id) {
                    index.push(id);
                }
            }
            let ia = index.iter().position(|&x| x == t.a).unwrap() as u32;
            let ib = index.iter().position(|&x| x == t.b).unwrap() as u32;
            let (oa, ob) = (self.object(t.a.index()), self.object(t.b.index()));
            let rules = &self.st.settings;
            let frame_a = pose(&seg[t.a.index()].state).inverse();
            let mut last = if self.st.step_settings.warm_start {
                self.warm.get(&(t.a, t.b)).cloned().unwrap_or_default()
            } else {
                Vec::new()
            };
            let reach = WARM_MATCH * oa.outer_radius();
            if !t.points.is_empty() {
                self.counters.count_pair_points(t.points.len());
            }
            for (k, p) in points[ci].iter().enumerate() {
                let near = k >= t.points.len();
                let local = frame_a.transform_point(&p.point.into()).coords;
                // Each point of the last solve warms one new point at most.
                let nearest = last
                    .iter()
                    .enumerate()
                    .map(|(k, w)| (k, (w.local - local).norm()))
                    .filter(|&(_, d)| d <= reach)
                    .min_by(|x, y| x.1.total_cmp(&y.1))
                    .map(|(k, _)| last.swap_remove(k));
                let (warm_force, warm_friction, approach) = nearest
                    .map_or((0.0, Vector3::zeros(), 0.0), |w| {
                        (w.normal, w.friction, w.approach)
                    });
                pairs_here.push(((t.a, t.b), local));
                contacts.push(IslandContact {
                    a: ia,
                    b: ib,
                    point: p.point,
                    normal: p.normal,
                    restitution: rules
                        .restitution_rule
                        .combine(oa.restitution, ob.restitution),
                    // A speculative contact is frictionless: it pushes only where
                    // the gap would close past its target, and its friction rows
                    // would triple a pile's rows for a push that lasts a step.
                    friction: if near {
                        0.0
                    } else {
                        rules.friction_rule.combine(oa.friction, ob.friction)
                    },
                    separation: p.separation,
                    warm_force,
                    warm_friction,
                    turns: p.turns,
                    approach,
                    near,
                });
            }
        }
        (index, contacts, pairs_here)
    }

    /// An island's bodies as its task carries them (by world id): a body
    /// among `members` that moves takes impulses, every other is fixed.
    fn island_bodies(
        &self,
        index: &[BodyId],
        members: &[usize],
        seg: &[Segment],
        h: f64,
    ) -> Vec<IslandBody> {
        index
            .iter()
            .map(|id| {
                let i = id.index();
                let b = &self.bodies[i];
                let o = self.object(i);
                let s = &seg[i];
                let dynamic = b.is_dynamic() && self.moving(i) && members.binary_search(&i).is_ok();
                let body = self.body_at(i, s.state);
                let inv_inertia = if dynamic {
                    body.inv_inertia_world(o)
                } else {
                    nalgebra::Matrix3::zeros()
                };
                IslandBody {
                    id: BodyId(self.ids[i]),
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
            .collect()
    }

    /// Keeps each solved contact's resting force under its pair and point
    /// (the next solve's warm start), each pair's total force, and the
    /// pairs a speculative contact pushed on.
    fn keep_warm_starts(
        &mut self,
        contact_pairs: &[Vec<ContactWhere>],
        near_flags: &[Vec<bool>],
        results: &[IslandResult],
    ) {
        let mut pair_forces: BTreeMap<(BodyId, BodyId), f64> = Default::default();
        for ((pairs, near), r) in contact_pairs.iter().zip(near_flags).zip(results) {
            for (pair, _) in pairs {
                self.warm.remove(pair);
            }
            let pushed = (0..near.len()).filter(|&k| near[k] && r.pushed.get(k) == Some(&true));
            self.gathered
                .speculative_pushes
                .extend(pushed.map(|k| pairs[k].0));
            for ((((pair, local), f), friction), approach) in pairs
                .iter()
                .zip(&r.contact_force)
                .zip(&r.contact_friction)
                .zip(&r.carried)
            {
                *pair_forces.entry(*pair).or_default() += f;
                self.warm.entry(*pair).or_default().push(WarmContact {
                    local: *local,
                    normal: *f,
                    friction: *friction,
                    approach: *approach,
                });
            }
        }
        self.gathered.pair_forces.extend(pair_forces);
    }

    /// Applies the islands' impulses to the segment start states of
    /// `members` and adds their resting forces for the rest of the step.
    fn apply_impulses(
        &mut self,
        locals: &[Vec<BodyId>],
        results: &[IslandResult],
        members: &[usize],
        seg: &mut [Segment],
    ) {
        for (ids, r) in locals.iter().zip(results) {
            self.counters.solve.add(&r.stats);
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
    }

    /// What the solve of `islands` leaves for the rest of the step: who was
    /// solved together, and per island whose solve holds a resting force,
    /// its fastest spinner: that force is trusted for `SPIN_TRUST` of turn.
    fn solved(
        &self,
        islands: &[(Vec<BodyId>, Vec<usize>)],
        results: &[IslandResult],
        members: &[usize],
        seg: &[Segment],
    ) -> Solved {
        let spinning = islands
            .iter()
            .zip(results)
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
}

impl Region<'_> {
    /// Counts the pairs speculative contacts pushed on since the last count
    /// (`Counters::speculative_pushes`) and those of them that do not
    /// `touch` now (`speculative_ghosts`), and forgets them.
    pub(crate) fn count_speculative_ghosts(&mut self, touch: impl Fn(&(BodyId, BodyId)) -> bool) {
        let pushes = std::mem::take(&mut self.gathered.speculative_pushes);
        self.counters.speculative_pushes += pushes.len() as u64;
        self.counters.speculative_ghosts += pushes.iter().filter(|p| !touch(p)).count() as u64;
    }
}

/// The moving bodies of each contact island of the touching pairs, to tell
/// an approach inside a pile from one that stands alone
/// (`Settings::pile_bodies`).
struct PileSizes {
    /// Each body's island (a union–find root), if it takes part in islands.
    island: Vec<Option<u32>>,
    /// Moving bodies per island, by root.
    size: Vec<u32>,
}

impl PileSizes {
    fn of(w: &Region, touching: &[Touching], members: &[usize]) -> Self {
        let n = w.bodies.len();
        let joins =
            |i: usize| w.bodies[i].is_dynamic() && w.moving(i) && members.binary_search(&i).is_ok();
        let mut sets = island::DisjointSets::new(n);
        for t in touching.iter().filter(|t| t.touches()) {
            if joins(t.a.index()) && joins(t.b.index()) {
                sets.union(t.a.0, t.b.0);
            }
        }
        let island: Vec<Option<u32>> = (0..n)
            .map(|i| joins(i).then(|| sets.find(i as u32)))
            .collect();
        let mut size = vec![0u32; n];
        for r in island.iter().flatten() {
            size[*r as usize] += 1;
        }
        PileSizes { island, size }
    }

    /// Moving bodies in the islands of `a` and `b` together.
    fn pair_size(&self, a: BodyId, b: BodyId) -> u32 {
        match (self.island[a.index()], self.island[b.index()]) {
            (Some(ra), Some(rb)) if ra == rb => self.size[ra as usize],
            (ra, rb) => [ra, rb]
                .into_iter()
                .flatten()
                .map(|r| self.size[r as usize])
                .sum(),
        }
    }
}

impl Region<'_> {
    /// A pair's points for its contact solve over the interval `h`: its
    /// contacts, then those of its near points that may close within the
    /// interval and approach no faster than the speculative speed there
    /// (`Settings::slow_speed` anywhere, `speculative_speed` inside a
    /// pile). A faster approach is left to an exact impact event.
    fn solved_points(
        &self,
        t: &Touching,
        seg: &[Segment],
        piles: &PileSizes,
        h: f64,
    ) -> Vec<ContactPoint> {
        let mut points = t.points.clone();
        let settings = self.st.settings;
        // A body that turns more than `SPIN_TRUST` within the interval
        // moves its points off the straight lines a speculative row
        // predicts: its approaches stay exact events.
        let turns_fast = |i: usize| {
            self.body_at(i, seg[i].state)
                .angular_velocity(self.object(i))
                .norm()
                * h
                > SPIN_TRUST
        };
        if turns_fast(t.a.index()) || turns_fast(t.b.index()) {
            return points;
        }
        // Both bodies solved here, or one against a body that does not
        // move (fixed, or resting): a body that moves but is not solved
        // here (outside an impact's members, or driven) would push its
        // partner along a speculative row with nothing to give, against
        // whatever holds the partner (a nut between it and the floor took
        // 66 N·s).
        let held = |i: usize| piles.island[i].is_some() || !self.moving(i);
        if !(held(t.a.index()) && held(t.b.index())) {
            return points;
        }
        let in_pile = piles.pair_size(t.a, t.b) >= settings.pile_bodies;
        let limit = if in_pile {
            settings.speculative_speed().max(settings.slow_speed())
        } else {
            settings.slow_speed()
        };
        let reach = settings.gravity.norm() * h;
        let velocity_at = |i: usize, p: &Vector3<f64>| self.point_velocity(i, &seg[i].state, p);
        points.extend(t.near.iter().filter(|p| {
            let v = velocity_at(t.a.index(), &p.point) - velocity_at(t.b.index(), &p.point);
            let vn = p.normal.dot(&v);
            let may_close = p.separation - SPECULATIVE_GAP < (reach - vn) * h;
            vn >= -limit && may_close
        }));
        points
    }
}

/// Islands of this many contacts or more are kept by `solve_again_or_anew`
/// (below, a solve costs about what its bytes cost to hash).
const KEPT_MIN_CONTACTS: usize = 16;

/// The island solves of a split group's parts (`Region::keep_answers`,
/// `super::kept`): `solve_island` is a function of its task alone.
fn solve_again_or_anew(exec: &mut dyn Executor, tasks: Vec<IslandTask>) -> Vec<IslandResult> {
    use crate::contact::solver::IslandResult;
    thread_local! {
        static KEPT: std::cell::RefCell<Kept<IslandResult>> = Default::default();
    }
    let questions = tasks
        .iter()
        .map(|t| (t.contacts.len() >= KEPT_MIN_CONTACTS).then(|| kept::question(t)))
        .collect();
    kept::again_or_anew(
        &KEPT,
        tasks,
        questions,
        |tasks| exec.solve_islands(tasks),
        |r| 64 * (r.impulse.len() + r.contact_force.len()),
    )
}
