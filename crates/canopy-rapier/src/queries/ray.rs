//! Ray queries: closest hit (with or without the normal), every hit, and batches of rays cast
//! in a cache-friendly order, in parallel, with results in input order.

use super::{valid_ray, SceneQueries};
use crate::filter::Mobility;
use rapier3d::parry::shape::FeatureId;
use rapier3d::prelude::{
    Collider, ColliderHandle, QueryFilter, Ray, RayIntersection, Real, Vector,
};
use rayon::prelude::*;

/// parry's `cast_ray_and_get_normal` on `collider`, except for a ray whose direction has no
/// length in `f32` (its squared length is 0): parry's box test names a face that does not
/// exist for such a ray (a subtraction overflow, which panics in debug builds, and a bogus
/// face in release). Such a ray can only hit where it starts, so it gets `cast_ray`'s answer
/// with a zero normal and no feature, as parry reports a solid hit from inside a shape.
fn hit_with_normal(
    collider: &Collider,
    ray: &Ray,
    max_toi: Real,
    solid: bool,
) -> Option<RayIntersection> {
    let (shape, pose) = (collider.shape(), collider.position());
    if ray.dir.norm_squared() > 0.0 {
        return shape.cast_ray_and_get_normal(pose, ray, max_toi, solid);
    }
    shape
        .cast_ray(pose, ray, max_toi, solid)
        .map(|t| RayIntersection::new(t, Vector::zeros(), FeatureId::Unknown))
}

impl<'a> SceneQueries<'a> {
    /// The closest hit of `ray` within `max_toi` (in units of `ray.dir`), as Rapier's
    /// `QueryPipeline::cast_ray`: `solid` makes a ray starting inside a shape hit it at 0.
    pub fn cast_ray(
        &self,
        ray: &Ray,
        max_toi: Real,
        solid: bool,
    ) -> Option<(ColliderHandle, Real)> {
        self.closest_ray_hit(ray, max_toi, |collider, t_max| {
            collider
                .shape()
                .cast_ray(collider.position(), ray, t_max, solid)
                .map(|t| (t, ()))
        })
        .map(|(handle, t, ())| (handle, t))
    }

    /// The closest hit of `ray` with the surface normal there, as Rapier's
    /// `QueryPipeline::cast_ray_and_get_normal`.
    pub fn cast_ray_and_get_normal(
        &self,
        ray: &Ray,
        max_toi: Real,
        solid: bool,
    ) -> Option<(ColliderHandle, RayIntersection)> {
        self.closest_ray_hit(ray, max_toi, |collider, t_max| {
            hit_with_normal(collider, ray, t_max, solid).map(|hit| (hit.time_of_impact, hit))
        })
        .map(|(handle, _, hit)| (handle, hit))
    }

    /// Every collider `ray` hits within `max_toi`, with the hit, as Rapier's
    /// `QueryPipeline::intersect_ray` (collected first: the order is the trees' traversal
    /// order, the same for the same world and broadphase).
    pub fn intersect_ray(
        &self,
        ray: Ray,
        max_toi: Real,
        solid: bool,
    ) -> impl Iterator<Item = (ColliderHandle, &'a Collider, RayIntersection)> + 'a {
        let mut hits = Vec::new();
        if !valid_ray(&ray, max_toi) {
            return hits.into_iter();
        }
        let bp = self.broad_phase;
        let cray = canopy_core::Ray::new(ray.origin, ray.dir);
        let mut test = |handle: ColliderHandle, collider: &'a Collider| {
            if let Some(hit) = hit_with_normal(collider, &ray, max_toi, solid) {
                hits.push((handle, collider, hit));
            }
        };
        for m in Mobility::ALL {
            let loose = self.loose(m);
            bp.trees[m as usize].cast_ray(&bp.proxies, &cray, max_toi, |id, _| {
                if !loose || cray.intersect_aabb(self.tight(id), max_toi).is_some() {
                    if let Some((handle, collider)) = self.collider(id) {
                        test(handle, collider);
                    }
                }
                None
            });
        }
        for (handle, collider, aabb) in self.edited() {
            if cray.intersect_aabb(&aabb, max_toi).is_some() {
                test(handle, collider);
            }
        }
        hits.into_iter()
    }

    /// [`Self::cast_ray`] for every ray of `rays`, results in the order of `rays`. The rays
    /// are cast in the Morton order of their origins (neighbouring rays walk the same nodes and
    /// read the same colliders, so the batch runs from cache far more than rays in random order
    /// do), in parallel (rayon) when the filter has no predicate closure: a closure is not
    /// required to be thread-safe, so with one the rays are cast on the calling thread.
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
    /// let narrow_phase = NarrowPhase::new();
    /// let queries = broad_phase.scene_queries(
    ///     narrow_phase.query_dispatcher(), &bodies, &colliders, QueryFilter::default());
    /// let rays = [
    ///     Ray::new(point![-5.0, 0.0, 0.0], vector![1.0, 0.0, 0.0]),
    ///     Ray::new(point![-5.0, 5.0, 0.0], vector![1.0, 0.0, 0.0]),
    /// ];
    /// assert_eq!(queries.cast_rays(&rays, 100.0, true), vec![Some((ball, 4.0)), None]);
    /// ```
    pub fn cast_rays(
        &self,
        rays: &[Ray],
        max_toi: Real,
        solid: bool,
    ) -> Vec<Option<(ColliderHandle, Real)>> {
        let order = coherent_order(rays);
        let sorted: Vec<Option<(ColliderHandle, Real)>> = if self.filter.predicate.is_some() {
            order
                .iter()
                .map(|&i| self.cast_ray(&rays[i as usize], max_toi, solid))
                .collect()
        } else {
            // Rebuilt per ray from thread-safe parts: `QueryFilter` is not `Sync` (its
            // predicate type has no `Sync` bound), everything else here is.
            let (broad_phase, dispatcher, bodies, colliders) = (
                self.broad_phase,
                self.dispatcher,
                self.bodies,
                self.colliders,
            );
            let f = &self.filter;
            let (flags, groups, exclude_collider, exclude_rigid_body) =
                (f.flags, f.groups, f.exclude_collider, f.exclude_rigid_body);
            order
                .par_iter()
                .with_min_len(64)
                .map(|&i| {
                    let queries = SceneQueries {
                        broad_phase,
                        dispatcher,
                        bodies,
                        colliders,
                        filter: QueryFilter {
                            flags,
                            groups,
                            exclude_collider,
                            exclude_rigid_body,
                            predicate: None,
                        },
                    };
                    queries.cast_ray(&rays[i as usize], max_toi, solid)
                })
                .collect()
        };
        let mut out = vec![None; rays.len()];
        for (&i, hit) in order.iter().zip(sorted) {
            out[i as usize] = hit;
        }
        out
    }

    /// The closest hit over the trees and the edited colliders; `exact(collider, best_t)`
    /// gives the time of impact (and what else the caller wants) with one collider.
    fn closest_ray_hit<T>(
        &self,
        ray: &Ray,
        max_toi: Real,
        mut exact: impl FnMut(&'a Collider, Real) -> Option<(Real, T)>,
    ) -> Option<(ColliderHandle, Real, T)> {
        if !valid_ray(ray, max_toi) {
            return None;
        }
        let bp = self.broad_phase;
        let cray = canopy_core::Ray::new(ray.origin, ray.dir);
        let mut best: Option<(ColliderHandle, Real, T)> = None;
        let mut best_t = max_toi;
        for m in Mobility::ALL {
            let mut found: Option<(ColliderHandle, Real, T)> = None;
            let loose = self.loose(m);
            bp.trees[m as usize].cast_ray(&bp.proxies, &cray, best_t, |id, t_max| {
                if loose {
                    cray.intersect_aabb(self.tight(id), t_max)?;
                }
                let (handle, collider) = self.collider(id)?;
                let (t, extra) = exact(collider, t_max)?;
                if found.as_ref().is_none_or(|f| t < f.1) {
                    found = Some((handle, t, extra));
                }
                Some(t)
            });
            if let Some(f) = found {
                if best.is_none() || f.1 < best_t {
                    best_t = f.1;
                    best = Some(f);
                }
            }
        }
        for (handle, collider, aabb) in self.edited() {
            if cray.intersect_aabb(&aabb, best_t).is_none() {
                continue;
            }
            if let Some((t, extra)) = exact(collider, best_t) {
                if t <= best_t && (best.is_none() || t < best_t) {
                    best_t = t;
                    best = Some((handle, t, extra));
                }
            }
        }
        best
    }
}

/// The indices of `rays` sorted by the Morton code of their origins (ties by index), in the
/// box around the finite origins.
fn coherent_order(rays: &[Ray]) -> Vec<u32> {
    let mut lo = [Real::MAX; 3];
    let mut hi = [Real::MIN; 3];
    for r in rays {
        for i in 0..3 {
            if r.origin[i].is_finite() {
                lo[i] = lo[i].min(r.origin[i]);
                hi[i] = hi[i].max(r.origin[i]);
            }
        }
    }
    let inv = std::array::from_fn(|i| {
        let extent = hi[i] - lo[i];
        if extent > 0.0 && extent.is_finite() {
            1.0 / extent
        } else {
            0.0
        }
    });
    let lo = lo.map(|c| if c.is_finite() { c } else { 0.0 });
    let mut keys: Vec<u64> = rays
        .iter()
        .map(|r| canopy_core::morton::morton_code([r.origin.x, r.origin.y, r.origin.z], lo, inv))
        .collect();
    let mut order: Vec<u32> = (0..rays.len() as u32).collect();
    // One value per key, so the sort cannot refuse them; the input order would do anyway.
    let _ = canopy_core::build::radix_sort_pairs(&mut keys, &mut order, false);
    order
}
