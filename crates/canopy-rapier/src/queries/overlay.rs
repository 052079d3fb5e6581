//! Edits made outside a step, for the scene queries: [`CanopyBroadPhase::refresh_queries`]
//! compares every collider with its proxy and records, until the next update, the proxies
//! that no longer stand for their collider (removed, disabled, moved out of the collision box
//! of the last update, a reused handle) and the colliders the trees do not cover (new, or moved out). Queries skip
//! the former and test the latter directly. The pair-tracking state is not touched: the next
//! update sees the same edits through Rapier's modified list and clears the overlay.

use crate::broad_phase::CanopyBroadPhase;
use canopy_core::Aabb;
use rapier3d::prelude::{ColliderHandle, ColliderSet};

/// What `refresh_queries` found; empty between an update and the next refresh.
#[derive(Clone, Debug, Default)]
pub(crate) struct QueryOverlay {
    /// Per proxy id: the proxy no longer stands for its collider.
    stale: Vec<bool>,
    /// Ids set in `stale`, to clear it.
    stale_ids: Vec<u32>,
    /// Colliders to test directly, in handle order.
    extra: Vec<ColliderHandle>,
}

impl QueryOverlay {
    #[inline]
    pub fn is_stale(&self, id: u32) -> bool {
        !self.stale_ids.is_empty() && self.stale.get(id as usize).copied().unwrap_or(false)
    }

    pub fn extra(&self) -> &[ColliderHandle] {
        &self.extra
    }

    pub fn is_empty(&self) -> bool {
        self.stale_ids.is_empty() && self.extra.is_empty()
    }

    fn mark_stale(&mut self, id: u32) {
        if id as usize >= self.stale.len() {
            self.stale.resize(id as usize + 1, false);
        }
        if !self.stale[id as usize] {
            self.stale[id as usize] = true;
            self.stale_ids.push(id);
        }
    }

    /// Empties the overlay; returns the proxy ids it affected (stale proxies and the indices
    /// of extra colliders).
    pub fn clear(&mut self) -> Vec<u32> {
        let mut ids = std::mem::take(&mut self.stale_ids);
        for &id in &ids {
            self.stale[id as usize] = false;
        }
        ids.extend(self.extra.drain(..).map(|h| h.into_raw_parts().0));
        ids
    }
}

impl CanopyBroadPhase {
    /// Brings the scene queries up to date with edits made since the last update: colliders
    /// inserted, moved, removed, enabled or disabled outside a physics step. One pass over the
    /// colliders (one AABB each); the trees and pairs are left for the next update, which sees
    /// the same edits and makes this unnecessary again. Not needed after a step.
    ///
    /// ```
    /// use canopy_rapier::CanopyBroadPhase;
    /// use rapier3d::prelude::*;
    ///
    /// let bodies = RigidBodySet::new();
    /// let mut colliders = ColliderSet::new();
    /// let ball = colliders.insert(ColliderBuilder::ball(1.0));
    /// let mut broad_phase = CanopyBroadPhase::new();
    /// broad_phase.refresh_queries(&colliders);
    /// // Teleport the ball, then query before any step.
    /// colliders[ball].set_translation(vector![50.0, 0.0, 0.0]);
    /// broad_phase.refresh_queries(&colliders);
    /// let dispatcher = NarrowPhase::new();
    /// let queries = broad_phase.scene_queries(dispatcher.query_dispatcher(), &bodies, &colliders, QueryFilter::default());
    /// assert_eq!(queries.intersect_point(point![50.0, 0.5, 0.0]).count(), 1);
    /// assert_eq!(queries.intersect_point(point![0.0, 0.0, 0.0]).count(), 0);
    /// ```
    pub fn refresh_queries(&mut self, colliders: &ColliderSet) {
        let affected = self.overlay.clear();
        self.mirror.touch_all(&affected);
        let mut seen = vec![false; self.proxies.len()];
        for (handle, collider) in colliders.iter() {
            let id = handle.into_raw_parts().0;
            let proxy = self.proxies.get(id as usize).and_then(Option::as_ref);
            if let Some(p) = proxy {
                seen[id as usize] = true;
                if !p.is_for(handle) {
                    self.overlay.mark_stale(id);
                }
            }
            if !collider.is_enabled() {
                if proxy.is_some() {
                    self.overlay.mark_stale(id);
                }
                continue;
            }
            let aabb = collider.compute_aabb();
            let aabb = Aabb::new(aabb.mins, aabb.maxs);
            // The queries cull with the fat box, then test the collision box of the last update
            // before the shape: both must still hold the collider.
            let covered = proxy.is_some_and(|p| {
                p.is_for(handle)
                    && p.is_valid()
                    && p.fat.contains(&aabb)
                    && self.tights[id as usize].contains(&aabb)
            });
            if !covered {
                if proxy.is_some() {
                    self.overlay.mark_stale(id);
                }
                if aabb.is_valid() {
                    self.overlay.extra.push(handle);
                }
            }
        }
        // Proxies whose collider is gone.
        for (id, p) in self.proxies.iter().enumerate() {
            if p.is_some() && !seen[id] {
                self.overlay.mark_stale(id as u32);
            }
        }
        let ids: Vec<u32> = self
            .overlay
            .stale_ids
            .iter()
            .copied()
            .chain(self.overlay.extra.iter().map(|h| h.into_raw_parts().0))
            .collect();
        self.mirror.touch_all(&ids);
    }
}
