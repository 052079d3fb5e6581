//! [`BroadPhaseStats`]: counts that tell what the broadphase did and holds.

/// What [`crate::CanopyBroadPhase`] holds and what its last update did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BroadPhaseStats {
    /// Colliders in the fixed, kinematic and dynamic trees (including pending ones).
    pub proxies: [usize; 3],
    /// Colliders left out of the trees because their box has a NaN or infinite coordinate.
    /// They come back as soon as their box is valid again.
    pub invalid: usize,
    /// Live pairs: reported to Rapier, exact collision boxes overlapping.
    pub pairs: usize,
    /// Candidate pairs: fat boxes overlapping (a superset of the live pairs).
    pub candidates: usize,
    /// Proxies whose fat box or filter changed in the last update (the move buffer).
    pub moved: usize,
    /// The last update found the moved proxies' pairs by walking whole trees (marked pair
    /// walks, taken when many proxies moved), not by one box query per moved proxy.
    pub walked: bool,
    /// `AddPair` events of the last update.
    pub added: usize,
    /// `DeletePair` events of the last update.
    pub deleted: usize,
    /// Colliders examined in the last update whose loosening, contact skin plus half the
    /// prediction distance, was negative or NaN (parry refuses it: Rapier's own broadphase
    /// panics). Their box is their shape's box, not loosened; they keep all their pairs.
    pub negative_loosening: usize,
    /// Tree rebuilds since creation (all trees).
    pub rebuilds: u64,
    /// Tree refits since creation (all trees).
    pub refits: u64,
}
