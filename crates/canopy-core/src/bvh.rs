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

    /// Primitive slot range of a leaf.
    #[inline(always)]
    pub fn leaf_range(&self) -> std::ops::Range<usize> {
        self.first as usize..(self.first + self.count) as usize
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
    /// Inverse of `prim_indices`: the slot of each primitive. Empty after a build;
    /// `refit_primitives` makes it when first needed (most users never need it).
    pub(crate) slot_of: Vec<u32>,
}

impl Bvh {
    /// Builds a tree over `aabbs` with the builder chosen in `options`.
    ///
    /// Primitive `i` is `aabbs[i]`. Empty input gives an empty tree; zero-size boxes are fine.
    ///
    /// # Errors
    /// [`BvhError::InvalidAabb`] naming the first box with a NaN or infinite coordinate or
    /// `min > max`; [`BvhError::InvalidOptions`] for a zero leaf size or a bin count outside
    /// `2..=64`; [`BvhError::TooManyPrimitives`] beyond `u32::MAX - 1` boxes.
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
        build::build(aabbs, &options)
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
