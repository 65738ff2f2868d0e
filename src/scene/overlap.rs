//! Bodies placed inside each other (issue 23). The step lets bodies touch
//! within the contact tolerance; a scene that starts with two bodies
//! overlapping by more is bad input, not a run that starts by flinging them
//! apart (or silently carries the overlap to the end).
//!
//! Every pair with a dynamic body is tested, as the step tests pairs: a
//! sort and sweep over the bodies' bounding spheres grown by the contact
//! tolerance (`broadphase::candidate_pairs`, O(n log n)), then the parts'
//! world boxes (a pair overlapping by more than the tolerance has a part of
//! each whose boxes overlap; scattered bodies never do, see `scatter`), and
//! for what is left the step's own narrowphase (`narrowphase::query_pair`),
//! judged as the time of impact judges an overlap
//! (`PairResult::needs_rollback`).

use super::{boxes_overlap, part_boxes};
use crate::body::{Body, BodyId, ObjectDef};
use crate::collision::broadphase::{self, SphereProxy};
use crate::collision::narrowphase::{self, CONTACT_TOLERANCE, PairTask};

/// Two bodies, `a < b` in scene order, that overlap by `depth` metres.
pub(super) struct StartOverlap {
    pub a: usize,
    pub b: usize,
    pub depth: f64,
}

/// The first pair in body order that overlaps by more than the contact
/// tolerance, if any. Pairs of two fixed or driven bodies are not tested:
/// the step never tests them either (walls meeting at a corner).
pub(super) fn first_overlap(bodies: &[Body], objects: &[ObjectDef]) -> Option<StartOverlap> {
    let object = |i: usize| &objects[bodies[i].object.0 as usize];
    let proxies: Vec<SphereProxy> = bodies
        .iter()
        .enumerate()
        .flat_map(|(i, b)| {
            object(i).spheres.iter().map(move |s| SphereProxy {
                body: i as u32,
                center: b.state.position + b.state.orientation * s.center,
                radius: s.radius + CONTACT_TOLERANCE,
            })
        })
        .collect();
    let pairs = broadphase::candidate_pairs(&proxies, |a, b| {
        bodies[a as usize].is_dynamic() || bodies[b as usize].is_dynamic()
    });
    for (a, b) in pairs {
        let (a, b) = (a as usize, b as usize);
        let (oa, ob) = (object(a), object(b));
        if !boxes_overlap(&part_boxes(oa, &bodies[a]), &part_boxes(ob, &bodies[b])) {
            continue;
        }
        let task = PairTask {
            a: BodyId(a as u32),
            b: BodyId(b as u32),
            object_a: bodies[a].object.0,
            object_b: bodies[b].object.0,
            pose_a: bodies[a].pose(),
            pose_b: bodies[b].pose(),
            warm: Vec::new(),
            contact_tolerance: CONTACT_TOLERANCE,
            near_distance: 0.0,
        };
        let r = narrowphase::query_pair(objects, &task);
        if r.needs_rollback(CONTACT_TOLERANCE) {
            // The contact points' depth, as the step measures it; V-Clip's
            // own (local) estimate when the overlap gave no points.
            let depth = if r.contacts.is_empty() {
                -r.distance
            } else {
                r.depth
            };
            return Some(StartOverlap { a, b, depth });
        }
    }
    None
}
