//! # canopy-parry
//!
//! Collision detection for [parry3d](https://parry.rs) users who do not use Rapier: a
//! [`CollisionWorld`] whose broad phase is a canopy-core BVH and whose narrow phase is parry's
//! contact-manifold code (`DefaultQueryDispatcher`: GJK/EPA for general convex pairs, the
//! specialised routines elsewhere).
//!
//! * Objects are parry [`SharedShape`](parry3d::shape::SharedShape)s with an `Isometry3` and
//!   user data, named by generation-checked [`ObjectHandle`]s.
//! * [`CollisionWorld::update`] finds candidate pairs with canopy-core, computes their
//!   manifolds (kept across updates, see [`Coherence`]) and reports [`ContactEvent`]s.
//! * Triangle meshes and compounds get their own canopy-core BVH: mesh-vs-convex pairs query
//!   it with the convex shape's box, mesh-vs-mesh pairs traverse both trees (pairwise
//!   pruning); only surviving triangle / part pairs reach parry.
//! * Deformable meshes ([`CollisionWorld::insert_deformable`]) refit their BVH when their
//!   vertices move and report self-collisions between non-adjacent triangles.
//! * [`brute_force`] is the truth: parry called on every pair.
//!
//! ```
//! use canopy_parry::CollisionWorld;
//! use nalgebra::Isometry3;
//! use parry3d::shape::SharedShape;
//!
//! let mut world = CollisionWorld::new();
//! for i in 0..10 {
//!     world.insert(SharedShape::ball(0.6), Isometry3::translation(i as f32, 0.0, 0.0), i)?;
//! }
//! world.update(0.0)?;
//! assert_eq!(world.contact_pairs().count(), 9); // each ball touches the next
//! # Ok::<(), canopy_parry::CollisionError>(())
//! ```
//!
//! Files: `world.rs` (the world), `handle.rs`, `error.rs`, `validate.rs` (input checks),
//! `narrow.rs` (one pair's narrow phase), `parts.rs` (composite parts and their BVH),
//! `deformable.rs`, `self_contact.rs`, `pair.rs`, `event.rs`, `coherence.rs`, `stats.rs`,
//! `convert.rs`, `brute_force.rs`.

#![deny(missing_docs)]

pub mod brute_force;
mod coherence;
mod convert;
mod deformable;
mod error;
mod event;
mod handle;
mod narrow;
mod pair;
mod parts;
mod self_contact;
mod stats;
mod validate;
mod world;

pub use coherence::Coherence;
pub use error::CollisionError;
pub use event::ContactEvent;
pub use handle::ObjectHandle;
pub use narrow::in_contact;
pub use pair::{min_distance, ContactPair, Manifold, WorldContact};
pub use self_contact::{adjacent, triangle_pair_manifold, SelfContact};
pub use stats::UpdateStats;
pub use validate::{check_bounds, check_pose, check_shape, MAX_COORDINATE};
pub use world::CollisionWorld;

pub use parry3d;
