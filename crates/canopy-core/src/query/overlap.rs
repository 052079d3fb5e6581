//! Box overlap and point containment queries: a callback form (a walk of the tree's four-wide
//! copy, four children tested at once) and an iterator form (on the binary nodes). Both report
//! exactly the primitives whose stored box overlaps the query (closed boxes), each once, in an
//! order fixed by the tree (not the same order for the two forms).

use super::ray::INTERIOR;
use super::Stack;
use crate::aabb::{overlaps, Aabb};
use crate::build::f4::{aabb_box, eq_bits, overlap, prim_box, F4};
use crate::bvh::Bvh;
use nalgebra::Point3;
use std::ops::Range;

/// Hits [`Bvh::for_each_overlap`] gathers before handing them to its callback.
const HIT_BUFFER: usize = 64;

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
    pub fn for_each_overlap(&self, aabb: &Aabb, f: impl FnMut(u32)) {
        self.walk_overlaps::<HIT_BUFFER>(aabb, f);
    }

    /// The walk of [`Bvh::for_each_overlap`] on the four-wide copy (`Node4`, shared with the
    /// ray casts and the self-pair walk), with a hit buffer of `HITS` entries (at least 4; the
    /// unit tests run it with small ones).
    ///
    /// The four children of a node are tested at once. The leaves met take no branch on a
    /// test's outcome, which a branch predictor cannot guess (about half of the lanes and
    /// primitives tested overlap): the hit lanes of one primitive are written to the hit buffer
    /// four at a time, each advancing the buffer by its hit bit, and the primitives of larger
    /// leaves are tested one by one, each written and advancing by its result. `f` gets the
    /// buffer's hits when it fills and at the end. The interior lanes keep their branches: the
    /// first one hit is visited next, the others pushed, last lane first. A predicted branch
    /// lets the processor start on a subtree waiting on the stack while a node's loads are in
    /// flight; pushed without branches (the stack pointer advanced by the lanes' bits), the
    /// next node waits for the current one, and the walk took 2.4 times as long on a million
    /// boxes (`benches/core_queries.rs`, `overlaps/1000000`). For a node, the leaves of one
    /// primitive come first, then the larger leaves, each in lane order.
    ///
    /// `overlaps` group of `benches/core_queries.rs` (10k box queries, canopy / parry 0.22's
    /// `intersect_aabb` in the same run): this walk 2.37x, 2.20x and 2.07x faster than parry
    /// on 10k, 100k and 1M boxes, against 2.15x, 1.79x and 1.86x for the walk before it, which
    /// branched on each lane's and primitive's test. On `spawn_storm`'s fat boxes (4,000, a
    /// query per box, warm): 226 ns a query against about 350.
    fn walk_overlaps<const HITS: usize>(&self, aabb: &Aabb, mut f: impl FnMut(u32)) {
        const { assert!(HITS >= 4) };
        if self.nodes.is_empty() {
            return;
        }
        let r4 = self.four_wide();
        let (min, max) = (aabb.min_array(), aabb.max_array());
        let qlo = min.map(F4::splat);
        let qhi = max.map(F4::splat);
        let q4 = aabb_box(aabb);
        // `hits[..k]` waits for `f`; the four lanes of a node are written at `k..k + 4`.
        let mut hits = [0u32; HITS];
        let mut k = 0usize;
        let mut stack: Stack<u32> = Stack::new();
        let mut cur = 0u32;
        loop {
            let n = r4.at(cur as usize);
            let mut mask = 0xf;
            for a in 0..3 {
                mask &= F4::load4(&n.b[a]).le_bits(qhi[a]) & qlo[a].le_bits(F4::load4(&n.b[3 + a]));
            }
            let interior = eq_bits(&n.meta, INTERIOR);
            let leaves = mask & !interior;
            if leaves != 0 {
                if k + 4 > HITS {
                    hits[..k].iter().for_each(|&i| f(i));
                    k = 0;
                }
                let single = eq_bits(&n.meta, 1);
                let singles = leaves & single;
                for lane in 0..4 {
                    hits[k] = n.first[lane];
                    k += ((singles >> lane) & 1) as usize;
                }
                let mut larger = leaves & !single;
                while larger != 0 {
                    let lane = larger.trailing_zeros() as usize;
                    larger &= larger - 1;
                    let first = n.first[lane] as usize;
                    let slots = first..first + n.meta[lane] as usize;
                    let (Some(boxes), Some(indices)) = (
                        self.prim_bounds.get(slots.clone()),
                        self.prim_indices.get(slots),
                    ) else {
                        continue;
                    };
                    // The leaf in pieces the hit buffer holds (the whole leaf, unless it is
                    // larger): room is made once per piece, not checked per primitive.
                    for (boxes, indices) in boxes.chunks(HITS).zip(indices.chunks(HITS)) {
                        if k + boxes.len() > HITS {
                            hits[..k].iter().for_each(|&i| f(i));
                            k = 0;
                        }
                        for (b, &index) in boxes.iter().zip(indices) {
                            let (blo, bhi) = prim_box(b);
                            // `k` stays below `HITS` here: the modulo never changes it, only
                            // spares the bounds check.
                            hits[k % HITS] = index;
                            k += overlap(blo, bhi, q4.0, q4.1) as usize;
                        }
                    }
                }
            }
            let mut inner = mask & interior;
            if inner != 0 {
                // The first interior lane is visited next, without a trip through the stack;
                // the others wait there, last lane first.
                let next = n.first[inner.trailing_zeros() as usize];
                inner &= inner - 1;
                while inner != 0 {
                    let lane = 31 - inner.leading_zeros() as usize;
                    inner &= !(1 << lane);
                    stack.push(n.first[lane]);
                }
                cur = next;
                continue;
            }
            match stack.pop() {
                Some(next) => cur = next,
                None => break,
            }
        }
        hits[..k].iter().for_each(|&i| f(i));
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

#[cfg(test)]
mod tests {
    use crate::{Aabb, BuildOptions, Builder, Bvh};
    use proptest::prelude::*;

    fn boxes(raw: &[([f32; 3], [f32; 3])]) -> Vec<Aabb> {
        raw.iter()
            .map(|&(c, h)| {
                Aabb::from_arrays(
                    [0, 1, 2].map(|a| c[a] - h[a]),
                    [0, 1, 2].map(|a| c[a] + h[a]),
                )
            })
            .collect()
    }

    proptest! {
        /// The walk with a hit buffer of four or five (handed to the callback at almost every
        /// leaf) reports exactly the overlapping primitives, each once, in the default
        /// buffer's order.
        #[test]
        fn small_buffers_report_every_overlap_once(
            raw in prop::collection::vec(
                (prop::array::uniform3(0.0f32..20.0), prop::array::uniform3(0.0f32..3.0)),
                1..300,
            ),
            query in (prop::array::uniform3(0.0f32..20.0), prop::array::uniform3(0.0f32..12.0)),
            sah in any::<bool>(),
            leaf in 1u32..9,
        ) {
            let boxes = boxes(&raw);
            let options = BuildOptions {
                builder: if sah { Builder::BinnedSah } else { Builder::Lbvh },
                max_leaf_size: leaf,
                parallel: false,
                ..Default::default()
            };
            let bvh = Bvh::build(&boxes, options).expect("valid boxes");
            let q = self::boxes(&[query])[0];
            let expect: Vec<u32> =
                (0..boxes.len() as u32).filter(|&i| boxes[i as usize].intersects(&q)).collect();
            let mut small = Vec::new();
            bvh.walk_overlaps::<4>(&q, |i| small.push(i));
            let mut large = Vec::new();
            bvh.walk_overlaps::<64>(&q, |i| large.push(i));
            let mut odd = Vec::new();
            bvh.walk_overlaps::<5>(&q, |i| odd.push(i));
            prop_assert_eq!(&small, &large);
            prop_assert_eq!(&odd, &large);
            large.sort_unstable();
            prop_assert_eq!(large, expect);
        }
    }
}
