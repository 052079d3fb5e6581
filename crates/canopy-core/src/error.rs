//! Error types returned by builders, refit and validation.

use thiserror::Error;

/// Why a tree could not be built or refit.
#[derive(Clone, Debug, PartialEq, Error)]
pub enum BvhError {
    /// The box at `index` has a NaN or infinite coordinate, or `min > max` on some axis.
    #[error("invalid AABB at index {index}: coordinates must be finite with min <= max")]
    InvalidAabb {
        /// Position of the offending box in the input slice.
        index: usize,
    },
    /// More primitives than `u32` node indices can address (a tree of `n` primitives may have
    /// `2n - 1` nodes): at most [`crate::build::MAX_PRIMITIVES`], 2^31.
    #[error(
        "too many primitives: {count} (at most {} are supported)",
        crate::build::MAX_PRIMITIVES
    )]
    TooManyPrimitives {
        /// Number of boxes given.
        count: usize,
    },
    /// Refit was given a different number of boxes than the tree was built with.
    #[error("refit expects {expected} boxes, got {got}")]
    LengthMismatch {
        /// Primitive count of the tree.
        expected: usize,
        /// Number of boxes given.
        got: usize,
    },
    /// A primitive index that the tree does not hold.
    #[error("primitive {index} is not in the tree (it holds {len})")]
    UnknownPrimitive {
        /// The index given.
        index: u32,
        /// Primitive count of the tree.
        len: usize,
    },
    /// A build option is out of range.
    #[error("invalid build options: {0}")]
    InvalidOptions(&'static str),
    /// [`crate::build::radix_sort_pairs`] was given a different number of values than keys.
    #[error("{keys} keys to sort but {values} values")]
    KeysValuesMismatch {
        /// Number of keys given.
        keys: usize,
        /// Number of values given.
        values: usize,
    },
}

/// A broken tree invariant found by [`crate::Bvh::validate`].
#[derive(Clone, Debug, PartialEq, Eq, Error)]
#[error("invalid BVH: {0}")]
pub struct ValidationError(pub String);
