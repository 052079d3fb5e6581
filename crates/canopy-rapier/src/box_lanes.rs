//! `BoxLanes`: a box's six floats as two overlapping four-lane vectors, the way the examine
//! loop computes a collider's exact box, stores it, tests it against the fat box and makes the
//! new fat box, without moving single floats between registers: `lo` holds `min.x, min.y,
//! min.z, max.x` (the box's floats 0..4) and `hi` holds `min.z, max.x, max.y, max.z` (floats
//! 2..6). SSE on x86_64 (always there), plain arrays elsewhere. Both compute every coordinate
//! of a collision box with the same floating-point operations as parry does, so those boxes
//! are the same to the bit (a NaN stays a NaN; its sign and payload are not kept by the
//! compiler anyway).

use canopy_core::Aabb;
use rapier3d::parry::bounding_volume::Aabb as ParryAabb;

/// A box as two overlapping windows of its six floats (see the module comment).
#[derive(Clone, Copy, Debug)]
pub(crate) struct BoxLanes {
    lo: imp::V,
    hi: imp::V,
}

/// In the lanes of `lo`, then of `hi`: whether the lane is a lower corner's coordinate.
const LO_LOWER: [bool; 4] = [true, true, true, false];
const HI_LOWER: [bool; 4] = [true, false, false, false];

impl BoxLanes {
    /// The box with lower corner `(c - h) - pad` and upper corner `(c + h) + pad` on each
    /// axis: parry's box of a ball or cuboid, then its `loosened(pad)`.
    #[inline(always)]
    pub(crate) fn around(c: [f32; 3], h: [f32; 3], pad: f32) -> Self {
        let [x, y, z] = c;
        let [hx, hy, hz] = h;
        let lo = imp::around([x, y, z, x], [hx, hy, hz, hx], pad, LO_LOWER);
        let hi = imp::around([z, x, y, z], [hz, hx, hy, hz], pad, HI_LOWER);
        Self { lo, hi }
    }

    /// The lanes of a stored box.
    #[inline(always)]
    pub(crate) fn load(a: &Aabb) -> Self {
        let (lo, hi) = imp::load(a);
        Self { lo, hi }
    }

    /// The lanes of a box parry just returned, read as parry's functions write a returned box
    /// (`Shape::compute_aabb` of balls, cuboids and capsules, `Collider::compute_collision_aabb`:
    /// 16 bytes, then 8): a load that straddled those two stores (as copying the box into an
    /// [`Aabb`] did) could not take its data from them and waited for both to reach the cache,
    /// twice per collider in the examine loop.
    #[inline(always)]
    pub(crate) fn load_parry(a: &ParryAabb) -> Self {
        let (lo, hi) = imp::load_parry(a);
        Self { lo, hi }
    }

    /// The box enlarged by `margin` on every side (`Aabb::loosened`), then stretched by `d`:
    /// each finite coordinate of `d` moves the lower side when negative, the upper side
    /// otherwise; a NaN or infinite one is left out. (The fat box of a proxy: `d` is the
    /// body's motion over the velocity stretch.) A side left where it was gets `+ 0.0`, which
    /// turns a `-0.0` into `0.0`: the same number.
    #[inline(always)]
    pub(crate) fn fattened(self, margin: f32, d: [f32; 3]) -> Self {
        let [x, y, z] = d;
        Self {
            lo: imp::fatten(self.lo, margin, [x, y, z, x], LO_LOWER),
            hi: imp::fatten(self.hi, margin, [z, x, y, z], HI_LOWER),
        }
    }

    /// The box enlarged by `amount` on every side with parry's operations (`mins + (-amount)`,
    /// `maxs + amount`): parry's `loosened`, to the bit.
    #[inline(always)]
    pub(crate) fn loosened(self, amount: f32) -> Self {
        Self {
            lo: imp::loosen(self.lo, amount, LO_LOWER),
            hi: imp::loosen(self.hi, amount, HI_LOWER),
        }
    }

    /// `Aabb::is_valid`: every coordinate finite and `min <= max` on every axis.
    #[inline(always)]
    pub(crate) fn is_valid(self) -> bool {
        imp::is_valid(self.lo, self.hi)
    }

    /// The box as an [`Aabb`].
    #[inline(always)]
    pub(crate) fn to_aabb(self) -> Aabb {
        let mut out = Aabb::EMPTY;
        self.write(&mut out);
        out
    }

    /// Stores the box into `out`.
    #[inline(always)]
    pub(crate) fn write(self, out: &mut Aabb) {
        imp::write(self.lo, self.hi, out);
    }

    /// `true` when the box lies inside the closed box `outer` (every comparison `<=`; a NaN
    /// on either side fails it): `outer.contains(&self.to_aabb())`.
    #[inline(always)]
    pub(crate) fn inside(self, outer: &Aabb) -> bool {
        imp::inside(self.lo, self.hi, outer)
    }
}

#[cfg(target_arch = "x86_64")]
use sse as imp;

#[cfg(not(target_arch = "x86_64"))]
use portable as imp;

#[cfg(target_arch = "x86_64")]
mod sse {
    use canopy_core::Aabb;
    use rapier3d::parry::bounding_volume::Aabb as ParryAabb;
    use std::arch::x86_64::*;

    pub(crate) type V = __m128;

    const _: () = assert!(std::mem::size_of::<Aabb>() == 24);
    const _: () = assert!(std::mem::size_of::<ParryAabb>() == 24);

    /// Per lane: `(c - h) - pad` where `lower`, else `(c + h) + pad` (a subtraction as the
    /// addition of the negated operand: the same number).
    #[inline(always)]
    pub(crate) fn around(c: [f32; 4], h: [f32; 4], pad: f32, lower: [bool; 4]) -> V {
        let mask = lane_mask(lower);
        // SAFETY: SSE2 is part of the x86_64 baseline; no memory is touched.
        unsafe {
            // The sign bit in the lower lanes: a xor with it negates them exactly.
            let sign = _mm_and_ps(mask, _mm_set1_ps(-0.0));
            let c = _mm_setr_ps(c[0], c[1], c[2], c[3]);
            let h = _mm_setr_ps(h[0], h[1], h[2], h[3]);
            let corner = _mm_add_ps(c, _mm_xor_ps(h, sign));
            _mm_add_ps(corner, _mm_xor_ps(_mm_set1_ps(pad), sign))
        }
    }

    /// All bits set in the lanes that are `true`.
    #[inline(always)]
    fn lane_mask(lanes: [bool; 4]) -> V {
        let all = |l: bool| if l { -1 } else { 0 };
        // SAFETY: SSE2 is part of the x86_64 baseline; no memory is touched.
        unsafe {
            _mm_castsi128_ps(_mm_setr_epi32(
                all(lanes[0]),
                all(lanes[1]),
                all(lanes[2]),
                all(lanes[3]),
            ))
        }
    }

    /// Per lane: `v + (-amount)` where `lower`, else `v + amount` (parry's `loosened`).
    #[inline(always)]
    pub(crate) fn loosen(v: V, amount: f32, lower: [bool; 4]) -> V {
        let lower = lane_mask(lower);
        // SAFETY: SSE2 is part of the x86_64 baseline; no memory is touched.
        unsafe {
            let sign = _mm_and_ps(lower, _mm_set1_ps(-0.0));
            _mm_add_ps(v, _mm_xor_ps(_mm_set1_ps(amount), sign))
        }
    }

    /// Per lane: `v - margin` where `lower`, else `v + margin`; then plus `d` where `d` is
    /// finite and negative (`lower` lanes) or finite and not negative (the others).
    #[inline(always)]
    pub(crate) fn fatten(v: V, margin: f32, d: [f32; 4], lower: [bool; 4]) -> V {
        let lower = lane_mask(lower);
        // SAFETY: SSE2 is part of the x86_64 baseline; no memory is touched.
        unsafe {
            let sign = _mm_and_ps(lower, _mm_set1_ps(-0.0));
            let v = _mm_add_ps(v, _mm_xor_ps(_mm_set1_ps(margin), sign));
            let d = _mm_setr_ps(d[0], d[1], d[2], d[3]);
            let finite = _mm_cmple_ps(_mm_andnot_ps(_mm_set1_ps(-0.0), d), _mm_set1_ps(f32::MAX));
            let negative = _mm_cmplt_ps(d, _mm_setzero_ps());
            // Lower lanes take the negative coordinates, the others the rest.
            let take = _mm_and_ps(
                finite,
                _mm_xor_ps(
                    negative,
                    _mm_xor_ps(lower, _mm_castsi128_ps(_mm_set1_epi32(-1))),
                ),
            );
            _mm_add_ps(v, _mm_and_ps(d, take))
        }
    }

    #[inline(always)]
    pub(crate) fn is_valid(lo: V, hi: V) -> bool {
        // SAFETY: SSE2 is part of the x86_64 baseline; no memory is touched.
        unsafe {
            let big = _mm_set1_ps(f32::MAX);
            let abs = |v: V| _mm_andnot_ps(_mm_set1_ps(-0.0), v);
            let finite = _mm_and_ps(_mm_cmple_ps(abs(lo), big), _mm_cmple_ps(abs(hi), big));
            // min.x, y, z (lanes 0..3 of `lo`) against max.x, y, z (lanes 1..4 of `hi`).
            let max = _mm_shuffle_ps::<0b11_11_10_01>(hi, hi);
            let ordered = _mm_movemask_ps(_mm_cmple_ps(lo, max));
            _mm_movemask_ps(finite) == 0b1111 && ordered & 0b0111 == 0b0111
        }
    }

    #[inline(always)]
    pub(crate) fn load(a: &Aabb) -> (V, V) {
        let p = (a as *const Aabb).cast::<f32>();
        // SAFETY: as in `write`, two unaligned loads within the box's 24 bytes.
        unsafe { (_mm_loadu_ps(p), _mm_loadu_ps(p.add(2))) }
    }

    #[inline(always)]
    pub(crate) fn load_parry(a: &ParryAabb) -> (V, V) {
        let p = (a as *const ParryAabb).cast::<f32>();
        // SAFETY: parry's `Aabb` is `repr(C)`, `mins` then `maxs`, six `f32` (24 bytes,
        // asserted above): floats 0..4, then floats 4..6 as one 8-byte load, both within it.
        unsafe {
            let lo = _mm_loadu_ps(p);
            let tail = _mm_castpd_ps(_mm_load_sd(p.add(4).cast::<f64>()));
            // min.z, max.x (lanes 2, 3 of `lo`), then max.y, max.z (lanes 0, 1 of `tail`).
            (lo, _mm_shuffle_ps::<0b01_00_11_10>(lo, tail))
        }
    }

    #[inline(always)]
    pub(crate) fn write(lo: V, hi: V, out: &mut Aabb) {
        let p = (out as *mut Aabb).cast::<f32>();
        // SAFETY: `Aabb` is `repr(C)`, six `f32` (`min` then `max`; 24 bytes, asserted above):
        // floats 0..4 and 2..6 both lie within it; unaligned stores.
        unsafe {
            _mm_storeu_ps(p, lo);
            _mm_storeu_ps(p.add(2), hi);
        }
    }

    #[inline(always)]
    pub(crate) fn inside(lo: V, hi: V, outer: &Aabb) -> bool {
        let p = (outer as *const Aabb).cast::<f32>();
        // SAFETY: as in `write`, two unaligned loads within the box's 24 bytes.
        unsafe {
            let (outer_lo, outer_hi) = (_mm_loadu_ps(p), _mm_loadu_ps(p.add(2)));
            // outer.min <= min (lanes 0..3 of `lo`), max <= outer.max (lanes 1..4 of `hi`).
            let low = _mm_movemask_ps(_mm_cmple_ps(outer_lo, lo));
            let high = _mm_movemask_ps(_mm_cmple_ps(hi, outer_hi));
            // Lane 3 of `low` and lane 0 of `high` are not part of the test.
            (low | 0b1000) & (high | 0b0001) == 0b1111
        }
    }
}

/// The same operations on plain arrays (built everywhere for the tests, which check that both
/// agree).
#[cfg(any(test, not(target_arch = "x86_64")))]
mod portable {
    use canopy_core::Aabb;
    use rapier3d::parry::bounding_volume::Aabb as ParryAabb;

    pub(crate) type V = [f32; 4];

    #[inline(always)]
    pub(crate) fn around(c: [f32; 4], h: [f32; 4], pad: f32, lower: [bool; 4]) -> V {
        std::array::from_fn(|i| {
            if lower[i] {
                (c[i] - h[i]) - pad
            } else {
                (c[i] + h[i]) + pad
            }
        })
    }

    #[inline(always)]
    pub(crate) fn loosen(v: V, amount: f32, lower: [bool; 4]) -> V {
        std::array::from_fn(|i| {
            if lower[i] {
                v[i] + -amount
            } else {
                v[i] + amount
            }
        })
    }

    #[inline(always)]
    pub(crate) fn fatten(v: V, margin: f32, d: [f32; 4], lower: [bool; 4]) -> V {
        std::array::from_fn(|i| {
            let v = if lower[i] {
                v[i] - margin
            } else {
                v[i] + margin
            };
            let take = d[i].is_finite() && (d[i] < 0.0) == lower[i];
            v + if take { d[i] } else { 0.0 }
        })
    }

    #[inline(always)]
    pub(crate) fn is_valid(lo: V, hi: V) -> bool {
        lo.iter().chain(&hi).all(|x| x.is_finite())
            && (lo[0] <= hi[1])
            && (lo[1] <= hi[2])
            && (lo[2] <= hi[3])
    }

    #[inline(always)]
    pub(crate) fn load(a: &Aabb) -> (V, V) {
        (
            [a.min.x, a.min.y, a.min.z, a.max.x],
            [a.min.z, a.max.x, a.max.y, a.max.z],
        )
    }

    #[inline(always)]
    pub(crate) fn load_parry(a: &ParryAabb) -> (V, V) {
        let (n, x) = (a.mins, a.maxs);
        ([n.x, n.y, n.z, x.x], [n.z, x.x, x.y, x.z])
    }

    #[inline(always)]
    pub(crate) fn write(lo: V, hi: V, out: &mut Aabb) {
        out.min = [lo[0], lo[1], lo[2]].into();
        out.max = [hi[1], hi[2], hi[3]].into();
    }

    #[inline(always)]
    pub(crate) fn inside(lo: V, hi: V, outer: &Aabb) -> bool {
        (outer.min.x <= lo[0])
            & (outer.min.y <= lo[1])
            & (outer.min.z <= lo[2])
            & (hi[1] <= outer.max.x)
            & (hi[2] <= outer.max.y)
            & (hi[3] <= outer.max.z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn coord() -> impl Strategy<Value = f32> {
        prop_oneof![
            -10.0f32..10.0,
            -1.0e30f32..1.0e30,
            Just(0.0f32),
            Just(-0.0f32),
            Just(f32::NAN),
            Just(-f32::NAN),
            Just(f32::INFINITY),
            Just(f32::NEG_INFINITY),
        ]
    }

    /// The box's bits, every NaN as one NaN (the compiler keeps no NaN's sign or payload).
    fn bits(a: &Aabb) -> [u32; 6] {
        [a.min.x, a.min.y, a.min.z, a.max.x, a.max.y, a.max.z]
            .map(|x| if x.is_nan() { f32::NAN } else { x }.to_bits())
    }

    /// The box of `around`, coordinate by coordinate.
    fn expected(c: [f32; 3], h: [f32; 3], pad: f32) -> Aabb {
        Aabb::from_arrays(
            [0, 1, 2].map(|i| (c[i] - h[i]) - pad),
            [0, 1, 2].map(|i| (c[i] + h[i]) + pad),
        )
    }

    /// The lanes of `a` as they are (not computed).
    fn lanes_of(a: &Aabb) -> ([f32; 4], [f32; 4]) {
        (
            [a.min.x, a.min.y, a.min.z, a.max.x],
            [a.min.z, a.max.x, a.max.y, a.max.z],
        )
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(3000))]
        /// `around` (through `write` and `to_aabb`) gives `(c - h) - pad` and `(c + h) + pad`
        /// to the bit, on both implementations.
        #[test]
        fn around_is_the_loosened_box(
            c in prop::array::uniform3(coord()),
            h in prop::array::uniform3(coord()),
            pad in coord(),
        ) {
            let want = bits(&expected(c, h, pad));
            let lanes = BoxLanes::around(c, h, pad);
            let mut out = Aabb::from_arrays([1.0; 3], [2.0; 3]);
            lanes.write(&mut out);
            prop_assert_eq!(bits(&out), want);
            prop_assert_eq!(bits(&lanes.to_aabb()), want);
            let [x, y, z] = c;
            let [hx, hy, hz] = h;
            let lo = portable::around([x, y, z, x], [hx, hy, hz, hx], pad, LO_LOWER);
            let hi = portable::around([z, x, y, z], [hz, hx, hy, hz], pad, HI_LOWER);
            let mut out = Aabb::EMPTY;
            portable::write(lo, hi, &mut out);
            prop_assert_eq!(bits(&out), want);
        }

        /// `load_parry` gives the lanes of parry's box as they are, on both implementations,
        /// and writes back the same box.
        #[test]
        fn load_parry_is_the_box(
            mins in prop::array::uniform3(coord()),
            maxs in prop::array::uniform3(coord()),
        ) {
            let parry = ParryAabb::new(mins.into(), maxs.into());
            let want = Aabb::from_arrays(mins, maxs);
            prop_assert_eq!(bits(&BoxLanes::load_parry(&parry).to_aabb()), bits(&want));
            let (lo, hi) = portable::load_parry(&parry);
            let mut out = Aabb::EMPTY;
            portable::write(lo, hi, &mut out);
            prop_assert_eq!(bits(&out), bits(&want));
        }

        /// `loosened` is parry's `loosened`, to the bit, on both implementations.
        #[test]
        fn loosened_is_parrys(
            mins in prop::array::uniform3(coord()),
            maxs in prop::array::uniform3(coord()),
            amount in 0.0f32..10.0,
        ) {
            use rapier3d::parry::bounding_volume::BoundingVolume;
            let parry = ParryAabb::new(mins.into(), maxs.into());
            let want = parry.loosened(amount);
            let want = Aabb::new(want.mins, want.maxs);
            prop_assert_eq!(bits(&BoxLanes::load_parry(&parry).loosened(amount).to_aabb()), bits(&want));
            let (lo, hi) = portable::load_parry(&parry);
            let (lo, hi) = (
                portable::loosen(lo, amount, LO_LOWER),
                portable::loosen(hi, amount, HI_LOWER),
            );
            let mut out = Aabb::EMPTY;
            portable::write(lo, hi, &mut out);
            prop_assert_eq!(bits(&out), bits(&want));
        }

        /// The portable `inside` is `Aabb::contains`, NaNs included.
        #[test]
        fn inside_is_contains(
            inner in (prop::array::uniform3(coord()), prop::array::uniform3(coord())),
            outer in (prop::array::uniform3(coord()), prop::array::uniform3(coord())),
        ) {
            let (inner, outer) = (
                Aabb::from_arrays(inner.0, inner.1),
                Aabb::from_arrays(outer.0, outer.1),
            );
            let (lo, hi) = lanes_of(&inner);
            prop_assert_eq!(portable::inside(lo, hi, &outer), outer.contains(&inner));
        }

        /// `fattened` is `loosened(margin)`, then each finite coordinate of the stretch on the
        /// lower side when negative, else the upper side, and `is_valid` is `Aabb::is_valid`:
        /// on both implementations, through `load` and `write`.
        #[test]
        fn fattened_is_loosened_then_stretched(
            tight in (prop::array::uniform3(coord()), prop::array::uniform3(coord())),
            margin in coord(),
            d in prop::array::uniform3(coord()),
        ) {
            let tight = Aabb::from_arrays(tight.0, tight.1);
            let mut want = tight.loosened(margin);
            for (i, &d) in d.iter().enumerate() {
                if d.is_finite() {
                    if d < 0.0 {
                        want.min[i] += d;
                    } else {
                        want.max[i] += d;
                    }
                }
            }
            // Lanes left unstretched get `+ 0.0`, which turns a -0.0 into 0.0: the same number.
            let same = |a: &Aabb| bits(a).map(|b| if b == (-0.0f32).to_bits() { 0 } else { b });
            let fat = BoxLanes::load(&tight).fattened(margin, d);
            prop_assert_eq!(same(&fat.to_aabb()), same(&want));
            prop_assert_eq!(fat.is_valid(), want.is_valid());
            let (lo, hi) = portable::load(&tight);
            let [x, y, z] = d;
            let (lo, hi) = (
                portable::fatten(lo, margin, [x, y, z, x], LO_LOWER),
                portable::fatten(hi, margin, [z, x, y, z], HI_LOWER),
            );
            let mut out = Aabb::EMPTY;
            portable::write(lo, hi, &mut out);
            prop_assert_eq!(same(&out), same(&want));
            prop_assert_eq!(portable::is_valid(lo, hi), want.is_valid());
        }

        /// `inside` (SSE on x86_64) is `Aabb::contains` of the stored box, NaNs included.
        #[test]
        fn inside_of_computed_boxes_is_contains(
            c in prop::array::uniform3(coord()),
            h in prop::array::uniform3(coord()),
            pad in coord(),
            outer in (prop::array::uniform3(coord()), prop::array::uniform3(coord())),
        ) {
            let outer = Aabb::from_arrays(outer.0, outer.1);
            let lanes = BoxLanes::around(c, h, pad);
            prop_assert_eq!(lanes.inside(&outer), outer.contains(&lanes.to_aabb()));
        }
    }
}
