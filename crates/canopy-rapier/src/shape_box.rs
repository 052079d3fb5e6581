//! A collider's collision box (`Collider::compute_collision_aabb`) with the arithmetic of the
//! three commonest shapes (ball, cuboid, capsule) written out here, so that it inlines into the
//! examine loop: parry reaches it through a virtual `compute_aabb` and nalgebra's generic
//! matrix code. The result is the same to the bit: every coordinate is computed by the same
//! floating-point operations in the same order as parry 0.22 and nalgebra 0.33 do (quaternion
//! to matrix, absolute value, matrix times vector as nalgebra's `gemv` sums it, the quaternion
//! rotation of a point, simba's `simd_min`/`simd_max` for the capsule's corners, then the
//! loosening), which the tests check against `compute_collision_aabb` on random shapes and
//! poses. Balls' and cuboids' boxes come as `BoxLanes`, which the examine loop stores and tests
//! without taking them apart. Other shapes go through parry. A build whose parry or nalgebra computes these boxes
//! otherwise (another release) is caught at run time too: `written_out_agrees` compares both on
//! a fixed set of shapes and poses once per process, and the broadphase keeps to parry's path
//! when they differ.

use crate::box_lanes::BoxLanes;
use rapier3d::geometry::{Collider, ColliderBuilder};
use rapier3d::math::{Isometry, Point, Real, Translation, Vector};
use rapier3d::na::{Quaternion, UnitQuaternion};
use rapier3d::parry::bounding_volume::Aabb as ParryAabb;
use rapier3d::parry::shape::TypedShape;
use std::sync::OnceLock;

/// `collider.compute_collision_aabb(prediction)`, bit for bit.
#[inline(always)]
pub(crate) fn collision_box(collider: &Collider, prediction: Real) -> ParryAabb {
    match written_box(collider, prediction) {
        Written::Lanes(lanes) => {
            let a = lanes.to_aabb();
            ParryAabb::new(a.min, a.max)
        }
        Written::Capsule(b) => b,
        Written::Unwritten => collider.compute_collision_aabb(prediction),
    }
}

/// A collision box from `written_box`.
pub(crate) enum Written {
    /// A ball's or a cuboid's, still in vector registers.
    Lanes(BoxLanes),
    /// A capsule's.
    Capsule(ParryAabb),
    /// Not written out here: another shape, or a negative or NaN loosening (which parry
    /// refuses).
    Unwritten,
}

/// `collider.compute_collision_aabb(prediction)`, bit for bit, for the shapes written out
/// here: balls and cuboids as `BoxLanes` (stored and tested against the fat box without
/// leaving vector registers), capsules as a box.
#[inline(always)]
pub(crate) fn written_box(collider: &Collider, prediction: Real) -> Written {
    // The shape first: the amount computed after the (virtual) call stays in a register.
    let shape = collider.shape().as_typed_shape();
    let amount = collider.contact_skin() + prediction;
    if amount.is_nan() || amount < 0.0 {
        return Written::Unwritten;
    }
    let pos = collider.position();
    let (mins, maxs) = match shape {
        TypedShape::Ball(b) => {
            let c = pos.translation.vector;
            let r = b.radius;
            return Written::Lanes(BoxLanes::around([c.x, c.y, c.z], [r, r, r], amount));
        }
        TypedShape::Cuboid(c) => {
            let t = pos.translation.vector;
            let h = abs_rotated(pos, &c.half_extents);
            return Written::Lanes(BoxLanes::around([t.x, t.y, t.z], [h.x, h.y, h.z], amount));
        }
        TypedShape::Capsule(c) => {
            let a = transform_point(pos, &c.segment.a);
            let b = transform_point(pos, &c.segment.b);
            let r = c.radius;
            // nalgebra's `inf`/`sup` (simba's `simd_min`/`simd_max`): the first operand unless
            // the comparison fails, which differs from `f32::min`/`max` on NaNs and signed
            // zeros.
            let min = |x: Real, y: Real| if x <= y { x } else { y };
            let max = |x: Real, y: Real| if x >= y { x } else { y };
            (
                Vector::new(min(a.x, b.x), min(a.y, b.y), min(a.z, b.z)).map(|x| x - r),
                Vector::new(max(a.x, b.x), max(a.y, b.y), max(a.z, b.z)).map(|x| x + r),
            )
        }
        _ => return Written::Unwritten,
    };
    // `Aabb::loosened`.
    Written::Capsule(ParryAabb::new(
        Point::from(mins.map(|x| x + -amount)),
        Point::from(maxs.map(|x| x + amount)),
    ))
}

/// Whether `collision_box` gives parry's boxes, bit for bit, on balls, cuboids and capsules in
/// a fixed set of poses (rotations about every axis, translations of several magnitudes),
/// checked on first use, once per process.
pub(crate) fn written_out_agrees() -> bool {
    static AGREES: OnceLock<bool> = OnceLock::new();
    *AGREES.get_or_init(|| {
        let shapes = [
            ColliderBuilder::ball(0.5),
            ColliderBuilder::cuboid(0.5, 0.25, 1.5),
            ColliderBuilder::capsule_y(0.3, 0.4),
            ColliderBuilder::capsule_from_endpoints(
                Point::new(0.1, -0.7, 0.3),
                Point::new(-0.4, 0.2, 0.9),
                0.2,
            ),
        ];
        let mut seed = 0x9e37_79b9_u32;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f32 / u32::MAX as f32 * 2.0 - 1.0
        };
        (0..64).all(|k| {
            let q = Quaternion::new(next(), next(), next(), next());
            let scale = [1.0, 100.0, 1.0e5][k % 3];
            let t = Translation::new(next() * scale, next() * scale, next() * scale);
            let pos = Isometry::from_parts(t, UnitQuaternion::from_quaternion(q));
            let collider = shapes[k % shapes.len()]
                .clone()
                .position(pos)
                .contact_skin(0.01 * (k % 2) as Real)
                .build();
            let (a, b) = (
                collision_box(&collider, 0.001),
                collider.compute_collision_aabb(0.001),
            );
            a.mins.coords.map(Real::to_bits) == b.mins.coords.map(Real::to_bits)
                && a.maxs.coords.map(Real::to_bits) == b.maxs.coords.map(Real::to_bits)
        })
    })
}

/// `|R| v`, with `R` the rotation matrix of `pos`: nalgebra's `to_rotation_matrix` entry by
/// entry, then each row summed as its `gemv` does (column 0, plus column 1, plus column 2).
#[inline(always)]
fn abs_rotated(pos: &Isometry<Real>, v: &Vector<Real>) -> Vector<Real> {
    let q = pos.rotation.quaternion();
    let (i, j, k, w) = (q.i, q.j, q.k, q.w);
    let (ww, ii, jj, kk) = (w * w, i * i, j * j, k * k);
    let ij = i * j * 2.0;
    let wk = w * k * 2.0;
    let wj = w * j * 2.0;
    let ik = i * k * 2.0;
    let jk = j * k * 2.0;
    let wi = w * i * 2.0;
    let m = [
        [ww + ii - jj - kk, ij - wk, wj + ik],
        [wk + ij, ww - ii + jj - kk, jk - wi],
        [ik - wj, wi + jk, ww - ii - jj + kk],
    ];
    let row = |r: [Real; 3]| r[0].abs() * v.x + r[1].abs() * v.y + r[2].abs() * v.z;
    Vector::new(row(m[0]), row(m[1]), row(m[2]))
}

/// `pos * p`: nalgebra's rotation of a vector by a unit quaternion (`t = 2 (q × p)`, then
/// `t w + q × t + p`), then the translation.
#[inline(always)]
fn transform_point(pos: &Isometry<Real>, p: &Point<Real>) -> Vector<Real> {
    let q = pos.rotation.quaternion();
    let (qv, w) = (q.vector(), q.w);
    let cross = |a: &Vector<Real>, b: &Vector<Real>| {
        Vector::new(
            a.y * b.z - a.z * b.y,
            a.z * b.x - a.x * b.z,
            a.x * b.y - a.y * b.x,
        )
    };
    let qv = Vector::new(qv.x, qv.y, qv.z);
    let t = cross(&qv, &p.coords) * 2.0;
    let c = cross(&qv, &t);
    t * w + c + p.coords + pos.translation.vector
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use rapier3d::prelude::*;

    fn bits(a: &ParryAabb) -> [u32; 6] {
        [a.mins.x, a.mins.y, a.mins.z, a.maxs.x, a.maxs.y, a.maxs.z].map(f32::to_bits)
    }

    fn coord() -> impl Strategy<Value = f32> {
        prop_oneof![
            -10.0f32..10.0,
            -1.0e6f32..1.0e6,
            Just(0.0f32),
            Just(-0.0f32),
            -1.0e-6f32..1.0e-6,
        ]
    }

    fn size() -> impl Strategy<Value = f32> {
        prop_oneof![0.0f32..5.0, Just(0.0f32), 0.0f32..1.0e4]
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(2000))]
        /// Bit for bit what Rapier computes, for every shape written out here, at any pose
        /// (quaternions from any four numbers, normalized as nalgebra does), skin and
        /// prediction distance.
        #[test]
        fn collision_box_matches_rapier_bit_for_bit(
            kind in 0..4usize,
            (a, b, c) in (size(), size(), size()),
            t in prop::array::uniform3(coord()),
            q in prop::array::uniform4(-1.0f32..1.0),
            skin in prop_oneof![Just(0.0f32), 0.0f32..0.5],
            prediction in prop_oneof![Just(0.0f32), 0.0f32..0.5],
        ) {
            let builder = match kind {
                0 => ColliderBuilder::ball(a),
                1 => ColliderBuilder::cuboid(a, b, c),
                2 => ColliderBuilder::capsule_y(a, b),
                _ => ColliderBuilder::capsule_from_endpoints(
                    point![a, -b, c],
                    point![-c, a, b],
                    b,
                ),
            };
            let quat = rapier3d::na::Quaternion::new(q[3], q[0], q[1], q[2]);
            prop_assume!(quat.norm() > 1.0e-3);
            let rot = rapier3d::na::UnitQuaternion::from_quaternion(quat);
            let pos = Isometry::from_parts(Translation::new(t[0], t[1], t[2]), rot);
            let collider = builder.position(pos).contact_skin(skin).build();
            prop_assert_eq!(
                bits(&collision_box(&collider, prediction)),
                bits(&collider.compute_collision_aabb(prediction))
            );
        }
    }

    /// The run-time check passes with the parry and nalgebra this crate is built with.
    #[test]
    fn written_out_agrees_here() {
        assert!(written_out_agrees());
    }

    /// Capsules whose endpoints tie on an axis with zeros of both signs, or where one endpoint
    /// is NaN: nalgebra's corner picks (the first operand unless the comparison fails) decide
    /// the bits, and `f32::min`/`max` would pick otherwise.
    #[test]
    fn capsule_corners_tie_as_in_nalgebra() {
        // A NaN coordinate spreads to the whole rotated point (0 * NaN in the cross products).
        let ends = [
            (point![0.0, -1.0, -0.0], point![-0.0, 1.0, 0.0]),
            (point![-0.0, -1.0, 0.0], point![0.0, 1.0, -0.0]),
            (point![0.5, -1.0, 0.0], point![f32::NAN, 1.0, 2.0]),
            (point![f32::NAN, -1.0, 0.0], point![0.5, 1.0, 2.0]),
        ];
        for ((a, b), t) in ends.into_iter().flat_map(|e| [(e, 0.0), (e, -0.0)]) {
            let collider = ColliderBuilder::capsule_from_endpoints(a, b, 0.0)
                .translation(vector![t, t, t])
                .contact_skin(0.0)
                .build();
            assert_eq!(
                bits(&collision_box(&collider, 0.0)),
                bits(&collider.compute_collision_aabb(0.0)),
                "{a:?} {b:?} at {t:?}"
            );
        }
    }

    /// Shapes not written out here go through parry, and non-finite poses give what parry
    /// gives (compared as bits, NaNs included).
    #[test]
    fn other_shapes_and_non_finite_poses_match_rapier() {
        let shapes = [
            ColliderBuilder::cylinder(0.5, 0.3),
            ColliderBuilder::cone(0.5, 0.3),
            ColliderBuilder::ball(0.5),
            ColliderBuilder::cuboid(0.5, 0.2, 0.1),
            ColliderBuilder::capsule_z(0.5, 0.2),
        ];
        for builder in shapes {
            for t in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, f32::MAX, 3.0] {
                let mut collider = builder.clone().build();
                collider.set_translation(vector![t, 1.0, -t]);
                assert_eq!(
                    bits(&collision_box(&collider, 0.002)),
                    bits(&collider.compute_collision_aabb(0.002)),
                    "{:?} at {t}",
                    collider.shape().shape_type()
                );
            }
        }
    }
}
