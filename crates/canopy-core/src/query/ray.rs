//! Ray casts: closest hit and any hit. Nodes are tested with the slab test, near child first,
//! and subtrees entered beyond the best time so far are skipped. The caller's callback decides
//! the exact primitive test; the stored primitive boxes cull first.

use super::Stack;
use crate::bvh::{wide_at, Bvh, Node};
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
        let slab = SignedSlab::new(ray);
        let wide = &self.wide;
        let mut best: Option<RayHit> = None;
        let mut best_t = t_max;
        let mut stack: Stack<(u32, f32)> = Stack::new();
        // Current child reference (`2 * wide index + side`, see `Wide`): the root first.
        let mut cur = 0usize;
        loop {
            let node = &wide_at(wide, cur >> 1).0[cur & 1];
            if node.is_leaf() {
                // A leaf of one primitive has that primitive's box (builders and refit make
                // leaf boxes from their primitives), which the ray was just seen to enter
                // before `best_t`: no second slab test.
                let range = node.leaf_range();
                if range.len() == 1 {
                    let prim = self.prim_indices[range.start];
                    if let Some(t) = hit(prim, best_t) {
                        if t <= best_t && (best.is_none() || t < best_t) {
                            best_t = t;
                            best = Some(RayHit { primitive: prim, t });
                            if ANY {
                                return best;
                            }
                        }
                    }
                } else {
                    // Primitives in the order the ray enters their boxes, so that the nearest
                    // hit comes first and the primitives behind it are skipped (the exact test
                    // is usually the expensive part). Leaves larger than `SORTED_LEAF` are
                    // taken in storage order.
                    let mut order = [(0.0f32, 0u32); SORTED_LEAF];
                    let mut len = 0;
                    let sort = range.len() <= SORTED_LEAF;
                    for slot in range {
                        let b = &self.prim_bounds[slot];
                        let Some(entry) = ray.slab(&b.min, &b.max, best_t) else {
                            continue;
                        };
                        if sort {
                            order[len] = (entry, slot as u32);
                            len += 1;
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
                    let order = &mut order[..len];
                    order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                    for &(entry, slot) in order.iter() {
                        if entry > best_t {
                            break;
                        }
                        let prim = self.prim_indices[slot as usize];
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
                }
            } else {
                // Both children from one cache line.
                let w = node.first as usize;
                let [ln, rn] = &wide_at(wide, w).0;
                let tl = slab.entry(ln, best_t);
                let tr = slab.entry(rn, best_t);
                let (l, r) = (2 * w, 2 * w + 1);
                match (tl, tr) {
                    (Some(a), Some(b)) => {
                        let (near, far, tfar, fnode) =
                            if a <= b { (l, r, b, rn) } else { (r, l, a, ln) };
                        // The near child's line is loaded next; start loading what the far
                        // child will read when popped, so that both misses overlap.
                        self.prefetch_child(fnode);
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

impl Bvh {
    /// Starts loading the first line that visiting `child` (an entry of the wide array) reads:
    /// its children's `Wide` for an interior node, its first primitive's index or box for a
    /// leaf.
    #[inline(always)]
    fn prefetch_child(&self, child: &Node) {
        let i = child.first as usize;
        if !child.is_leaf() {
            prefetch(self.wide.as_ptr().wrapping_add(i));
        } else if child.count == 1 {
            prefetch(self.prim_indices.as_ptr().wrapping_add(i));
        } else {
            prefetch(self.prim_bounds.as_ptr().wrapping_add(i));
        }
    }
}

/// A hint to load the cache line holding `p` into all cache levels; no effect on targets
/// without a prefetch instruction in `core::arch` on stable Rust.
#[inline(always)]
fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is only a hint: it never faults and never changes memory, whatever
    // the address; SSE is part of the x86_64 baseline.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// Largest leaf whose primitives are tested in ray-entry order.
const SORTED_LEAF: usize = 8;

/// The slab test with the near and far plane of each axis chosen once per ray by the sign of
/// the direction: three subtractions and multiplications per plane set, no min/max per axis.
struct SignedSlab {
    origin: [f32; 3],
    inv: [f32; 3],
    neg: [bool; 3],
}

impl SignedSlab {
    #[inline(always)]
    fn new(ray: &Ray) -> Self {
        let inv = [ray.inv_dir.x, ray.inv_dir.y, ray.inv_dir.z];
        Self {
            origin: [ray.origin.x, ray.origin.y, ray.origin.z],
            inv,
            neg: inv.map(f32::is_sign_negative),
        }
    }

    /// Entry time into the node's box within `[0, t_max]`, or `None`. Same result as
    /// `Ray::slab` (a NaN plane time, from `0 * inf`, is dropped by `f32::max`/`min`).
    #[inline(always)]
    fn entry(&self, n: &Node, t_max: f32) -> Option<f32> {
        let mut t0 = 0.0f32;
        let mut t1 = t_max;
        for i in 0..3 {
            let (near, far) = if self.neg[i] {
                (n.max[i], n.min[i])
            } else {
                (n.min[i], n.max[i])
            };
            t0 = t0.max((near - self.origin[i]) * self.inv[i]);
            t1 = t1.min((far - self.origin[i]) * self.inv[i]);
        }
        (t0 <= t1).then_some(t0)
    }
}
