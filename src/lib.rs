//! # canopy
//!
//! A fast bounding volume hierarchy and, built on it, a broadphase for the Rapier physics
//! engine. This root crate re-exports the workspace crates:
//!
//! * [`core`] (`canopy-core`): the BVH: builders, refit, queries, pair finding.
//! * [`rapier`] (`canopy-rapier`): `CanopyBroadPhase`, a drop-in `rapier3d` broadphase.
//! * [`scenes`] (`canopy-scenes`): the standard scenes and the measuring harness used by the
//!   examples, tests and benchmarks.
//! * [`parry`] (`canopy-parry`): `CollisionWorld`, collision detection for parry3d users:
//!   canopy-core broad phase, parry contact manifolds, triangle-mesh pruning, deformable
//!   self-collision.
//!
//! ```
//! use canopy::core::{Aabb, Bvh, BuildOptions};
//! let bvh = Bvh::build(&[Aabb::from_arrays([0.0; 3], [1.0; 3])], BuildOptions::default())?;
//! assert_eq!(bvh.len(), 1);
//! # Ok::<(), canopy::core::BvhError>(())
//! ```

#![deny(missing_docs)]

pub use canopy_core as core;
pub use canopy_parry as parry;
pub use canopy_rapier as rapier;
pub use canopy_scenes as scenes;
pub use rapier3d;

/// The README's examples, compiled and run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
pub struct ReadmeDoctests;
