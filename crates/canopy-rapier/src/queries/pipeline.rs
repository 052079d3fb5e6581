//! Rapier's own `QueryPipeline` over a canopy broadphase, for code written against it (the
//! kinematic character controller, user code): a parry [`Bvh`] over the proxies' fat boxes,
//! keyed by collider index as Rapier's pipeline expects, brought in sync only when
//! [`CanopyBroadPhase::as_query_pipeline`] is called. The broadphase records which proxies
//! changed since (a list and a bitmap, kept only once the mirror exists); the sync updates
//! those leaves, refits, and lets parry's incremental optimisation improve a part of the tree.

use crate::broad_phase::CanopyBroadPhase;
use rapier3d::parry::partitioning::{Bvh, BvhBuildStrategy, BvhWorkspace};
use rapier3d::parry::query::QueryDispatcher;
use rapier3d::prelude::{
    Aabb, ColliderHandle, ColliderSet, QueryFilter, QueryPipeline, RigidBodySet,
};
use rustc_hash::FxHashMap;

/// Margin of parry's change detection for updated leaves (Rapier's own value for length
/// unit 1): a leaf is stored this much larger than the fat box.
const CHANGE_MARGIN: f32 = 1.0e-2;

/// A mirror with at most this many leaves after a sync's changes is rebuilt rather than
/// optimised (see `sync_query_pipeline`).
const SMALL_TREE: u32 = 32;

/// The parry BVH behind `as_query_pipeline` and the proxies changed since it was synced.
#[derive(Clone, Default)]
pub(crate) struct QueryMirror {
    bvh: Bvh,
    workspace: BvhWorkspace,
    /// Whether the mirror exists (it is built on the first `as_query_pipeline`).
    active: bool,
    /// The box stored per leaf (collider index), to skip unchanged leaves.
    leaves: Vec<Option<Aabb>>,
    dirty: Vec<u32>,
    is_dirty: Vec<bool>,
}

impl std::fmt::Debug for QueryMirror {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("QueryMirror")
            .field("active", &self.active)
            .field("leaves", &self.bvh.leaf_count())
            .field("dirty", &self.dirty.len())
            .finish()
    }
}

impl QueryMirror {
    /// Records that proxy `id` (or the collider of that index) changed.
    #[inline]
    pub fn touch(&mut self, id: u32) {
        if !self.active {
            return;
        }
        let i = id as usize;
        if i >= self.is_dirty.len() {
            self.is_dirty.resize(i + 1, false);
        }
        if !self.is_dirty[i] {
            self.is_dirty[i] = true;
            self.dirty.push(id);
        }
    }

    pub fn touch_all(&mut self, ids: &[u32]) {
        for &id in ids {
            self.touch(id);
        }
    }
}

impl CanopyBroadPhase {
    /// The box the mirror should hold for collider index `id`: the proxy's fat box when it is
    /// current, else the collider's current box when it was edited since the last update, if
    /// that box is valid by the test `refresh_queries` makes. (The collider may have been
    /// edited again since `refresh_queries` checked it; a NaN box would make parry's tree
    /// panic, and a collider with no valid box is left out of the queries, as it is out of the
    /// broadphase's trees.)
    fn mirror_box(
        &self,
        id: u32,
        colliders: &ColliderSet,
        extra: &FxHashMap<u32, ColliderHandle>,
    ) -> Option<Aabb> {
        if !self.overlay.is_stale(id) {
            if let Some(p) = self.proxies.get(id as usize).and_then(Option::as_ref) {
                if p.is_valid() {
                    return Some(Aabb::new(p.fat.min, p.fat.max));
                }
            }
        }
        colliders
            .get(*extra.get(&id)?)
            .map(|c| c.compute_aabb())
            .filter(|b| canopy_core::Aabb::new(b.mins, b.maxs).is_valid())
    }

    /// Rapier's own `QueryPipeline` (as `BroadPhaseBvh::as_query_pipeline` returns it) over
    /// this broadphase, so that code written for Rapier's pipeline, like
    /// `KinematicCharacterController::move_shape`, works unchanged. It reads a parry BVH that
    /// this call first brings in sync with the broadphase: built on the first call, then
    /// updated only where proxies changed since the previous call. For canopy's own faster
    /// queries, see [`Self::scene_queries`].
    ///
    /// ```
    /// use canopy_rapier::CanopyBroadPhase;
    /// use rapier3d::control::KinematicCharacterController;
    /// use rapier3d::prelude::*;
    ///
    /// let bodies = RigidBodySet::new();
    /// let mut colliders = ColliderSet::new();
    /// colliders.insert(ColliderBuilder::cuboid(10.0, 0.1, 10.0));
    /// let mut broad_phase = CanopyBroadPhase::new();
    /// broad_phase.refresh_queries(&colliders);
    /// let narrow_phase = NarrowPhase::new();
    /// let pipeline = broad_phase.as_query_pipeline(
    ///     narrow_phase.query_dispatcher(), &bodies, &colliders, QueryFilter::default());
    /// let controller = KinematicCharacterController::default();
    /// let capsule = Capsule::new_y(0.5, 0.3);
    /// let movement = controller.move_shape(
    ///     1.0 / 60.0, &pipeline, &capsule, &Isometry::translation(0.0, 1.0, 0.0),
    ///     vector![0.0, -2.0, 0.0], |_| {});
    /// // The floor (top at 0.1) stops the fall of the capsule (bottom at 0.2): about 0.1 down.
    /// assert!(movement.translation.y < 0.0 && movement.translation.y > -0.15);
    /// ```
    pub fn as_query_pipeline<'a>(
        &'a mut self,
        dispatcher: &'a dyn QueryDispatcher,
        bodies: &'a RigidBodySet,
        colliders: &'a ColliderSet,
        filter: QueryFilter<'a>,
    ) -> QueryPipeline<'a> {
        self.sync_query_pipeline(colliders);
        self.query_pipeline(dispatcher, bodies, colliders, filter)
    }

    /// Rapier's `QueryPipeline` over the parry BVH as [`Self::sync_query_pipeline`] last left
    /// it, through a shared borrow (so that it can be used beside [`Self::scene_queries`]).
    /// [`Self::as_query_pipeline`] is the two in one.
    pub fn query_pipeline<'a>(
        &'a self,
        dispatcher: &'a dyn QueryDispatcher,
        bodies: &'a RigidBodySet,
        colliders: &'a ColliderSet,
        filter: QueryFilter<'a>,
    ) -> QueryPipeline<'a> {
        QueryPipeline {
            dispatcher,
            bvh: &self.mirror.bvh,
            bodies,
            colliders,
            filter,
        }
    }

    /// Brings the parry BVH behind [`Self::query_pipeline`] in sync with the broadphase (and
    /// the edits [`Self::refresh_queries`] recorded): built on the first call, then updated
    /// where proxies changed since the previous call.
    pub fn sync_query_pipeline(&mut self, colliders: &ColliderSet) {
        if self.mirror.active && self.mirror.dirty.is_empty() {
            return;
        }
        let extra: FxHashMap<u32, ColliderHandle> = self
            .overlay
            .extra()
            .iter()
            .map(|h| (h.into_raw_parts().0, *h))
            .collect();
        if !self.mirror.active {
            self.mirror.active = true;
            let n = extra
                .keys()
                .map(|&i| i as usize + 1)
                .max()
                .unwrap_or(0)
                .max(self.proxies.len());
            let boxes: Vec<Option<Aabb>> = (0..n as u32)
                .map(|id| self.mirror_box(id, colliders, &extra))
                .collect();
            self.mirror.bvh = build(&boxes);
            self.mirror.leaves = boxes;
            return;
        }
        let mut dirty = std::mem::take(&mut self.mirror.dirty);
        let mut updates = Vec::new();
        for &id in &dirty {
            self.mirror.is_dirty[id as usize] = false;
            let new = self.mirror_box(id, colliders, &extra);
            let i = id as usize;
            if i >= self.mirror.leaves.len() {
                self.mirror.leaves.resize(i + 1, None);
            }
            if self.mirror.leaves[i] != new {
                updates.push((id, new));
            }
        }
        dirty.clear();
        self.mirror.dirty = dirty;
        let changed = !updates.is_empty();
        // In the order Rapier's broadphase uses the same tree: every removal (or move, taken
        // out and put back) first, then the insertions, then optimisation and refit.
        for &(id, _) in &updates {
            if self.mirror.leaves[id as usize].is_some() {
                self.mirror.bvh.remove(id);
                self.mirror.leaves[id as usize] = None;
            }
        }
        for &(id, new) in &updates {
            if let Some(b) = new {
                self.mirror
                    .bvh
                    .insert_or_update_partially(b, id, CHANGE_MARGIN);
                self.mirror.leaves[id as usize] = Some(b);
            }
        }
        if changed {
            let mirror = &mut self.mirror;
            if mirror.bvh.leaf_count() <= SMALL_TREE {
                // parry 0.22's `optimize_incremental` on a tree that removals left with one
                // leaf makes every later traversal loop forever (a ray cast never returns).
                // A small tree is built afresh instead, for about what the update costs.
                mirror.bvh = build(&mirror.leaves);
            } else {
                // As Rapier's own broadphase does: optimise a part of the tree, then refit.
                mirror.bvh.optimize_incremental(&mut mirror.workspace);
                mirror.bvh.refit(&mut mirror.workspace);
            }
        }
    }
}

/// A parry BVH over `leaves` (the box of each collider index that has one). parry 0.22's
/// builder mislabels the leaves of a tree of one or two (it takes their indices to be 0 and
/// 1, and panics when they are not), so those are inserted one by one instead.
fn build(leaves: &[Option<Aabb>]) -> Bvh {
    let items = leaves
        .iter()
        .enumerate()
        .filter_map(|(i, b)| b.map(|b| (i, b)));
    if leaves.iter().flatten().count() > 2 {
        return Bvh::from_iter(BvhBuildStrategy::Binned, items);
    }
    let mut bvh = Bvh::default();
    for (i, b) in items {
        bvh.insert(b, i as u32);
    }
    bvh
}
