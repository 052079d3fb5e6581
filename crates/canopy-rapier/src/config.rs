//! Configuration of [`crate::CanopyBroadPhase`]: fat-box margin, tree rebuild policy,
//! parallelism. Every field has a documented default, and [`CanopyBroadPhaseConfig::validate`]
//! says which values are refused ([`ConfigError`]).

use canopy_core::Builder;
use thiserror::Error;

/// A field of [`CanopyBroadPhaseConfig`] out of its range, from
/// [`CanopyBroadPhaseConfig::validate`] and [`crate::CanopyBroadPhase::with_config`].
#[derive(Clone, Copy, Debug, PartialEq, Error)]
pub enum ConfigError {
    /// A fat-box margin, the velocity stretch or the live-pair skin is negative, NaN or
    /// infinite. A negative margin would store boxes smaller than the colliders' own and lose
    /// pairs.
    #[error("{field} must be finite and at least 0, got {value}")]
    NegativeOrNotFinite {
        /// The field's name (`margin`, `fixed_margin`, `velocity_steps` or `live_pair_skin`).
        field: &'static str,
        /// The value given.
        value: f32,
    },
    /// A fraction or factor of the rebuild policy is negative or NaN.
    #[error("rebuild.{field} must be at least 0 (and not NaN), got {value}")]
    NegativeOrNan {
        /// The field's name (`max_cost_growth`, `pending_fraction` or `max_dead_fraction`).
        field: &'static str,
        /// The value given.
        value: f64,
    },
}

/// When and how the trees of moving colliders are rebuilt.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RebuildPolicy {
    /// Builder for the trees of moving (dynamic and kinematic) colliders. Default: LBVH, the
    /// fastest build; those trees are refit every step and rebuilt often.
    pub moving_builder: Builder,
    /// Builder for the tree of fixed colliders, which rarely changes. Default: binned SAH.
    pub fixed_builder: Builder,
    /// Rebuild a refit tree once its SAH cost exceeds this multiple of its cost right after the
    /// last build (compared every few refits, and at once after a refit that moved at least
    /// half of the tree's leaves when some member jumped since the last comparison: a new fat
    /// box clear of the one it replaced). Default: 1.5.
    pub max_cost_growth: f64,
    /// New colliders wait in a pending list with a small tree of its own (rebuilt when the list
    /// changes, refit when only boxes do); the main tree is rebuilt once that list exceeds
    /// `max(min_pending, tree size * pending_fraction)`. Defaults: 16 and 1/16.
    pub min_pending: usize,
    /// See [`RebuildPolicy::min_pending`].
    pub pending_fraction: f64,
    /// Removed colliders leave a dead leaf until the next rebuild; rebuild once more than this
    /// fraction of the tree is dead. Default: 1/4.
    pub max_dead_fraction: f64,
}

impl Default for RebuildPolicy {
    fn default() -> Self {
        Self {
            moving_builder: Builder::Lbvh,
            fixed_builder: Builder::BinnedSah,
            max_cost_growth: 1.5,
            min_pending: 16,
            pending_fraction: 1.0 / 16.0,
            max_dead_fraction: 0.25,
        }
    }
}

/// Settings of [`crate::CanopyBroadPhase`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CanopyBroadPhaseConfig {
    /// Margin of the fat boxes, in multiples of `IntegrationParameters::length_unit`. Each
    /// collider's box is stored enlarged by this much on every side; while its exact box stays
    /// inside, the collider costs nothing. Larger margins mean fewer updates but more candidate
    /// pairs. Default: 0.1 (Box2D's `b2_aabbMargin`).
    pub margin: f32,
    /// Margin of the fat boxes of colliders attached to fixed bodies or to no body, in the same
    /// unit. They only move when the user moves them, so a margin buys them nothing but extra
    /// candidate pairs and looser boxes for the scene queries. Default: 0 (as Box2D v3 gives
    /// static shapes no margin).
    pub fixed_margin: f32,
    /// Fat boxes also cover where the collider will be after this many steps at its parent's
    /// current linear velocity, so that steadily moving bodies stay inside their box for that
    /// long. 0 disables it. It never affects correctness (every step still checks the exact
    /// box), only how often boxes are re-enlarged against how many candidate pairs there are;
    /// the live pairs do not grow with it, as a pair stays live only while its exact boxes
    /// touch (`live_pair_skin`). Default: 12 (Box2D 2.4 stretched by 4 steps,
    /// `b2_aabbMultiplier`, and kept a pair as long as the fat boxes overlapped). Measured with
    /// `broadphase_replay SCENE ab` (200 steps; time against 6 steps, which kept live pairs as
    /// long as candidates; two runs each): `spawn_storm` 0.98, `many_kinematics` 0.89 to 0.92,
    /// `pyramid` 0.96, `teleport` 0.99, `balls` 0.98 to 1.01, `boxes` 1.03 to 1.04,
    /// `keva_tower` 1.01 to 1.02, `many_pyramids` 1.01 to 1.04; 16 steps made `balls` 1.02 to
    /// 1.04.
    pub velocity_steps: f32,
    /// Tree maintenance. See [`RebuildPolicy`].
    pub rebuild: RebuildPolicy,
    /// Search new pairs and rebuild trees with rayon (the current pool). Results and event order
    /// are the same with any number of threads. Default: `true`.
    pub parallel: bool,
    /// When a live pair ends, in multiples of `length_unit`. A candidate pair goes live
    /// (`AddPair`) once the colliders' exact boxes (Rapier's collision boxes) overlap. It ends
    /// (`DeletePair`, and waits again as a candidate) once those boxes are more than twice this
    /// skin apart, which is checked whenever either collider gets a new fat box, and in any
    /// case when the fat boxes separate (the candidate ends). The skin keeps a pair that
    /// touches on and off from being deleted and added again every step. The narrow phase
    /// computes contacts for every live pair, so the sooner a pair that stopped touching ends,
    /// the less work it does: after `compare`'s 200 steps of `spawn_storm`, 7,992 live pairs
    /// instead of 9,316 kept as long as their candidates (Rapier's broadphase: 7,465). Use
    /// `f32::MAX` to keep a live pair as long as its candidate. Default: 0.01 (the skin of the
    /// leaf boxes of Rapier's own broadphase).
    pub live_pair_skin: f32,
}

impl CanopyBroadPhaseConfig {
    /// `Ok` when every field is in range: the margins, the velocity stretch and the live-pair
    /// skin finite and at least 0; the rebuild policy's `max_cost_growth`, `pending_fraction` and
    /// `max_dead_fraction` at least 0 (infinity allowed: never rebuild for that reason).
    ///
    /// ```
    /// use canopy_rapier::{CanopyBroadPhaseConfig, ConfigError};
    /// assert!(CanopyBroadPhaseConfig::default().validate().is_ok());
    /// let shrinking = CanopyBroadPhaseConfig { margin: -0.1, ..Default::default() };
    /// assert!(matches!(
    ///     shrinking.validate(),
    ///     Err(ConfigError::NegativeOrNotFinite { field: "margin", .. })
    /// ));
    /// ```
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (field, value) in [
            ("margin", self.margin),
            ("fixed_margin", self.fixed_margin),
            ("velocity_steps", self.velocity_steps),
            ("live_pair_skin", self.live_pair_skin),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(ConfigError::NegativeOrNotFinite { field, value });
            }
        }
        let policy = &self.rebuild;
        for (field, value) in [
            ("max_cost_growth", policy.max_cost_growth),
            ("pending_fraction", policy.pending_fraction),
            ("max_dead_fraction", policy.max_dead_fraction),
        ] {
            if value.is_nan() || value < 0.0 {
                return Err(ConfigError::NegativeOrNan { field, value });
            }
        }
        Ok(())
    }
}

impl Default for CanopyBroadPhaseConfig {
    fn default() -> Self {
        Self {
            margin: 0.1,
            fixed_margin: 0.0,
            velocity_steps: 12.0,
            rebuild: RebuildPolicy::default(),
            parallel: true,
            live_pair_skin: 0.01,
        }
    }
}
