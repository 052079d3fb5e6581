//! # canopy-rapier
//!
//! [`CanopyBroadPhase`]: a broadphase for rapier3d 0.27 built on canopy-core. Pass it to
//! `PhysicsPipeline::step` instead of Rapier's `BroadPhaseBvh`; the simulation is the same,
//! the broadphase time is lower.
//!
//! Files: `broad_phase.rs` (the update), `arena_ahead.rs` (its prefetching of colliders and
//! bodies), `proxy.rs` (per-collider state), `proxy_tree.rs` (one
//! tree per mobility), `pair_set.rs` (live pairs and per-proxy partner lists), `filter.rs`
//! (pairs the narrow phase would discard), `config.rs`, `stats.rs`, and `queries/` (scene
//! queries: ray, point and shape queries with Rapier's names, and Rapier's own
//! `QueryPipeline` for the character controller).

#![deny(missing_docs)]

mod arena_ahead;
mod box_lanes;
mod broad_phase;
mod config;
mod filter;
mod pair_set;
#[cfg(feature = "phase-times")]
mod phase_times;
mod proxy;
mod proxy_tree;
mod queries;
mod shape_box;
mod stats;

pub use broad_phase::CanopyBroadPhase;
pub use config::{CanopyBroadPhaseConfig, ConfigError, RebuildPolicy};
pub use filter::Mobility;
#[cfg(feature = "phase-times")]
pub use phase_times::PhaseTimes;
pub use queries::SceneQueries;
pub use stats::BroadPhaseStats;
