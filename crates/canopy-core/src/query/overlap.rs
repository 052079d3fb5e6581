//! Box overlap and point containment queries: a callback form (a walk of the tree's wide array,
//! both children of a node in one cache line) and an iterator form (on the nodes). Both report
//! exactly the primitives whose stored box overlaps the query (closed boxes), in the same order.

use super::Stack;
use crate::aabb::{overlaps, Aabb};
use crate::bvh::{wide_at, Bvh};
use nalgebra::Point3;
use std::ops::Range;

/// Iterator over the primitives whose box overlaps a query box, from [`Bvh::overlaps`].
#[derive(Clone, Debug)]
pub struct OverlapIter<'a> {
    bvh: &'a Bvh,
    min: [f32; 3],
    max: [f32; 3],
    stack: Stack<u32>,
    leaf: Range<usize>,
}

impl Iterator for OverlapIter<'_> {
    type Item = u32;

    fn next(&mut self) -> Option<u32> {
        loop {
            for slot in self.leaf.by_ref() {
                let b = &self.bvh.prim_bounds[slot];
                if overlaps(&b.min, &b.max, &self.min, &self.max) {
                    return Some(self.bvh.prim_indices[slot]);
                }
            }
            let i = self.stack.pop()? as usize;
            let node = &self.bvh.nodes[i];
            if !overlaps(&node.min, &node.max, &self.min, &self.max) {
                continue;
            }
            if node.is_leaf() {
                self.leaf = node.leaf_range();
            } else {
                self.stack.push(node.right());
                self.stack.push(i as u32 + 1);
            }
        }
    }
}

impl Bvh {
    /// Iterates over every primitive whose box overlaps `aabb` (touching counts), in tree order.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let boxes: Vec<Aabb> = (0..10)
    ///     .map(|i| Aabb::from_arrays([i as f32; 3], [i as f32 + 0.5; 3]))
    ///     .collect();
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let mut hits: Vec<u32> = bvh.overlaps(&Aabb::from_arrays([2.5; 3], [4.0; 3])).collect();
    /// hits.sort();
    /// assert_eq!(hits, [2, 3, 4]);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn overlaps(&self, aabb: &Aabb) -> OverlapIter<'_> {
        let mut stack = Stack::new();
        if !self.nodes.is_empty() {
            stack.push(0);
        }
        OverlapIter {
            bvh: self,
            min: aabb.min_array(),
            max: aabb.max_array(),
            stack,
            leaf: 0..0,
        }
    }

    /// Calls `f` with every primitive whose box overlaps `aabb` (touching counts).
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let boxes = [Aabb::from_arrays([0.0; 3], [1.0; 3]), Aabb::from_arrays([2.0; 3], [3.0; 3])];
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let mut n = 0;
    /// bvh.for_each_overlap(&Aabb::from_arrays([0.5; 3], [0.6; 3]), |i| { assert_eq!(i, 0); n += 1 });
    /// assert_eq!(n, 1);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn for_each_overlap(&self, aabb: &Aabb, mut f: impl FnMut(u32)) {
        // On the wide array: both children of a node are tested from one cache line when the
        // node is visited, and only the overlapping ones are pushed (right first), so leaves
        // come in the same order as from `overlaps`.
        let wide = self.wide();
        let Some(root) = wide.first().map(|w| &w.0[0]) else {
            return;
        };
        let (min, max) = (aabb.min_array(), aabb.max_array());
        if !overlaps(&root.min, &root.max, &min, &max) {
            return;
        }
        let mut stack: Stack<u32> = Stack::new();
        stack.push(0);
        while let Some(r) = stack.pop() {
            let e = &wide_at(wide, r as usize / 2).0[r as usize % 2];
            if e.is_leaf() {
                for slot in e.leaf_range() {
                    let b = &self.prim_bounds[slot];
                    if overlaps(&b.min, &b.max, &min, &max) {
                        f(self.prim_indices[slot]);
                    }
                }
                continue;
            }
            let [left, right] = &wide_at(wide, e.first as usize).0;
            if overlaps(&right.min, &right.max, &min, &max) {
                stack.push(2 * e.first + 1);
            }
            if overlaps(&left.min, &left.max, &min, &max) {
                stack.push(2 * e.first);
            }
        }
    }

    /// Iterates over every primitive whose box contains `point` (boundary included).
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// use nalgebra::Point3;
    /// let boxes = [Aabb::from_arrays([0.0; 3], [1.0; 3]), Aabb::from_arrays([1.0; 3], [2.0; 3])];
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// assert_eq!(bvh.containing_point(&Point3::new(1.5, 1.5, 1.5)).collect::<Vec<_>>(), [1]);
    /// assert_eq!(bvh.containing_point(&Point3::new(1.0, 1.0, 1.0)).count(), 2);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn containing_point(&self, point: &Point3<f32>) -> OverlapIter<'_> {
        self.overlaps(&Aabb::from_point(*point))
    }

    /// Calls `f` with every primitive whose box contains `point` (boundary included).
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// use nalgebra::Point3;
    /// let boxes = [Aabb::from_arrays([0.0; 3], [2.0; 3]), Aabb::from_arrays([1.0; 3], [3.0; 3])];
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let mut hits = Vec::new();
    /// bvh.for_each_containing_point(&Point3::new(1.5, 1.5, 1.5), |i| hits.push(i));
    /// hits.sort();
    /// assert_eq!(hits, [0, 1]);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn for_each_containing_point(&self, point: &Point3<f32>, f: impl FnMut(u32)) {
        self.for_each_overlap(&Aabb::from_point(*point), f)
    }
}
