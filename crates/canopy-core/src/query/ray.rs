//! Ray casts: closest hit and any hit. Nodes are tested with the slab test, near child first,
//! and subtrees entered beyond the best time so far are skipped. The caller's callback decides
//! the exact primitive test; the stored primitive boxes cull first.

use super::Stack;
use crate::bvh::Bvh;
use crate::ray::Ray;

/// A ray hit: which primitive, at what time (`ray.origin + t * ray.dir`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Primitive index.
    pub primitive: u32,
    /// Time of impact.
    pub t: f32,
}

impl Bvh {
    /// The closest hit along `ray` within `[0, t_max]`.
    ///
    /// `hit(primitive, best_t)` is called for primitives whose box the ray enters before
    /// `best_t` (the closest time found so far, or `t_max`); it returns the exact time of impact
    /// with that primitive, or `None` for a miss. Its time must not be before the ray enters the
    /// primitive's box. Hits later than `best_t` are ignored; ties keep the first found.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions, Ray};
    /// use nalgebra::{Point3, Vector3};
    /// let boxes: Vec<Aabb> = (0..10)
    ///     .map(|i| Aabb::from_arrays([i as f32 * 2.0, 0.0, 0.0], [i as f32 * 2.0 + 1.0, 1.0, 1.0]))
    ///     .collect();
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let ray = Ray::new(Point3::new(-5.0, 0.5, 0.5), Vector3::x());
    /// // The exact test here is the box itself.
    /// let hit = bvh.cast_ray(&ray, 100.0, |i, t_max| ray.intersect_aabb(&boxes[i as usize], t_max));
    /// assert_eq!(hit.map(|h| (h.primitive, h.t)), Some((0, 5.0)));
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn cast_ray(
        &self,
        ray: &Ray,
        t_max: f32,
        hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<RayHit> {
        self.traverse_ray::<false>(ray, t_max, hit)
    }

    /// Any hit along `ray` within `[0, t_max]`: stops at the first primitive for which `hit`
    /// (as in [`Bvh::cast_ray`]) reports a time of impact. Use it for shadow and
    /// line-of-sight rays.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions, Ray};
    /// use nalgebra::{Point3, Vector3};
    /// let boxes = [Aabb::from_arrays([1.0; 3], [2.0; 3])];
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let ray = Ray::new(Point3::origin(), Vector3::new(1.0, 1.0, 1.0));
    /// let test = |i: u32, t: f32| ray.intersect_aabb(&boxes[i as usize], t);
    /// assert!(bvh.cast_ray_any(&ray, 10.0, test).is_some());
    /// assert!(bvh.cast_ray_any(&ray, 0.5, test).is_none());
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn cast_ray_any(
        &self,
        ray: &Ray,
        t_max: f32,
        hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<RayHit> {
        self.traverse_ray::<true>(ray, t_max, hit)
    }

    fn traverse_ray<const ANY: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        mut hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<RayHit> {
        let root = self.nodes.first()?;
        if t_max.is_nan() || t_max < 0.0 {
            return None;
        }
        ray.slab(&root.min, &root.max, t_max)?;
        let mut best: Option<RayHit> = None;
        let mut best_t = t_max;
        let mut stack: Stack<(u32, f32)> = Stack::new();
        let mut cur = 0usize;
        loop {
            let node = &self.nodes[cur];
            if node.is_leaf() {
                // A leaf of one primitive has that primitive's box (builders and refit make
                // leaf boxes from their primitives), which the ray was just seen to enter
                // before `best_t`: no second slab test.
                let single = node.count == 1;
                for slot in node.leaf_range() {
                    let b = &self.prim_bounds[slot];
                    if !single && ray.slab(&b.min, &b.max, best_t).is_none() {
                        continue;
                    }
                    let prim = self.prim_indices[slot];
                    if let Some(t) = hit(prim, best_t) {
                        if t <= best_t && (best.is_none() || t < best_t) {
                            best_t = t;
                            best = Some(RayHit { primitive: prim, t });
                            if ANY {
                                return best;
                            }
                        }
                    }
                }
            } else {
                let (l, r) = (cur + 1, node.right() as usize);
                let (ln, rn) = (&self.nodes[l], &self.nodes[r]);
                let tl = ray.slab(&ln.min, &ln.max, best_t);
                let tr = ray.slab(&rn.min, &rn.max, best_t);
                match (tl, tr) {
                    (Some(a), Some(b)) => {
                        let (near, far, tfar) = if a <= b { (l, r, b) } else { (r, l, a) };
                        stack.push((far as u32, tfar));
                        cur = near;
                        continue;
                    }
                    (Some(_), None) => {
                        cur = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        cur = r;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Next subtree still worth entering.
            loop {
                let Some((i, t)) = stack.pop() else {
                    return best;
                };
                if t <= best_t {
                    cur = i as usize;
                    break;
                }
            }
        }
    }
}
