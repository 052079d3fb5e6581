//! Nearest-primitive query: best-first traversal ordered by the distance from the query point
//! to node boxes, with the caller's callback giving the exact distance to a primitive.

use crate::aabb::distance as box_distance;
use crate::bvh::Bvh;
use nalgebra::Point3;
use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

/// Result of [`Bvh::nearest`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NearestHit {
    /// Primitive index.
    pub primitive: u32,
    /// Distance reported by the callback.
    pub distance: f32,
}

#[derive(Clone, Copy, PartialEq)]
struct Entry(f32, u32);
impl Eq for Entry {}
impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        self.0.total_cmp(&other.0).then(self.1.cmp(&other.1))
    }
}

impl Bvh {
    /// The primitive nearest to `point` within `max_distance`.
    ///
    /// `distance(primitive, best)` is called for primitives whose box is no farther than the
    /// best distance so far (`best`, initially `max_distance`) and returns the exact distance
    /// from `point` to that primitive, or `None` to skip it. The distance must be at least the
    /// distance from `point` to the primitive's box (true of any shape inside its box). Ties
    /// keep the first found.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// use nalgebra::Point3;
    /// let boxes: Vec<Aabb> = (0..10)
    ///     .map(|i| Aabb::from_arrays([i as f32 * 3.0; 3], [i as f32 * 3.0 + 1.0; 3]))
    ///     .collect();
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let p = Point3::new(7.5, 7.5, 7.5);
    /// let hit = bvh.nearest(&p, f32::INFINITY, |i, _| Some(boxes[i as usize].distance_to_point(&p)));
    /// assert_eq!(hit.unwrap().primitive, 2);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn nearest(
        &self,
        point: &Point3<f32>,
        max_distance: f32,
        mut distance: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<NearestHit> {
        if self.nodes.is_empty() || max_distance.is_nan() || max_distance < 0.0 {
            return None;
        }
        let mut best: Option<NearestHit> = None;
        let mut best_d = max_distance;
        let node_dist = |i: usize| {
            let n = &self.nodes[i];
            box_distance(n.min, n.max, point)
        };
        let mut heap = BinaryHeap::new();
        heap.push(Reverse(Entry(node_dist(0), 0)));
        while let Some(Reverse(Entry(d, i))) = heap.pop() {
            if d > best_d {
                break;
            }
            let node = &self.nodes[i as usize];
            if node.is_leaf() {
                for slot in node.leaf_range() {
                    let b = &self.prim_bounds[slot];
                    if box_distance(b.min, b.max, point) > best_d {
                        continue;
                    }
                    let prim = self.prim_indices[slot];
                    if let Some(dp) = distance(prim, best_d) {
                        if dp <= best_d && (best.is_none() || dp < best_d) {
                            best_d = dp;
                            best = Some(NearestHit {
                                primitive: prim,
                                distance: dp,
                            });
                        }
                    }
                }
            } else {
                for c in [i as usize + 1, node.right() as usize] {
                    let dc = node_dist(c);
                    if dc <= best_d {
                        heap.push(Reverse(Entry(dc, c as u32)));
                    }
                }
            }
        }
        best
    }
}
