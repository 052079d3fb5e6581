//! Rays with a precomputed inverse direction, and the slab test against boxes used by the ray
//! queries in `query/ray.rs`.

use crate::aabb::Aabb;
use nalgebra::{Point3, Vector3};

/// A ray `origin + t * dir`, `t >= 0`, with its inverse direction precomputed for slab tests.
///
/// `dir` need not be normalised: times of impact are in units of `dir`. A zero component gives
/// an infinite inverse, which the slab test handles (a ray lying exactly in a box's face plane
/// may be reported as missing that box; every other ray is exact up to rounding).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Start point.
    pub origin: Point3<f32>,
    /// Direction.
    pub dir: Vector3<f32>,
    /// Component-wise `1 / dir`.
    pub inv_dir: Vector3<f32>,
}

impl Ray {
    /// A ray from `origin` along `dir`.
    #[inline]
    pub fn new(origin: Point3<f32>, dir: Vector3<f32>) -> Self {
        Self {
            origin,
            dir,
            inv_dir: Vector3::new(1.0 / dir.x, 1.0 / dir.y, 1.0 / dir.z),
        }
    }

    /// The point at time `t`.
    #[inline]
    pub fn point_at(&self, t: f32) -> Point3<f32> {
        self.origin + self.dir * t
    }

    /// `true` when origin and direction are finite and the direction is not zero.
    pub fn is_valid(&self) -> bool {
        self.origin.coords.iter().all(|c| c.is_finite())
            && self.dir.iter().all(|c| c.is_finite())
            && self.dir != Vector3::zeros()
    }

    /// `true` when origin and direction are finite (the direction may be zero).
    #[inline]
    pub(crate) fn is_finite(&self) -> bool {
        self.origin.coords.iter().all(|c| c.is_finite()) && self.dir.iter().all(|c| c.is_finite())
    }

    /// Entry time of the ray into `aabb` within `[0, t_max]`, or `None` when it misses.
    /// A ray starting inside the box enters at `t = 0`; a ray whose direction is zero enters
    /// only a box it starts in. Nothing is entered by a ray with a NaN or infinite origin or
    /// direction, nor with a NaN `t_max`.
    #[inline]
    pub fn intersect_aabb(&self, aabb: &Aabb, t_max: f32) -> Option<f32> {
        self.clip_aabb(aabb, t_max).map(|(entry, _)| entry)
    }

    /// Entry and exit times of the ray in `aabb` within `[0, t_max]` (the exit is `t_max`
    /// where the ray is still inside then), or `None` when it misses: the same test as
    /// [`intersect_aabb`](Self::intersect_aabb), which gives the entry.
    #[inline]
    pub fn clip_aabb(&self, aabb: &Aabb, t_max: f32) -> Option<(f32, f32)> {
        if t_max.is_nan() || !self.is_finite() {
            return None;
        }
        self.slab_interval(&aabb.min_array(), &aabb.max_array(), t_max)
    }

    /// Slab test on raw bounds: entry time in `[0, t_max]`, or `None`. An entry time that
    /// is infinite (a zero direction component with the box on its positive side, or an
    /// entry too far for `f32`) is no entry, also for an infinite `t_max`.
    #[inline(always)]
    pub(crate) fn slab(&self, min: &[f32; 3], max: &[f32; 3], t_max: f32) -> Option<f32> {
        self.slab_interval(min, max, t_max).map(|(entry, _)| entry)
    }

    /// [`Ray::slab`] with the exit time too.
    #[inline(always)]
    fn slab_interval(&self, min: &[f32; 3], max: &[f32; 3], t_max: f32) -> Option<(f32, f32)> {
        let mut t0 = 0.0f32;
        let mut t1 = t_max;
        for i in 0..3 {
            let a = (min[i] - self.origin[i]) * self.inv_dir[i];
            let b = (max[i] - self.origin[i]) * self.inv_dir[i];
            // `f32::min`/`max` drop a NaN operand (0 * inf when the origin lies on a face
            // plane of an axis the ray is parallel to), which keeps the test conservative.
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        (t0 <= t1 && t0 < f32::INFINITY).then_some((t0, t1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slab_hits_and_misses() {
        let b = Aabb::from_arrays([1.0, -1.0, -1.0], [2.0, 1.0, 1.0]);
        let r = Ray::new(Point3::origin(), Vector3::x());
        assert_eq!(r.intersect_aabb(&b, 10.0), Some(1.0));
        assert_eq!(r.intersect_aabb(&b, 0.5), None);
        let r = Ray::new(Point3::origin(), -Vector3::x());
        assert_eq!(r.intersect_aabb(&b, 10.0), None);
        let inside = Ray::new(Point3::new(1.5, 0.0, 0.0), Vector3::y());
        assert_eq!(inside.intersect_aabb(&b, 10.0), Some(0.0));
    }

    /// `clip_aabb` gives the entry of `intersect_aabb` and the exit, capped at `t_max`.
    #[test]
    fn clip_gives_entry_and_exit() {
        let b = Aabb::from_arrays([1.0, -1.0, -1.0], [2.0, 1.0, 1.0]);
        let r = Ray::new(Point3::origin(), Vector3::x());
        assert_eq!(r.clip_aabb(&b, 10.0), Some((1.0, 2.0)));
        assert_eq!(r.clip_aabb(&b, 1.5), Some((1.0, 1.5)));
        assert_eq!(r.clip_aabb(&b, 0.5), None);
        let inside = Ray::new(Point3::new(1.5, 0.0, 0.0), Vector3::new(0.0, 2.0, 0.0));
        assert_eq!(inside.clip_aabb(&b, 10.0), Some((0.0, 0.5)));
        let still = Ray::new(Point3::new(1.5, 0.0, 0.0), Vector3::zeros());
        assert_eq!(
            still.clip_aabb(&b, f32::INFINITY),
            Some((0.0, f32::INFINITY))
        );
        let nan = Ray::new(Point3::new(f32::NAN, 0.0, 0.0), Vector3::x());
        assert_eq!(nan.clip_aabb(&b, 10.0), None);
    }

    /// Rays that go nowhere or are not numbers, and a NaN time limit: a zero direction enters
    /// only the box it starts in (it used to enter, at `t = inf`, every box lying on the
    /// positive side of its origin on each axis); a NaN or infinite origin or direction enters
    /// nothing (it used to enter every box at `t = 0`); a NaN `t_max` enters nothing (it
    /// used to count as infinite), as `Bvh::cast_ray` answers for it.
    #[test]
    fn degenerate_rays_enter_only_where_they_start() {
        let b = Aabb::from_arrays([0.0; 3], [1.0; 3]);
        let still = |x: f32| Ray::new(Point3::new(x, 0.5, 0.5), Vector3::zeros());
        for t_max in [10.0, f32::INFINITY] {
            assert_eq!(still(-5.0).intersect_aabb(&b, t_max), None);
            assert_eq!(still(5.0).intersect_aabb(&b, t_max), None);
            assert_eq!(still(0.5).intersect_aabb(&b, t_max), Some(0.0));
        }
        let x = Vector3::x();
        for bad in [f32::NAN, f32::INFINITY, -f32::INFINITY] {
            let origin = Ray::new(Point3::new(bad, 0.5, 0.5), x);
            let dir = Ray::new(Point3::new(-5.0, 0.5, 0.5), Vector3::new(bad, 0.0, 0.0));
            assert_eq!(origin.intersect_aabb(&b, f32::INFINITY), None, "{bad}");
            assert_eq!(dir.intersect_aabb(&b, f32::INFINITY), None, "{bad}");
        }
        let ray = Ray::new(Point3::new(-5.0, 0.5, 0.5), x);
        assert_eq!(ray.intersect_aabb(&b, f32::NAN), None);
        assert_eq!(ray.intersect_aabb(&b, f32::INFINITY), Some(5.0));
        // An entry too far for `f32` is no entry.
        let slow = Ray::new(Point3::new(-5.0, 0.5, 0.5), Vector3::new(1.0e-38, 0.0, 0.0));
        assert_eq!(slow.intersect_aabb(&b, f32::INFINITY), None);
    }
}
