//! Point queries: projection on the closest collider, and the colliders containing a point.

use super::{beyond_parts_reach, finite, SceneQueries};
use crate::filter::Mobility;
use canopy_core::Aabb;
use rapier3d::prelude::{Collider, ColliderHandle, Point, PointProjection, Real};

impl<'a> SceneQueries<'a> {
    /// The projection of `point` on the closest collider within `max_dist`, as Rapier's
    /// `QueryPipeline::project_point` (which ignores `max_dist`; here a collider farther than
    /// it is not returned, so pass `Real::MAX` for Rapier's behaviour). With `solid`, a point
    /// inside a shape projects on itself; otherwise on the shape's boundary. `None` when no
    /// collider qualifies. A collider whose shape is made of parts (a mesh, heightfield or
    /// compound) and reaches farther than 1e19 from `point` is left out: parry's projection on
    /// it overflows `f32` there (it panics, or answers the point itself).
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
        let at = Aabb::new(*point, *point);
        // The distance in `f64`, rounded to `f32`: exact to rounding where `f32` squares
        // would overflow.
        let exact = |collider: &Collider, aabb: &Aabb| {
            if beyond_parts_reach(collider.shape(), aabb, &at) {
                return None;
            }
            let proj = collider
                .shape()
                .project_point(collider.position(), point, solid);
            let d = proj.point.coords.cast::<f64>() - point.coords.cast::<f64>();
            Some((d.norm() as Real, proj))
        };
        for m in Mobility::ALL {
            let mut found: Option<(ColliderHandle, Real, PointProjection)> = None;
            bp.trees[m as usize].nearest(&bp.proxies, point, best_d, |id, limit| {
                let tight = self.tight(id);
                if tight.distance_to_point(point) > limit {
                    return None;
                }
                let (handle, collider) = self.collider(id)?;
                let (d, proj) = exact(collider, tight)?;
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
            let Some((d, proj)) = exact(collider, &aabb) else {
                continue;
            };
            if d <= best_d && (best.is_none() || d < best_d) {
                best_d = d;
                best = Some((handle, d, proj));
            }
        }
        best.map(|(handle, _, proj)| (handle, proj))
    }

    /// Every collider containing `point`, as Rapier's `QueryPipeline::intersect_point`. A
    /// collider whose shape is made of parts and reaches farther than 1e19 from `point` is left
    /// out, as in [`project_point`](Self::project_point).
    pub fn intersect_point(
        &self,
        point: Point<Real>,
    ) -> impl Iterator<Item = (ColliderHandle, &'a Collider)> + 'a {
        if !finite(point.iter()) {
            return Vec::new().into_iter();
        }
        let at = Aabb::new(point, point);
        let contains = |collider: &Collider, aabb: &Aabb| {
            !beyond_parts_reach(collider.shape(), aabb, &at)
                && collider.shape().contains_point(collider.position(), &point)
        };
        self.colliders_in_aabb(&at, contains).into_iter()
    }
}
