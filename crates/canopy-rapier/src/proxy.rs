//! A proxy: what the broadphase keeps per collider (its handle, fat box, filter inputs, and
//! where it sits in the trees).

use crate::filter::{FilterData, Mobility};
use canopy_core::Aabb;
use rapier3d::prelude::ColliderHandle;

/// Where a proxy is stored in the tree of its mobility.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Loc {
    /// Leaf `slot` of the tree's BVH.
    Tree(u32),
    /// Entry of the tree's pending list, not in the BVH yet.
    Pending(u32),
    /// In no tree (its box is invalid).
    Out,
}

/// 64 bytes, aligned to 64: each proxy is one cache line (at 68 bytes every proxy straddled
/// two, and the examine loop and the queries' callbacks read them at random).
#[derive(Clone, Debug)]
#[repr(align(64))]
pub(crate) struct Proxy {
    pub handle: ColliderHandle,
    /// The box stored in the tree: the exact box enlarged by the margin.
    pub fat: Aabb,
    pub filter: FilterData,
    pub mobility: Mobility,
    pub loc: Loc,
    /// In the move buffer this step.
    pub moved: bool,
    /// Moved this step only because its exact box left its fat box (`refatten`): its filter
    /// and tree are unchanged, so its candidates' filters need no new check from its side.
    pub box_only: bool,
}

impl Proxy {
    pub fn is_valid(&self) -> bool {
        self.loc != Loc::Out
    }
}

const _: () = assert!(std::mem::size_of::<Option<Proxy>>() == 64);
