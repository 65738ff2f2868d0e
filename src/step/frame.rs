//! One step of the whole world, as SPEC 2.1's frame loop: each stage a
//! function of its own, in the order the step takes them.

use super::contact::SpinResolves;
use super::executor::{Executor, GroupOutput, PairKey, Segment, Since};
use super::group::{self, StepStart};
use super::region::{PairMap, Region};
use super::stats::{GroupWork, NumericalFailure, check_states};
use super::timers::Stage;
use super::toi::SolvedSince;
use super::touching::Touching;
use crate::body::{Activity, BodyId, BodyState};
use crate::collision::broadphase::SphereProxy;
use crate::collision::narrowphase::PairResult;
use nalgebra::Vector3;
use std::collections::BTreeSet;

/// What one step hands the next besides the bodies the region holds.
pub(super) struct Carried<'a> {
    /// The contacts touching at the step's end (the next step's islands).
    pub touching: &'a mut Vec<Touching>,
    /// Completed steps.
    pub steps: &'a mut u64,
    /// The deepest overlap committed so far.
    pub max_penetration: &'a mut f64,
    /// What each body's group took (the schedule's prediction of the next).
    pub work: &'a mut GroupWork,
}

/// One step of the whole world (`World::step`).
pub(super) fn step_world(
    w: &mut Region,
    exec: &mut dyn Executor,
    carried: Carried,
) -> Result<(), NumericalFailure> {
    let Carried {
        touching,
        steps,
        max_penetration,
        work,
    } = carried;
    let (h, t0) = (w.st.settings.dt, w.st.t0);
    w.wake_for_forces(t0, h);
    if *steps == 0 && touching.is_empty() {
        *touching = touching_at_start(w, exec);
    }
    // build_islands + solve_islands: impacts and resting forces of the
    // contacts touching now, for every moving body.
    let start_touching = std::mem::take(touching);
    let solved = solve_touching(w, exec, &start_touching)?;
    // integrate: every awake body along its segment to the step's end.
    let end = integrate(w, &solved.seg);
    // broadphase on the paths to the end of the step.
    let (pairs, proxies) = w.broadphase(&solved.seg, &end);
    // build_groups + narrowphase + time_of_impact, group by group: each
    // group tests its own pairs at the end of the step, then takes its
    // impacts. The stage time is the groups' wall time less the stages
    // they call (counted under theirs).
    let timer = w.stage.start(Stage::TimeOfImpact);
    let start = StepStart {
        seg: solved.seg,
        end,
        pairs,
        grown: grow(proxies, w.st.step_settings.group_margin),
        since: solved.since,
        separating: solved.separating,
        together: solved.together,
        spin_resolves: solved.spin_resolves,
        touching: start_touching
            .iter()
            .filter(|t| t.touches())
            .map(|t| (t.a.0, t.b.0))
            .collect(),
        body_cost: std::mem::take(&mut work.body_cost),
    };
    // What the groups' solves captured goes after the step-start solve's,
    // also when one of them fails.
    let mut captured = std::mem::take(&mut w.gathered.captured);
    let done = group::step_groups(w.st, w, &start, exec, &mut captured);
    w.gathered.captured = captured;
    let done = done?;
    let runs = done.runs;
    work.body_cost = start.body_cost.clone();
    for g in &runs {
        let members = g.bodies.iter().filter(|b| b.is_dynamic()).count().max(1);
        for (b, &id) in g.bodies.iter().zip(&g.ids) {
            if b.is_dynamic() {
                work.body_cost[id as usize] = g.busy_s / members as f64;
            }
        }
    }
    work.add_step(runs.iter().map(GroupOutput::seconds));
    let mut merged = merge_groups(w, runs, done.reruns);
    // The pairs between a split group's parts, which no part held, and
    // what its first stage and the checks between its parts counted.
    merged.pairs.extend(done.between);
    w.counters.add(&done.counters);
    w.stage
        .add(&done.stage, &[Stage::Narrowphase, Stage::Broadphase]);
    w.stage.stop(timer);
    // Commit the end states, the contacts touching now and the caches.
    *touching = commit(w, start.end, merged, max_penetration);
    count_start_ghosts(w, touching);
    *steps += 1;
    w.counters.steps += 1;
    check_states(
        w.bodies.iter().map(|b| &b.state).enumerate(),
        "integrate",
        t0 + h,
    )?;
    // Resting systems: wake the touched ones, rest and fall the others.
    w.wake_touched_at_end(touching);
    w.update_rest_and_falls(touching, h);
    Ok(())
}

/// Contacts touching at the very start (bodies placed in contact).
fn touching_at_start(w: &mut Region, exec: &mut dyn Executor) -> Vec<Touching> {
    let seg = segments(w);
    let now: Vec<BodyState> = seg.iter().map(|s| s.state).collect();
    let (pairs, _) = w.broadphase(&seg, &now);
    let results = w.narrowphase_at(exec, &pairs, &now);
    w.touching_from(&pairs, &results)
}

/// Each body's segment from its state at the step's start, with the
/// external forces then (constant over the step).
fn segments(w: &Region) -> Vec<Segment> {
    (0..w.bodies.len())
        .map(|i| {
            let (force, torque) = if w.bodies[i].is_dynamic() && w.moving(i) {
                w.external(i, w.st.t0)
            } else {
                (Vector3::zeros(), Vector3::zeros())
            };
            Segment {
                state: w.bodies[i].state,
                time: 0.0,
                force,
                torque,
            }
        })
        .collect()
}

/// Counts the step-start solve's speculative pushes and ghosts against the
/// contacts touching at the step's end; a group's own solves count theirs
/// at the group's end (`impacts::step_group`).
fn count_start_ghosts(w: &mut Region, touching: &[Touching]) {
    if w.gathered.speculative_pushes.is_empty() {
        return;
    }
    let touches: BTreeSet<(BodyId, BodyId)> = touching
        .iter()
        .filter(|t| t.touches())
        .map(|t| (t.a, t.b))
        .collect();
    w.count_speculative_ghosts(|pair| touches.contains(pair));
}

/// What the step's contact solve leaves for the rest of the step.
struct SolvedStart {
    seg: Vec<Segment>,
    since: SolvedSince,
    separating: PairMap<Vector3<f64>>,
    together: Vec<Vec<usize>>,
    spin_resolves: SpinResolves,
}

/// The contact solve of the islands touching at the step's start.
fn solve_touching(
    w: &mut Region,
    exec: &mut dyn Executor,
    touching: &[Touching],
) -> Result<SolvedStart, NumericalFailure> {
    let h = w.st.settings.dt;
    let mut seg = segments(w);
    let since: SolvedSince = touching
        .iter()
        .map(|t| {
            let deepest = t.points.iter().map(|p| -p.separation).fold(0.0, f64::max);
            let since = Since {
                time: 0.0,
                deepest,
                touched: !t.points.is_empty(),
            };
            ((t.a.0, t.b.0), since)
        })
        .collect();
    let all_moving: Vec<usize> = (0..w.bodies.len()).filter(|&i| w.moving(i)).collect();
    let solved = w.contact_phase(exec, touching, &all_moving, &mut seg, h);
    let mut spin_resolves = SpinResolves::default();
    spin_resolves.schedule(&solved, &all_moving, 0.0, h);
    check_states(
        seg.iter().map(|s| &s.state).enumerate(),
        "solve_islands",
        w.st.t0,
    )?;
    // Pairs touching now or hit during the last step ("colliding in the
    // previous frame") that now separate.
    let previous_impacts = std::mem::take(w.impacts);
    let mut separating = w.separating_pairs(&previous_impacts, &seg);
    separating.extend(w.separating_pairs(touching, &seg));
    Ok(SolvedStart {
        seg,
        since,
        separating,
        together: solved.together,
        spin_resolves,
    })
}

/// Every awake body to the end of the step along its segment.
fn integrate(w: &mut Region, seg: &[Segment]) -> Vec<BodyState> {
    let timer = w.stage.start(Stage::Integrate);
    let h = w.st.settings.dt;
    let mut end: Vec<BodyState> = seg.iter().map(|s| s.state).collect();
    let mut moving = 0u64;
    for i in 0..w.bodies.len() {
        if w.moving(i) {
            end[i] = w.integrate_segment(i, &seg[i], h);
            moving += 1;
        }
    }
    w.counters.integrations += moving;
    w.counters.integrations_skipped_resting += w
        .bodies
        .iter()
        .filter(|b| b.activity == Activity::Sleeping)
        .count() as u64;
    w.stage.stop(timer);
    end
}

/// The predicted spheres grown by the group margin, as the groups are formed.
fn grow(proxies: Vec<SphereProxy>, margin: f64) -> Vec<SphereProxy> {
    proxies
        .into_iter()
        .map(|p| SphereProxy {
            radius: p.radius * (1.0 + margin),
            ..p
        })
        .collect()
}

/// What the groups leave for `commit`, in world ids.
struct Merged {
    /// End state of each of the groups' dynamic bodies.
    ends: Vec<(usize, BodyState)>,
    /// Every group's pairs with their final results.
    pairs: Vec<(PairKey, PairResult)>,
}

/// Takes each group's results into the world, in group-id order: its
/// bodies' activity, warm starts, impacts, forces, counters and stage
/// times now; its end states and pairs for `commit`.
fn merge_groups(w: &mut Region, runs: Vec<GroupOutput>, reruns: u64) -> Merged {
    let mut merged = Merged {
        ends: Vec::new(),
        pairs: Vec::new(),
    };
    let mut events = 0u64;
    w.counters.groups += runs.len() as u64;
    w.counters.group_reruns += reruns;
    for g in runs {
        let ids = &g.ids;
        let mut size = 0u64;
        for (i, &id) in ids.iter().enumerate() {
            if !g.bodies[i].is_dynamic() {
                continue;
            }
            let wi = id as usize;
            size += u64::from(g.bodies[i].activity == Activity::Awake);
            w.bodies[wi].activity = g.bodies[i].activity;
            w.sleep_timer[wi] = g.sleep_timer[i];
            merged.ends.push((wi, g.end[i]));
        }
        w.counters.largest_group = w.counters.largest_group.max(size);
        let world_key = |(a, b): PairKey| (ids[a as usize], ids[b as usize]);
        merged
            .pairs
            .extend(g.pairs.iter().map(|&k| world_key(k)).zip(g.results));
        w.warm
            .extend(g.warm.into_iter().map(|e| group::to_world_warm(ids, e)));
        w.impacts.extend(
            g.impacts
                .into_iter()
                .map(|t| group::to_world_touching(ids, t)),
        );
        w.gathered.pair_forces.extend(
            g.pair_forces
                .into_iter()
                .map(|((a, b), f)| ((BodyId(ids[a.index()]), BodyId(ids[b.index()])), f)),
        );
        w.counters.add(&g.counters);
        // Not its time of impact: the step's own timer holds that.
        w.stage.add(
            &g.stage,
            &[
                Stage::Broadphase,
                Stage::Narrowphase,
                Stage::BuildIslands,
                Stage::SolveIslands,
                Stage::Integrate,
            ],
        );
        events += g.events;
    }
    w.counters.max_events_in_step = w.counters.max_events_in_step.max(events);
    if events > 0 {
        w.counters.steps_with_events += 1;
    }
    merged
}

/// The step's end: every awake body takes its end state (a group's, or
/// its prediction when it was in none), and the pairs' final results give
/// the deepest overlap, V-Clip's feature caches and the contacts touching
/// now, which are returned.
fn commit(
    w: &mut Region,
    mut end: Vec<BodyState>,
    merged: Merged,
    max_penetration: &mut f64,
) -> Vec<Touching> {
    for (i, state) in merged.ends {
        end[i] = state;
    }
    for (b, e) in w.bodies.iter_mut().zip(&end) {
        if b.activity == Activity::Awake {
            b.state = *e;
        }
    }
    // Every tested pair has a dynamic body, and so a group: the groups'
    // pairs are all of them.
    let mut all = merged.pairs;
    all.sort_unstable_by_key(|(k, _)| *k);
    for (k, r) in &all {
        *max_penetration = max_penetration.max(r.depth);
        if !r.features.is_empty() {
            w.features.insert(*k, r.features.clone());
        }
    }
    let (keys, results): (Vec<PairKey>, Vec<PairResult>) = all.into_iter().unzip();
    let touching = w.touching_from(&keys, &results);
    let touching_pairs: BTreeSet<(BodyId, BodyId)> = touching.iter().map(|t| (t.a, t.b)).collect();
    w.warm.retain(|k, _| touching_pairs.contains(k));
    touching
}
