//! `UpdateStats`: what the last update did and how long each phase took.

use std::time::Duration;

/// Counters and timings of the last [`crate::CollisionWorld::update`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UpdateStats {
    /// Time spent on boxes, the object BVH and candidate pairs.
    pub broad_phase: Duration,
    /// Time spent on contact manifolds (pairs and deformable self-collision).
    pub narrow_phase: Duration,
    /// Candidate pairs (overlapping loosened boxes).
    pub candidate_pairs: usize,
    /// Pairs with at least one contact point.
    pub contact_pairs: usize,
    /// Self-contacts of deformable meshes.
    pub self_contacts: usize,
    /// Whether the object BVH was rebuilt (objects inserted or removed) rather than refit.
    pub rebuilt: bool,
}
