//! Point queries: projection on the closest collider, and the colliders containing a point.

use super::{finite, SceneQueries};
use crate::filter::Mobility;
use canopy_core::Aabb;
use rapier3d::prelude::{Collider, ColliderHandle, Point, PointProjection, Real};

impl<'a> SceneQueries<'a> {
    /// The projection of `point` on the closest collider within `max_dist`, as Rapier's
    /// `QueryPipeline::project_point` (which ignores `max_dist`; here a collider farther than
    /// it is not returned, so pass `Real::MAX` for Rapier's behaviour). With `solid`, a point
    /// inside a shape projects on itself; otherwise on the shape's boundary. `None` when no
    /// collider qualifies.
    pub fn project_point(
        &self,
        point: &Point<Real>,
        max_dist: Real,
        solid: bool,
    ) -> Option<(ColliderHandle, PointProjection)> {
        if !finite(point.iter()) || max_dist.is_nan() || max_dist < 0.0 {
            return None;
        }
        let bp = self.broad_phase;
        let mut best: Option<(ColliderHandle, Real, PointProjection)> = None;
        let mut best_d = max_dist;
        let exact = |collider: &Collider| {
            let proj = collider
                .shape()
                .project_point(collider.position(), point, solid);
            (rapier3d::na::distance(&proj.point, point), proj)
        };
        for m in Mobility::ALL {
            let mut found: Option<(ColliderHandle, Real, PointProjection)> = None;
            bp.trees[m as usize].nearest(&bp.proxies, point, best_d, |id, limit| {
                if self.tight(id).distance_to_point(point) > limit {
                    return None;
                }
                let (handle, collider) = self.collider(id)?;
                let (d, proj) = exact(collider);
                if found.as_ref().is_none_or(|f| d < f.1) {
                    found = Some((handle, d, proj));
                }
                Some(d)
            });
            if let Some(f) = found {
                if f.1 <= best_d && (best.is_none() || f.1 < best_d) {
                    best_d = f.1;
                    best = Some(f);
                }
            }
        }
        for (handle, collider, aabb) in self.edited() {
            if aabb.distance_to_point(point) > best_d {
                continue;
            }
            let (d, proj) = exact(collider);
            if d <= best_d && (best.is_none() || d < best_d) {
                best_d = d;
                best = Some((handle, d, proj));
            }
        }
        best.map(|(handle, _, proj)| (handle, proj))
    }

    /// Every collider containing `point`, as Rapier's `QueryPipeline::intersect_point`.
    pub fn intersect_point(
        &self,
        point: Point<Real>,
    ) -> impl Iterator<Item = (ColliderHandle, &'a Collider)> + 'a {
        if !finite(point.iter()) {
            return Vec::new().into_iter();
        }
        let contains =
            |collider: &Collider| collider.shape().contains_point(collider.position(), &point);
        self.colliders_in_aabb(&Aabb::new(point, point), contains)
            .into_iter()
    }
}
