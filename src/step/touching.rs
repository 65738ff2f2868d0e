//! What the contact solve works from and leaves behind, pair by pair: the
//! touching pairs with their points, and the resting forces kept for the
//! next solve's warm start.

use crate::body::BodyId;
use crate::collision::manifold::ContactPoint;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Contacts of one touching body pair at the current time, and its points
/// apart by more than the contact tolerance but near enough to close within
/// a step at the speculative speed (`Settings::near_distance`): the
/// speculative contacts of the contact solve. A pair may have only those.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) struct Touching {
    pub(crate) a: BodyId,
    pub(crate) b: BodyId,
    pub(crate) points: Vec<ContactPoint>,
    pub(crate) near: Vec<ContactPoint>,
}

impl Touching {
    /// Whether the pair touches (within the contact tolerance), not only
    /// comes near: what wakes, sleeps and groups bodies together.
    pub(crate) fn touches(&self) -> bool {
        !self.points.is_empty()
    }
}

/// The resting force one contact point held in the last solve of its pair:
/// where (in A's body frame) and how much. The next solve of the pair starts
/// its iterative solve from these (`IslandContact::warm_force`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct WarmContact {
    pub(crate) local: Vector3<f64>,
    pub(crate) normal: f64,
    pub(crate) friction: Vector3<f64>,
    /// The approach a speculative contact here deferred (`IslandResult::carried`).
    pub(crate) approach: f64,
}
