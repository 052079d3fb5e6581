//! # canopy-core
//!
//! A bounding volume hierarchy over axis-aligned boxes, built for physics broadphases and scene
//! queries: binned-SAH and LBVH builders (parallel with rayon), a compact depth-first node
//! layout (32-byte nodes), refit, box / point / ray / nearest queries, and overlapping-pair
//! finding within one tree and between two trees.
//!
//! The tree never knows what a primitive is. It stores each primitive's index and box; queries
//! cull by box and hand survivors to a callback that makes the exact test.
//!
//! ```
//! use canopy_core::{Aabb, Bvh, BuildOptions, Builder};
//! let boxes: Vec<Aabb> = (0..1000)
//!     .map(|i| {
//!         let x = (i % 10) as f32;
//!         let y = ((i / 10) % 10) as f32;
//!         let z = (i / 100) as f32;
//!         Aabb::from_arrays([x, y, z], [x + 0.6, y + 0.6, z + 0.6])
//!     })
//!     .collect();
//! let bvh = Bvh::build(&boxes, BuildOptions::default().with_builder(Builder::Lbvh))?;
//! let mut pairs = 0;
//! bvh.self_pairs(|_, _| pairs += 1);
//! assert_eq!(pairs, 0); // 0.4 gaps between the boxes
//! # Ok::<(), canopy_core::BvhError>(())
//! ```
//!
//! Files: `aabb.rs`, `ray.rs`, `morton.rs`, `bvh.rs` (the tree), `build/` (one builder per
//! file), `refit.rs`, `query/` (one query family per file), `validate.rs`, `stats.rs`,
//! `error.rs`.

#![deny(missing_docs)]

pub mod aabb;
pub mod build;
pub mod bvh;
pub mod error;
pub mod morton;
pub mod query;
pub mod ray;
mod refit;
pub mod stats;
#[cfg(test)]
mod testing;
mod validate;

pub use aabb::Aabb;
pub use build::{BuildOptions, Builder};
pub use bvh::{Bvh, Node, PrimBounds};
pub use error::{BvhError, ValidationError};
pub use query::nearest::NearestHit;
pub use query::overlap::OverlapIter;
pub use query::pairs::PairMarks;
pub use query::ray::RayHit;
pub use ray::Ray;
pub use stats::BvhStats;

pub use nalgebra;
