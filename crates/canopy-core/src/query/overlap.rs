//! Box overlap and point containment queries: a callback form (a walk of the tree's four-wide
//! copy, four children tested at once) and an iterator form (on the binary nodes). Both report
//! exactly the primitives whose stored box overlaps the query (closed boxes), each once, in an
//! order fixed by the tree (not the same order for the two forms).

use super::ray::INTERIOR;
use super::Stack;
use crate::aabb::{overlaps, Aabb};
use crate::build::f4::{aabb_box, overlap, prim_box, F4};
use crate::bvh::Bvh;
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

    /// Calls `f` with every primitive whose box overlaps `aabb` (touching counts), each once, in
    /// an order that depends only on the tree.
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
        // On the four-wide copy (`Node4`, shared with the ray casts and the self-pair walk):
        // the four children of a node are tested against the query at once, one SSE compare
        // per axis and side, and only the overlapping lanes are followed. Leaf lanes are
        // reported as they are met; the first overlapping interior lane is visited next and the
        // others pushed (last lane first), so the order is fixed for a given tree, though not
        // the order of `overlaps`.
        if self.nodes.is_empty() {
            return;
        }
        let r4 = self.four_wide();
        let (min, max) = (aabb.min_array(), aabb.max_array());
        let qlo = min.map(F4::splat);
        let qhi = max.map(F4::splat);
        let q4 = aabb_box(aabb);
        let mut stack: Stack<u32> = Stack::new();
        let mut cur = 0u32;
        loop {
            let n = r4.at(cur as usize);
            let mut mask = 0xf;
            for a in 0..3 {
                mask &= F4::load4(&n.b[a]).le_bits(qhi[a]) & qlo[a].le_bits(F4::load4(&n.b[3 + a]));
            }
            // The overlapping interior lanes, followed after the leaf lanes are reported.
            let mut interior = 0u32;
            while mask != 0 {
                let lane = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                match n.meta[lane] {
                    INTERIOR => interior |= 1 << lane,
                    1 => f(n.first[lane]),
                    count => {
                        // One SSE test per primitive, one branch on its result.
                        let first = n.first[lane] as usize;
                        for slot in first..first + count as usize {
                            let (blo, bhi) = prim_box(&self.prim_bounds[slot]);
                            if overlap(blo, bhi, q4.0, q4.1) {
                                f(self.prim_indices[slot]);
                            }
                        }
                    }
                }
            }
            if interior != 0 {
                // The first interior lane is visited next, without a trip through the stack;
                // the others wait there, last lane first.
                let next = n.first[interior.trailing_zeros() as usize];
                interior &= interior - 1;
                while interior != 0 {
                    let lane = 31 - interior.leading_zeros() as usize;
                    interior &= !(1 << lane);
                    stack.push(n.first[lane]);
                }
                cur = next;
                continue;
            }
            match stack.pop() {
                Some(next) => cur = next,
                None => return,
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
