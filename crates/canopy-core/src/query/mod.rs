//! Queries on a built [`crate::Bvh`], one family per file: `overlap.rs` (boxes and points),
//! `ray.rs` (closest and any hit), `nearest.rs` (best-first), `pairs.rs` (self and
//! tree-vs-tree pairs, serial and rayon-parallel), `pairs4.rs` (the serial self-pair walk).

pub mod nearest;
pub mod overlap;
pub mod pairs;
mod pairs4;
pub mod ray;

use smallvec::SmallVec;

/// Traversal stack: 64 entries inline (deeper than any tree the builders make for realistic
/// inputs), spilling to the heap beyond.
pub(crate) type Stack<T> = SmallVec<[T; 64]>;
