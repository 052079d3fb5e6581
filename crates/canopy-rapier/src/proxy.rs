//! A proxy: what the broadphase keeps per collider. The record the examine loop streams
//! ([`Proxy`]: the handle's generation, the fat box, the filter inputs) and, apart from it,
//! where the proxy sits in the trees and its flags for the current update ([`Place`]).

use crate::filter::{FilterData, Mobility};
use canopy_core::Aabb;
use rapier3d::prelude::ColliderHandle;

/// Where a proxy is stored in the tree of its mobility.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Loc {
    /// Leaf `slot` of the tree's BVH.
    Tree(u32),
    /// Entry of the tree's pending list, not in the BVH yet.
    Pending(u32),
    /// In no tree (no proxy, or its box is invalid).
    #[default]
    Out,
}

/// 48 bytes: the examine loop reads one per modified collider, front to back, and its time
/// in `balls` follows the bytes it streams (records padded from 64 to 80 bytes made it 3.2%
/// slower, to 96 bytes 5.7%, to 128 bytes 9.3%; `docs/performance-log.md`, stops 44 and
/// 45). So only what that loop needs is here; the tree location and the update's flags are
/// in [`Place`].
#[derive(Clone, Debug)]
pub(crate) struct Proxy {
    /// The collider handle's generation; its index is the proxy id.
    pub generation: u32,
    /// The box stored in the tree: the exact box enlarged by the margin. [`Aabb::EMPTY`]
    /// while the proxy is in no tree (its exact or fat box is invalid): see [`Proxy::is_valid`].
    pub fat: Aabb,
    /// The pair filter's inputs; the body type also says which tree the proxy is filed in.
    pub filter: FilterData,
}

impl Proxy {
    /// The collider handle of proxy `id`.
    #[inline]
    pub fn handle(&self, id: u32) -> ColliderHandle {
        ColliderHandle::from_raw_parts(id, self.generation)
    }

    /// `true` when this proxy is `handle`'s (whose index is this proxy's id), not that of an
    /// earlier collider at the same index.
    #[inline]
    pub fn is_for(&self, handle: ColliderHandle) -> bool {
        self.generation == handle.into_raw_parts().1
    }

    /// In a tree: its fat box is valid. Invalid proxies keep [`Aabb::EMPTY`], whose minimum
    /// is above its maximum (and a NaN compares false), so one comparison tells.
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.fat.min.x <= self.fat.max.x
    }

    /// The tree it is filed in: that of its filter's body type.
    #[inline]
    pub fn mobility(&self) -> Mobility {
        Mobility::of(self.filter.body_type)
    }
}

const _: () = assert!(std::mem::size_of::<Option<Proxy>>() == 48);

/// Per proxy id, beside the records: where the proxy is in its tree and its flags for the
/// current update. Read by the tree bookkeeping and the searches, not by the examine loop's
/// fast path.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Place {
    pub loc: Loc,
    /// In the move buffer this update.
    pub moved: bool,
    /// Moved this update only because its exact box left its fat box (`refatten`): its filter
    /// and tree are unchanged, so its candidates' filters need no new check from its side.
    pub box_only: bool,
}
