//! Restitution at an impact: which contacts bounce (Newton's law over a
//! whole contact patch), from which approach (their own, or the one a
//! speculative contact deferred), and the approach a speculative contact
//! carries to the step where its bodies meet.

use super::task::{IslandContact, IslandTask, SPECULATIVE_GAP, closing_allowed};
use crate::collision::patch::same_normal;

/// The normal speed at which a speculative contact's gap, closing at `vn`
/// under the external forces' acceleration alone, would have closed to
/// `SPECULATIVE_GAP`: the approach its deferred bounce restitutes from.
/// `external_vn` is the change of its normal speed the external forces
/// alone give over the step.
pub(super) fn meeting_speed(
    task: &IslandTask,
    c: &IslandContact,
    vn: f64,
    external_vn: f64,
) -> f64 {
    let closing_accel = (-external_vn / task.dt).max(0.0);
    let gap = (c.separation - SPECULATIVE_GAP).max(0.0);
    -(vn * vn + 2.0 * closing_accel * gap).sqrt()
}

/// The normal speed a touching contact's impact restitutes from: its own
/// `vn`, or the approach a speculative contact deferred (`approach`) where
/// that was faster. Speculative contacts do not bounce.
pub(super) fn bounce_basis(c: &IslandContact, vn: f64, task: &IslandTask) -> f64 {
    if closing_allowed(c, task.dt) > 0.0 {
        0.0
    } else if c.approach < 0.0 && c.approach < vn {
        c.approach
    } else {
        vn
    }
}

/// Per contact, whether Newton's law applies at its impact: where any
/// touching point of its contact patch approaches faster than the
/// restitution threshold, every touching point of the patch restitutes from
/// its own approach. A patch is one contact: one rule over it keeps its rows
/// affine in the point, so the hull of its points (`collision::patch`)
/// answers as all of them do. A patch: consecutive contacts of one pair
/// whose normals agree (`patch::same_normal`), as the narrowphase gives
/// them. `speeds` are the contacts' normal speeds.
pub(super) fn patches_that_bounce(task: &IslandTask, speeds: &[f64]) -> Vec<bool> {
    let fast: Vec<bool> = task
        .contacts
        .iter()
        .zip(speeds)
        .map(|(c, &vn)| {
            closing_allowed(c, task.dt) == 0.0
                && bounce_basis(c, vn, task) < -task.restitution_threshold
        })
        .collect();
    let mut bounces = vec![false; fast.len()];
    let mut start = 0;
    while start < fast.len() {
        let first = &task.contacts[start];
        let end = (start + 1..fast.len())
            .find(|&k| {
                let c = &task.contacts[k];
                (c.a, c.b) != (first.a, first.b) || !same_normal(&c.normal, &first.normal)
            })
            .unwrap_or(fast.len());
        let any = fast[start..end].iter().any(|&f| f);
        for (bounce, c) in bounces[start..end]
            .iter_mut()
            .zip(&task.contacts[start..end])
        {
            *bounce = any && closing_allowed(c, task.dt) == 0.0;
        }
        start = end;
    }
    bounces
}
