//! Conversions between parry's and canopy-core's axis-aligned boxes.

use canopy_core::Aabb;
use parry3d::bounding_volume::Aabb as ParryAabb;

/// The canopy-core box with the same corners.
#[inline]
pub fn to_canopy(aabb: &ParryAabb) -> Aabb {
    Aabb::new(aabb.mins, aabb.maxs)
}

/// The parry box with the same corners.
#[inline]
pub fn to_parry(aabb: &Aabb) -> ParryAabb {
    ParryAabb::new(aabb.min, aabb.max)
}
