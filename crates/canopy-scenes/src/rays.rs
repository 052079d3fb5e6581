//! The standard ray batch of the ray-cast example and benchmark: rays from points spread over
//! a scene's colliders, in uniformly random directions, deterministic for a seed.

use crate::rng::XorShift;
use rapier3d::geometry::{ColliderSet, Ray};
use rapier3d::math::{Point, Real, Vector};

/// `n` rays over `colliders`: origins uniform in the box around the enabled colliders'
/// centres (grown by 10% on each side), directions uniform on the unit sphere. The same
/// colliders, `n` and `seed` always give the same rays. Empty sets give rays around the origin.
///
/// ```
/// use canopy_scenes::{ray_batch, scene, Size};
///
/// let scene = scene("many_static", Size::Small).unwrap();
/// let rays = ray_batch(&scene.colliders, 100, 1);
/// assert_eq!(rays.len(), 100);
/// assert!(rays.iter().all(|r| (r.dir.norm() - 1.0).abs() < 1e-5));
/// ```
pub fn ray_batch(colliders: &ColliderSet, n: usize, seed: u64) -> Vec<Ray> {
    let mut lo = Vector::repeat(Real::MAX);
    let mut hi = Vector::repeat(Real::MIN);
    for (_, c) in colliders.iter_enabled() {
        let t = c.translation();
        lo = lo.inf(t);
        hi = hi.sup(t);
    }
    if lo.x > hi.x {
        lo = Vector::repeat(-1.0);
        hi = Vector::repeat(1.0);
    }
    let grow = (hi - lo) * 0.1;
    let (lo, hi) = (lo - grow, hi + grow);
    let mut rng = XorShift::new(seed);
    (0..n)
        .map(|_| {
            let origin = Point::from(
                lo + (hi - lo).component_mul(&Vector::new(
                    rng.next_f32(),
                    rng.next_f32(),
                    rng.next_f32(),
                )),
            );
            // Uniform on the sphere: z uniform in [-1, 1], angle uniform.
            let z = 2.0 * rng.next_f32() - 1.0;
            let a = std::f32::consts::TAU * rng.next_f32();
            let r = (1.0 - z * z).max(0.0).sqrt();
            Ray::new(origin, Vector::new(r * a.cos(), r * a.sin(), z))
        })
        .collect()
}
