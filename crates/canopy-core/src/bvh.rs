//! The flat tree: 32-byte [`Node`]s in depth-first order, the primitive index array, the
//! primitives' boxes in leaf order, and [`Bvh::build`], which dispatches to the builders in
//! `build/`. Queries live in `query/`, refit in `refit.rs`, checks in `validate.rs`.

use crate::aabb::Aabb;
use crate::build::{self, BuildOptions};
use crate::error::BvhError;

/// One tree node: bounds and two `u32` words.
///
/// * Leaf (`count > 0`): primitives `first .. first + count` of [`Bvh::primitive_indices`].
/// * Interior (`count == 0`): the left child is the next node (`index + 1`, depth-first order)
///   and `first` holds the index of the right child.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(32))]
pub struct Node {
    /// Smallest corner of the node's box.
    pub min: [f32; 3],
    /// Leaf: first primitive slot. Interior: index of the right child.
    pub first: u32,
    /// Largest corner of the node's box.
    pub max: [f32; 3],
    /// Leaf: number of primitives (> 0). Interior: 0.
    pub count: u32,
}

const _: () = assert!(std::mem::size_of::<Node>() == 32);
const _: () = assert!(std::mem::align_of::<Node>() == 32);

impl Node {
    /// A leaf over `count` primitives starting at slot `first`.
    #[inline]
    pub fn leaf(min: [f32; 3], max: [f32; 3], first: u32, count: u32) -> Self {
        debug_assert!(count > 0);
        Self {
            min,
            first,
            max,
            count,
        }
    }

    /// An interior node whose right child is at `right`.
    #[inline]
    pub fn interior(min: [f32; 3], max: [f32; 3], right: u32) -> Self {
        Self {
            min,
            first: right,
            max,
            count: 0,
        }
    }

    /// `true` for a leaf.
    #[inline(always)]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }

    /// Index of the right child (interior nodes only).
    #[inline(always)]
    pub fn right(&self) -> u32 {
        self.first
    }

    /// The node's box.
    #[inline]
    pub fn aabb(&self) -> Aabb {
        Aabb::from_arrays(self.min, self.max)
    }

    /// Primitive slot range of a leaf (added in `usize`, so a hand-made node near `u32::MAX`
    /// gives its range rather than an overflow).
    #[inline(always)]
    pub fn leaf_range(&self) -> std::ops::Range<usize> {
        self.first as usize..self.first as usize + self.count as usize
    }
}

/// Both children of one interior node side by side in one 64-byte cache line, so that the box
/// queries and the binary pair walks test both children of a node from one line (the ray casts
/// and the self-pair walks use a four-wide copy, in `query/ray.rs`). A child that is an
/// interior node has `count == 0` and `first` = the index
/// of *its* `Wide` (not a node index); a leaf child is the leaf node itself. `wide[0]` holds
/// the root (twice); interior node `k` in depth-first order (root `k = 0`) has its children in
/// `wide[k + 1]`. A child is addressed as `2 * wide index + side` (root: 0).
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct Wide(pub(crate) [Node; 2]);

const _: () = assert!(std::mem::size_of::<Wide>() == 64);

/// `wide[i]` without a bounds check, for the traversal loops.
///
/// Every child reference stored in a wide array is made by [`make_wide`] from the tree's own
/// topology and indexes that array; the traversals only follow such references (or start at the
/// root, index 0, of a non-empty array), and the array is only ever replaced or refit as a
/// whole with its tree.
#[inline(always)]
pub(crate) fn wide_at(wide: &[Wide], i: usize) -> &Wide {
    debug_assert!(i < wide.len());
    // SAFETY: see above: `i` is a reference read from `wide` itself, or 0 in a non-empty array.
    unsafe { wide.get_unchecked(i) }
}

/// The wide array of the depth-first `nodes` (see [`Wide`]), in one pass.
///
/// Every interior node has two children, so a subtree of `s` nodes holds `s / 2` interior
/// nodes (`s` odd): interior node `i` of wide index `w` has its left child at `w + 1` and its
/// right child `r` at `w + 1 + (r - i - 1) / 2`. Panics when `nodes` is not such a tree (a
/// reference would leave the array).
pub(crate) fn make_wide(nodes: &[Node]) -> Vec<Wide> {
    let Some(root) = nodes.first() else {
        return Vec::new();
    };
    let interior = (nodes.len() - 1) / 2;
    // A child as the wide array stores it: an interior node refers to its `Wide`, `w`.
    let child = |n: &Node, w: usize| Node {
        first: if n.is_leaf() { n.first } else { w as u32 },
        ..*n
    };
    let mut wide = Vec::with_capacity(interior + 1);
    wide.push(Wide([child(root, 1); 2]));
    // The largest reference made.
    let mut top = 0usize;
    for (i, n) in nodes.iter().enumerate() {
        if n.is_leaf() {
            continue;
        }
        let w = wide.len();
        let r = n.right() as usize;
        let rw = w + 1 + r.saturating_sub(i + 1) / 2;
        let (left, right) = (&nodes[i + 1], &nodes[r]);
        wide.push(Wide([child(left, w + 1), child(right, rw)]));
        let made = if right.is_leaf() { w + 1 } else { rw };
        let made = if left.is_leaf() && right.is_leaf() {
            0
        } else {
            made
        };
        top = top.max(made);
    }
    assert!(
        wide.len() == interior + 1 && top <= interior,
        "make_wide: not a full binary tree in depth-first order"
    );
    wide
}

/// Copies the node boxes of `nodes` into `wide` (same topology).
pub(crate) fn refresh_wide(nodes: &[Node], wide: &mut [Wide]) {
    let Some(root) = nodes.first() else {
        return;
    };
    let set = |e: &mut Node, n: &Node| {
        e.min = n.min;
        e.max = n.max;
    };
    set(&mut wide[0].0[0], root);
    set(&mut wide[0].0[1], root);
    let mut w = 1;
    for (i, n) in nodes.iter().enumerate() {
        if !n.is_leaf() {
            let e = &mut wide[w].0;
            set(&mut e[0], &nodes[i + 1]);
            set(&mut e[1], &nodes[n.right() as usize]);
            w += 1;
        }
    }
}

/// A primitive's box stored in leaf order next to its index, so that leaf tests read
/// contiguous memory and never call back into user data.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct PrimBounds {
    /// Smallest corner.
    pub min: [f32; 3],
    /// Largest corner.
    pub max: [f32; 3],
}

impl PrimBounds {
    #[inline]
    pub(crate) fn from_aabb(a: &Aabb) -> Self {
        Self {
            min: a.min_array(),
            max: a.max_array(),
        }
    }
}

/// A bounding volume hierarchy over axis-aligned boxes.
///
/// The tree never knows what a primitive is: it stores each primitive's index (its position in
/// the slice given to [`Bvh::build`]) and its box. Queries test those boxes and hand the
/// survivors to a callback that decides the exact test.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    pub(crate) nodes: Vec<Node>,
    pub(crate) prim_indices: Vec<u32>,
    pub(crate) prim_bounds: Vec<PrimBounds>,
    /// The maps of `refit_primitives` (the slot and leaf of each primitive, the parent of each
    /// node...; see `refit.rs`). Empty after a build; `refit_primitives` makes them when first
    /// needed (most users never need them).
    pub(crate) refit: crate::refit::RefitMaps,
    /// Both children of each interior node in one cache line (see [`Wide`]), for the box
    /// queries and the pair walks on binary nodes: made by the first such query after a build
    /// (builds that are never queried so do not pay for it), refit with the tree once made.
    pub(crate) wide: std::sync::OnceLock<Vec<Wide>>,
    /// The four-wide copy of the tree that the ray casts and [`Bvh::self_pairs`] walk (see
    /// `query/ray.rs`): made by the first such query after a build, refit with the tree once
    /// made.
    pub(crate) ray4: std::sync::OnceLock<crate::query::ray::Ray4>,
    /// Which build made this tree: a number no other build in this process gets (0 for a tree
    /// made by [`Bvh::new`]), kept by refits and clones, which keep the topology. Pair marks
    /// carry the stamp of the tree they were made for (`PairMarks`).
    pub(crate) stamp: u64,
}

/// The stamp of the next build (see [`Bvh::stamp`]).
static NEXT_STAMP: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);

impl Bvh {
    /// Builds a tree over `aabbs` with the builder chosen in `options`.
    ///
    /// Primitive `i` is `aabbs[i]`. Empty input gives an empty tree; zero-size boxes are fine.
    ///
    /// # Errors
    /// [`BvhError::InvalidAabb`] naming the first box with a NaN or infinite coordinate or
    /// `min > max`; [`BvhError::InvalidOptions`] for a zero leaf size or a bin count outside
    /// `2..=32`; [`BvhError::TooManyPrimitives`] beyond 2^31 boxes
    /// ([`crate::build::MAX_PRIMITIVES`]: a node index must fit in a `u32`).
    ///
    /// # Example
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions, Builder};
    /// let boxes: Vec<Aabb> = (0..100)
    ///     .map(|i| Aabb::from_arrays([i as f32, 0.0, 0.0], [i as f32 + 0.5, 1.0, 1.0]))
    ///     .collect();
    /// let sah = Bvh::build(&boxes, BuildOptions::default())?;
    /// let lbvh = Bvh::build(&boxes, BuildOptions { builder: Builder::Lbvh, ..Default::default() })?;
    /// assert_eq!(sah.len(), 100);
    /// assert!(sah.validate().is_ok() && lbvh.validate().is_ok());
    ///
    /// let bad = [Aabb::from_arrays([f32::NAN, 0.0, 0.0], [1.0; 3])];
    /// assert!(Bvh::build(&bad, BuildOptions::default()).is_err());
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn build(aabbs: &[Aabb], options: BuildOptions) -> Result<Bvh, BvhError> {
        let mut bvh = build::build(aabbs, &options)?;
        bvh.stamp = NEXT_STAMP.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        Ok(bvh)
    }

    /// The wide array (see [`Wide`]), made on first use.
    #[inline]
    pub(crate) fn wide(&self) -> &[Wide] {
        self.wide.get_or_init(|| make_wide(&self.nodes))
    }

    /// An empty tree.
    pub fn new() -> Self {
        Self::default()
    }

    /// Number of primitives.
    #[inline]
    pub fn len(&self) -> usize {
        self.prim_indices.len()
    }

    /// `true` when the tree holds no primitive.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.prim_indices.is_empty()
    }

    /// The nodes, root first, in depth-first order.
    #[inline]
    pub fn nodes(&self) -> &[Node] {
        &self.nodes
    }

    /// Primitive indices in leaf order; a leaf's range indexes this slice.
    #[inline]
    pub fn primitive_indices(&self) -> &[u32] {
        &self.prim_indices
    }

    /// Primitive boxes in leaf order (parallel to [`Bvh::primitive_indices`]).
    #[inline]
    pub fn primitive_bounds(&self) -> &[PrimBounds] {
        &self.prim_bounds
    }

    /// The box of the whole tree, `None` when empty.
    pub fn root_aabb(&self) -> Option<Aabb> {
        self.nodes.first().map(Node::aabb)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A leaf's slot range, for nodes made by hand anywhere in `u32`'s range, including ranges
    /// that end past `u32::MAX`.
    #[test]
    fn leaf_range_is_first_plus_count() {
        for (first, count) in [(0u32, 1u32), (7, 3), (u32::MAX - 1, 1), (u32::MAX, 2)] {
            let n = Node::leaf([0.0; 3], [1.0; 3], first, count);
            let start = first as usize;
            assert_eq!(n.leaf_range(), start..start + count as usize);
        }
    }
}
