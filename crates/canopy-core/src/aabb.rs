//! Axis-aligned bounding boxes (`Aabb`), the one primitive shape canopy-core knows about.
//!
//! Boxes are closed: two boxes that only touch on a face, edge or corner overlap. Builders and
//! queries take `Aabb` at the API (nalgebra points); inside the tree, nodes keep plain
//! `[f32; 3]` bounds (see `bvh.rs`).

use crate::build::f4::{aabb_box, overlap};
use nalgebra::{Point3, Vector3};

/// An axis-aligned bounding box in 3D, `f32` coordinates, closed on every face.
///
/// A box is *valid* when every coordinate is finite and `min <= max` on every axis; zero-size
/// boxes (points, segments, flat boxes) are valid. [`Aabb::EMPTY`] is the identity of
/// [`Aabb::merge`] and is not valid.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub struct Aabb {
    /// Smallest corner.
    pub min: Point3<f32>,
    /// Largest corner.
    pub max: Point3<f32>,
}

impl Aabb {
    /// The empty box: `min = +inf`, `max = -inf`. Merging anything into it gives that thing.
    pub const EMPTY: Aabb = Aabb {
        min: Point3::new(f32::INFINITY, f32::INFINITY, f32::INFINITY),
        max: Point3::new(f32::NEG_INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY),
    };

    /// A box from its two corners (not checked; see [`Aabb::is_valid`]).
    #[inline]
    pub fn new(min: Point3<f32>, max: Point3<f32>) -> Self {
        Self { min, max }
    }

    /// A box from two corners given as arrays.
    #[inline]
    pub fn from_arrays(min: [f32; 3], max: [f32; 3]) -> Self {
        Self::new(min.into(), max.into())
    }

    /// The zero-size box at `p`.
    #[inline]
    pub fn from_point(p: Point3<f32>) -> Self {
        Self::new(p, p)
    }

    /// A box of half-extents `half` centred on `center`.
    #[inline]
    pub fn from_center_half_extents(center: Point3<f32>, half: Vector3<f32>) -> Self {
        Self::new(center - half, center + half)
    }

    /// The smallest box holding every point of `points` ([`Aabb::EMPTY`] when there are none).
    pub fn from_points<'a>(points: impl IntoIterator<Item = &'a Point3<f32>>) -> Self {
        points
            .into_iter()
            .fold(Self::EMPTY, |b, p| b.merge(&Self::from_point(*p)))
    }

    /// `true` when every coordinate is finite and `min <= max` on every axis.
    #[inline]
    pub fn is_valid(&self) -> bool {
        (0..3).all(|i| {
            self.min[i].is_finite() && self.max[i].is_finite() && self.min[i] <= self.max[i]
        })
    }

    /// `true` when every coordinate is finite (the box may still be inverted).
    #[inline]
    pub fn is_finite(&self) -> bool {
        (0..3).all(|i| self.min[i].is_finite() && self.max[i].is_finite())
    }

    /// The smallest box holding both `self` and `other`.
    #[inline]
    pub fn merge(&self, other: &Aabb) -> Aabb {
        Aabb::new(self.min.inf(&other.min), self.max.sup(&other.max))
    }

    /// `true` when the closed boxes share at least one point.
    #[inline]
    pub fn intersects(&self, other: &Aabb) -> bool {
        self.min.x <= other.max.x
            && other.min.x <= self.max.x
            && self.min.y <= other.max.y
            && other.min.y <= self.max.y
            && self.min.z <= other.max.z
            && other.min.z <= self.max.z
    }

    /// [`Aabb::intersects`] without early exits: all six comparisons, combined bitwise, so
    /// that no branch waits on the boxes or mispredicts on a partial overlap (for loops over
    /// many box pairs whose answers are hard to predict). Two four-lane comparisons (SSE on
    /// x86-64), as the tree walks test a primitive's box.
    #[inline]
    pub fn intersects_branchless(&self, other: &Aabb) -> bool {
        let (a_lo, a_hi) = aabb_box(self);
        let (b_lo, b_hi) = aabb_box(other);
        overlap(a_lo, a_hi, b_lo, b_hi)
    }

    /// `true` when `p` lies inside the closed box.
    #[inline]
    pub fn contains_point(&self, p: &Point3<f32>) -> bool {
        (0..3).all(|i| self.min[i] <= p[i] && p[i] <= self.max[i])
    }

    /// `true` when `other` lies inside the closed box.
    #[inline]
    pub fn contains(&self, other: &Aabb) -> bool {
        (0..3).all(|i| self.min[i] <= other.min[i] && other.max[i] <= self.max[i])
    }

    /// [`Aabb::contains`] without early exits: all six comparisons, combined bitwise, so that
    /// no branch waits on the boxes (for loops where the answer is hard to predict and the
    /// boxes arrive late from memory). Scalar on purpose, unlike
    /// [`Aabb::intersects_branchless`]: its callers test a box they have just computed, and a
    /// 16-byte load of a box written moments before in smaller pieces waits for those stores
    /// to reach the cache (the SSE form made canopy-rapier's `balls` update 10% slower).
    #[inline]
    pub fn contains_branchless(&self, other: &Aabb) -> bool {
        (self.min.x <= other.min.x)
            & (other.max.x <= self.max.x)
            & (self.min.y <= other.min.y)
            & (other.max.y <= self.max.y)
            & (self.min.z <= other.min.z)
            & (other.max.z <= self.max.z)
    }

    /// The centre point, computed without overflow for boxes near `f32::MAX`.
    #[inline]
    pub fn center(&self) -> Point3<f32> {
        Point3::from(self.min.coords * 0.5 + self.max.coords * 0.5)
    }

    /// Size along each axis.
    #[inline]
    pub fn extents(&self) -> Vector3<f32> {
        self.max - self.min
    }

    /// Surface area, in `f64` so that boxes with huge coordinates do not overflow.
    #[inline]
    pub fn surface_area(&self) -> f64 {
        surface_area(
            [self.min.x, self.min.y, self.min.z],
            [self.max.x, self.max.y, self.max.z],
        )
    }

    /// The box grown by `margin` on every side (shrunk when `margin` is negative).
    #[inline]
    pub fn loosened(&self, margin: f32) -> Aabb {
        let m = Vector3::repeat(margin);
        Aabb::new(self.min - m, self.max + m)
    }

    /// Squared Euclidean distance from `p` to the box (0 inside), in `f32`: infinite where the
    /// square passes `f32::MAX` (distances beyond about 1.8e19), which
    /// [`distance_to_point`](Self::distance_to_point) does not do.
    #[inline]
    pub fn distance_squared_to_point(&self, p: &Point3<f32>) -> f32 {
        distance_squared(
            [self.min.x, self.min.y, self.min.z],
            [self.max.x, self.max.y, self.max.z],
            p,
        )
    }

    /// Euclidean distance from `p` to the box (0 inside), computed in `f64` and rounded to
    /// `f32`: exact to rounding for any finite box and point (infinite only for a distance
    /// past `f32::MAX`).
    #[inline]
    pub fn distance_to_point(&self, p: &Point3<f32>) -> f32 {
        distance(self.min_array(), self.max_array(), p)
    }

    pub(crate) fn min_array(&self) -> [f32; 3] {
        [self.min.x, self.min.y, self.min.z]
    }

    pub(crate) fn max_array(&self) -> [f32; 3] {
        [self.max.x, self.max.y, self.max.z]
    }
}

/// Surface area of the box `[min, max]` in `f64`; 0 for empty or inverted boxes.
#[inline]
pub(crate) fn surface_area(min: [f32; 3], max: [f32; 3]) -> f64 {
    let dx = (max[0] as f64 - min[0] as f64).max(0.0);
    let dy = (max[1] as f64 - min[1] as f64).max(0.0);
    let dz = (max[2] as f64 - min[2] as f64).max(0.0);
    2.0 * (dx * dy + dy * dz + dz * dx)
}

/// Closed-interval overlap test on raw bounds.
#[inline(always)]
pub(crate) fn overlaps(amin: &[f32; 3], amax: &[f32; 3], bmin: &[f32; 3], bmax: &[f32; 3]) -> bool {
    amin[0] <= bmax[0]
        && bmin[0] <= amax[0]
        && amin[1] <= bmax[1]
        && bmin[1] <= amax[1]
        && amin[2] <= bmax[2]
        && bmin[2] <= amax[2]
}

/// Squared distance from `p` to the box `[min, max]` on raw bounds.
#[inline(always)]
pub(crate) fn distance_squared(min: [f32; 3], max: [f32; 3], p: &Point3<f32>) -> f32 {
    let mut d = 0.0;
    for i in 0..3 {
        let v = (min[i] - p[i]).max(0.0).max(p[i] - max[i]);
        d += v * v;
    }
    d
}

/// Euclidean distance from `p` to the box `[min, max]` on raw bounds: the differences and
/// their squares in `f64`, so nothing overflows before the result is rounded to `f32` (in
/// `f32`, squares overflow for distances beyond about 1.8e19). A NaN difference counts as 0,
/// as in `distance_squared`.
#[inline]
pub(crate) fn distance(min: [f32; 3], max: [f32; 3], p: &Point3<f32>) -> f32 {
    let mut d = 0.0f64;
    for i in 0..3 {
        let below = min[i] as f64 - p[i] as f64;
        let above = p[i] as f64 - max[i] as f64;
        let v = below.max(0.0).max(above);
        d += v * v;
    }
    d.sqrt() as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn touching_boxes_overlap() {
        let a = Aabb::from_arrays([0.0; 3], [1.0; 3]);
        let b = Aabb::from_arrays([1.0, 0.0, 0.0], [2.0, 1.0, 1.0]);
        let c = Aabb::from_arrays([1.0001, 0.0, 0.0], [2.0, 1.0, 1.0]);
        assert!(a.intersects(&b) && b.intersects(&a));
        assert!(!a.intersects(&c));
    }

    #[test]
    fn validity() {
        assert!(Aabb::from_point(Point3::new(1.0, 2.0, 3.0)).is_valid());
        assert!(!Aabb::EMPTY.is_valid());
        assert!(!Aabb::from_arrays([f32::NAN, 0.0, 0.0], [1.0; 3]).is_valid());
        assert!(!Aabb::from_arrays([0.0; 3], [f32::INFINITY, 1.0, 1.0]).is_valid());
        assert!(!Aabb::from_arrays([2.0, 0.0, 0.0], [1.0; 3]).is_valid());
    }

    #[test]
    fn huge_boxes_do_not_overflow() {
        let b = Aabb::from_arrays([-f32::MAX; 3], [f32::MAX; 3]);
        assert!(b.surface_area().is_finite());
        assert!(b.center().coords.iter().all(|c| c.is_finite()));
    }

    #[test]
    fn distance() {
        let b = Aabb::from_arrays([0.0; 3], [1.0; 3]);
        assert_eq!(b.distance_to_point(&Point3::new(0.5, 0.5, 0.5)), 0.0);
        assert_eq!(b.distance_to_point(&Point3::new(3.0, 0.5, 0.5)), 2.0);
        assert_eq!(b.merge(&Aabb::EMPTY), b);
    }
}
