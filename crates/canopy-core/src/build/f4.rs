//! A four-lane `f32` vector for the builders' and queries' inner loops: SSE2 on x86_64 (always
//! available there), plain arrays elsewhere. Boxes use lanes 0..3; lane 3 is padding that the
//! callers keep finite (usually 0) so that arithmetic on it never meets denormals or NaNs.
//!
//! `min`/`max` follow the SSE rule (`a < b ? a : b`): only used on finite data.

#![allow(dead_code)]

#[cfg(target_arch = "x86_64")]
mod imp {
    use std::arch::x86_64::*;

    #[derive(Clone, Copy, Debug)]
    #[repr(transparent)]
    pub(crate) struct F4(pub(crate) __m128);

    impl F4 {
        #[inline(always)]
        pub(crate) fn splat(v: f32) -> F4 {
            // SAFETY: SSE2 is part of the x86_64 baseline.
            unsafe { F4(_mm_set1_ps(v)) }
        }
        #[inline(always)]
        pub(crate) fn new(a: f32, b: f32, c: f32, d: f32) -> F4 {
            unsafe { F4(_mm_set_ps(d, c, b, a)) }
        }
        /// Loads four lanes from 16 bytes at `p` (any alignment).
        #[inline(always)]
        pub(crate) fn load4(p: &[f32; 4]) -> F4 {
            unsafe { F4(_mm_loadu_ps(p.as_ptr())) }
        }
        #[inline(always)]
        pub(crate) fn to_array(self) -> [f32; 4] {
            let mut a = [0.0f32; 4];
            unsafe { _mm_storeu_ps(a.as_mut_ptr(), self.0) };
            a
        }
        #[inline(always)]
        pub(crate) fn add(self, o: F4) -> F4 {
            unsafe { F4(_mm_add_ps(self.0, o.0)) }
        }
        #[inline(always)]
        pub(crate) fn sub(self, o: F4) -> F4 {
            unsafe { F4(_mm_sub_ps(self.0, o.0)) }
        }
        #[inline(always)]
        pub(crate) fn mul(self, o: F4) -> F4 {
            unsafe { F4(_mm_mul_ps(self.0, o.0)) }
        }
        #[inline(always)]
        pub(crate) fn min(self, o: F4) -> F4 {
            unsafe { F4(_mm_min_ps(self.0, o.0)) }
        }
        #[inline(always)]
        pub(crate) fn max(self, o: F4) -> F4 {
            unsafe { F4(_mm_max_ps(self.0, o.0)) }
        }
        /// Lane 3 set to 0.
        #[inline(always)]
        pub(crate) fn xyz0(self) -> F4 {
            unsafe {
                let m = _mm_castsi128_ps(_mm_set_epi32(0, -1, -1, -1));
                F4(_mm_and_ps(self.0, m))
            }
        }
        /// `self` where `mask` is set, else `other` (`mask` from a comparison).
        #[inline(always)]
        pub(crate) fn select(mask: F4, a: F4, b: F4) -> F4 {
            unsafe {
                F4(_mm_or_ps(
                    _mm_and_ps(mask.0, a.0),
                    _mm_andnot_ps(mask.0, b.0),
                ))
            }
        }
        /// All lanes set when `m`, else all clear.
        #[inline(always)]
        pub(crate) fn mask(m: bool) -> F4 {
            unsafe { F4(_mm_castsi128_ps(_mm_set1_epi32(-(m as i32)))) }
        }
        /// `x*y + y*z + z*x` of lanes 0..3 (half the surface area of a box of these extents).
        #[inline(always)]
        pub(crate) fn half_area(self) -> f32 {
            unsafe {
                let yzx = _mm_shuffle_ps::<0b11_00_10_01>(self.0, self.0);
                let p = _mm_mul_ps(self.0, yzx);
                let p1 = _mm_shuffle_ps::<0b11_11_11_01>(p, p);
                let p2 = _mm_movehl_ps(p, p);
                _mm_cvtss_f32(_mm_add_ss(_mm_add_ss(p, p1), p2))
            }
        }
        /// Truncates lanes to `i32` (lanes must be in range; callers clamp first).
        #[inline(always)]
        pub(crate) fn to_i32(self) -> [i32; 4] {
            let mut a = [0i32; 4];
            unsafe {
                _mm_storeu_si128(a.as_mut_ptr() as *mut __m128i, _mm_cvttps_epi32(self.0));
            }
            a
        }
        #[inline(always)]
        pub(crate) fn lane(self, i: usize) -> f32 {
            self.to_array()[i]
        }
        /// Bit `i` set when lane `i` of `self` is `<=` lane `i` of `o`.
        #[inline(always)]
        pub(crate) fn le_bits(self, o: F4) -> u32 {
            unsafe { _mm_movemask_ps(_mm_cmple_ps(self.0, o.0)) as u32 }
        }
        /// Lanes all set where `self <= o`, else clear.
        #[inline(always)]
        pub(crate) fn le(self, o: F4) -> F4 {
            unsafe { F4(_mm_cmple_ps(self.0, o.0)) }
        }
        /// Lanes all set where `self < o`, else clear.
        #[inline(always)]
        pub(crate) fn lt(self, o: F4) -> F4 {
            unsafe { F4(_mm_cmplt_ps(self.0, o.0)) }
        }
        /// Bitwise and.
        #[inline(always)]
        pub(crate) fn and(self, o: F4) -> F4 {
            unsafe { F4(_mm_and_ps(self.0, o.0)) }
        }
        /// Absolute values (sign bits cleared).
        #[inline(always)]
        pub(crate) fn abs(self) -> F4 {
            unsafe { F4(_mm_andnot_ps(_mm_set1_ps(-0.0), self.0)) }
        }
        /// Lanes 1, 2, 3 moved down to lanes 0, 1, 2 (lane 3 keeps lane 3).
        #[inline(always)]
        pub(crate) fn shift_down(self) -> F4 {
            unsafe { F4(_mm_shuffle_ps::<0b11_11_10_01>(self.0, self.0)) }
        }
        /// Lane `i` holds lane `(i + K) % 4` (`K` in `1..=3`).
        #[inline(always)]
        pub(crate) fn rot<const K: i32>(self) -> F4 {
            unsafe {
                match K {
                    1 => F4(_mm_shuffle_ps::<0b00_11_10_01>(self.0, self.0)),
                    2 => F4(_mm_shuffle_ps::<0b01_00_11_10>(self.0, self.0)),
                    _ => F4(_mm_shuffle_ps::<0b10_01_00_11>(self.0, self.0)),
                }
            }
        }
        /// Bit `i` set when the sign bit of lane `i` is (a mask from [`F4::le`]: lane set).
        #[inline(always)]
        pub(crate) fn bits(self) -> u32 {
            unsafe { _mm_movemask_ps(self.0) as u32 }
        }
    }

    /// Bit `i` set when `words[i] == v`: one SSE2 compare for four words.
    #[inline(always)]
    pub(crate) fn eq_bits(words: &[u32; 4], v: u32) -> u32 {
        // SAFETY: SSE2 is part of the x86_64 baseline; the load reads the 16 bytes of `words`.
        unsafe {
            let w = _mm_loadu_si128(words.as_ptr() as *const __m128i);
            let eq = _mm_cmpeq_epi32(w, _mm_set1_epi32(v as i32));
            _mm_movemask_ps(_mm_castsi128_ps(eq)) as u32
        }
    }
}

#[cfg(not(target_arch = "x86_64"))]
mod imp {
    #[derive(Clone, Copy, Debug)]
    #[repr(C, align(16))]
    pub(crate) struct F4(pub(crate) [f32; 4]);

    #[inline(always)]
    fn zip(a: F4, b: F4, f: impl Fn(f32, f32) -> f32) -> F4 {
        F4([
            f(a.0[0], b.0[0]),
            f(a.0[1], b.0[1]),
            f(a.0[2], b.0[2]),
            f(a.0[3], b.0[3]),
        ])
    }

    impl F4 {
        #[inline(always)]
        pub(crate) fn splat(v: f32) -> F4 {
            F4([v; 4])
        }
        #[inline(always)]
        pub(crate) fn new(a: f32, b: f32, c: f32, d: f32) -> F4 {
            F4([a, b, c, d])
        }
        #[inline(always)]
        pub(crate) fn load4(p: &[f32; 4]) -> F4 {
            F4(*p)
        }
        #[inline(always)]
        pub(crate) fn to_array(self) -> [f32; 4] {
            self.0
        }
        #[inline(always)]
        pub(crate) fn add(self, o: F4) -> F4 {
            zip(self, o, |a, b| a + b)
        }
        #[inline(always)]
        pub(crate) fn sub(self, o: F4) -> F4 {
            zip(self, o, |a, b| a - b)
        }
        #[inline(always)]
        pub(crate) fn mul(self, o: F4) -> F4 {
            zip(self, o, |a, b| a * b)
        }
        #[inline(always)]
        pub(crate) fn min(self, o: F4) -> F4 {
            zip(self, o, |a, b| if a < b { a } else { b })
        }
        #[inline(always)]
        pub(crate) fn max(self, o: F4) -> F4 {
            zip(self, o, |a, b| if a > b { a } else { b })
        }
        #[inline(always)]
        pub(crate) fn xyz0(self) -> F4 {
            F4([self.0[0], self.0[1], self.0[2], 0.0])
        }
        #[inline(always)]
        pub(crate) fn select(mask: F4, a: F4, b: F4) -> F4 {
            let m = |i: usize| {
                f32::from_bits(
                    (mask.0[i].to_bits() & a.0[i].to_bits())
                        | (!mask.0[i].to_bits() & b.0[i].to_bits()),
                )
            };
            F4([m(0), m(1), m(2), m(3)])
        }
        #[inline(always)]
        pub(crate) fn mask(m: bool) -> F4 {
            F4([f32::from_bits(if m { u32::MAX } else { 0 }); 4])
        }
        #[inline(always)]
        pub(crate) fn half_area(self) -> f32 {
            let e = self.0;
            e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
        }
        #[inline(always)]
        pub(crate) fn to_i32(self) -> [i32; 4] {
            self.0.map(|v| v as i32)
        }
        #[inline(always)]
        pub(crate) fn lane(self, i: usize) -> f32 {
            self.0[i]
        }
        #[inline(always)]
        pub(crate) fn le_bits(self, o: F4) -> u32 {
            (0..4).fold(0, |m, i| m | (((self.0[i] <= o.0[i]) as u32) << i))
        }
        #[inline(always)]
        pub(crate) fn le(self, o: F4) -> F4 {
            zip(self, o, |a, b| {
                f32::from_bits(if a <= b { u32::MAX } else { 0 })
            })
        }
        #[inline(always)]
        pub(crate) fn lt(self, o: F4) -> F4 {
            zip(self, o, |a, b| {
                f32::from_bits(if a < b { u32::MAX } else { 0 })
            })
        }
        #[inline(always)]
        pub(crate) fn and(self, o: F4) -> F4 {
            zip(self, o, |a, b| f32::from_bits(a.to_bits() & b.to_bits()))
        }
        #[inline(always)]
        pub(crate) fn abs(self) -> F4 {
            F4(self.0.map(f32::abs))
        }
        #[inline(always)]
        pub(crate) fn shift_down(self) -> F4 {
            F4([self.0[1], self.0[2], self.0[3], self.0[3]])
        }
        #[inline(always)]
        pub(crate) fn rot<const K: i32>(self) -> F4 {
            let k = K as usize;
            F4([0, 1, 2, 3].map(|i| self.0[(i + k) % 4]))
        }
        #[inline(always)]
        pub(crate) fn bits(self) -> u32 {
            (0..4).fold(0, |m, i| m | ((self.0[i].to_bits() >> 31) << i))
        }
    }

    /// Bit `i` set when `words[i] == v`.
    #[inline(always)]
    pub(crate) fn eq_bits(words: &[u32; 4], v: u32) -> u32 {
        (0..4).fold(0, |m, i| m | (((words[i] == v) as u32) << i))
    }
}

pub(crate) use imp::{eq_bits, F4};

use crate::aabb::Aabb;
use crate::bvh::{Node, PrimBounds};

const _: () = assert!(std::mem::size_of::<Aabb>() == 24);
const _: () = assert!(std::mem::offset_of!(Aabb, max) == 12);
const _: () = assert!(std::mem::size_of::<PrimBounds>() == 24);

/// A box stored as six `f32` (`min` then `max`) as two vectors; lane 3 is junk (ignore it).
#[inline(always)]
fn six_box(v: &[f32; 6]) -> (F4, F4) {
    // SAFETY: bytes 0..16 are `min` and `max[0]`, bytes 8..24 are `min[2]` and `max`: both
    // within the 24 bytes of `v`.
    unsafe {
        let p = v.as_ptr();
        let lo = F4::load4(&*(p as *const [f32; 4]));
        let hi = F4::load4(&*(p.add(2) as *const [f32; 4])).shift_down();
        (lo, hi)
    }
}

/// An input box as two vectors; lane 3 is junk (ignore it).
#[inline(always)]
pub(crate) fn aabb_box(a: &Aabb) -> (F4, F4) {
    // SAFETY: `Aabb` is `repr(C)`, two `Point3<f32>` (three `f32` each, `repr(C)` in
    // nalgebra): 24 bytes, `min` first (asserted above), alignment 4.
    six_box(unsafe { &*(a as *const Aabb as *const [f32; 6]) })
}

/// Lanes 0..3 all set when the box `[lo, hi]` is valid ([`super::box_ok`]: finite, `lo <= hi`);
/// fold many boxes with `and` and test `bits() & 7 == 7`.
#[inline(always)]
pub(crate) fn box_ok_lanes(lo: F4, hi: F4) -> F4 {
    let big = F4::splat(f32::MAX);
    lo.le(hi).and(lo.abs().le(big)).and(hi.abs().le(big))
}

/// A node's box as two vectors; lane 3 holds the bits of `first` / `count` (ignore it).
#[inline(always)]
pub(crate) fn node_box(n: &Node) -> (F4, F4) {
    // SAFETY: `Node` is `repr(C)`, 32 bytes: `min` and `first` in the first 16 bytes, `max` and
    // `count` in the last 16; every bit pattern is a valid `f32`.
    unsafe {
        let p = n as *const Node as *const [f32; 4];
        (F4::load4(&*p), F4::load4(&*p.add(1)))
    }
}

/// A primitive's box as two vectors; lane 3 is junk (ignore it).
#[inline(always)]
pub(crate) fn prim_box(b: &PrimBounds) -> (F4, F4) {
    // SAFETY: `PrimBounds` is `repr(C)`, six `f32`, `min` first.
    six_box(unsafe { &*(b as *const PrimBounds as *const [f32; 6]) })
}

/// `true` when the closed boxes `[alo, ahi]` and `[blo, bhi]` overlap (lanes 0..3).
#[inline(always)]
pub(crate) fn overlap(alo: F4, ahi: F4, blo: F4, bhi: F4) -> bool {
    alo.le_bits(bhi) & blo.le_bits(ahi) & 7 == 7
}

#[cfg(test)]
mod tests {
    use super::F4;

    #[test]
    fn lanes() {
        let a = F4::new(1.0, 2.0, 3.0, 4.0);
        let b = F4::new(4.0, 1.0, 5.0, -1.0);
        assert_eq!(a.min(b).to_array(), [1.0, 1.0, 3.0, -1.0]);
        assert_eq!(a.max(b).to_array(), [4.0, 2.0, 5.0, 4.0]);
        assert_eq!(a.add(b).sub(b).to_array(), a.to_array());
        assert_eq!(a.xyz0().to_array(), [1.0, 2.0, 3.0, 0.0]);
        assert_eq!(a.half_area(), 1.0 * 2.0 + 2.0 * 3.0 + 3.0 * 1.0);
        assert_eq!(F4::select(F4::mask(true), a, b).to_array(), a.to_array());
        assert_eq!(F4::select(F4::mask(false), a, b).to_array(), b.to_array());
        assert_eq!(F4::new(0.5, 1.9, 7.0, 0.0).to_i32(), [0, 1, 7, 0]);
        assert_eq!(a.le_bits(b), 0b0101);
        let bits = |v: F4| v.to_array().map(|x| x.to_bits() != 0);
        assert_eq!(bits(a.le(b)), [true, false, true, false]);
        assert_eq!(bits(a.lt(a)), [false; 4]);
        assert_eq!(bits(a.le(a)), [true; 4]);
        assert_eq!(
            a.and(F4::select(F4::mask(true), a, b)).to_array(),
            a.to_array()
        );
        assert_eq!(a.shift_down().to_array(), [2.0, 3.0, 4.0, 4.0]);
        assert_eq!(a.le(b).bits(), 0b0101);
        assert_eq!(a.rot::<1>().to_array(), [2.0, 3.0, 4.0, 1.0]);
        assert_eq!(a.rot::<2>().to_array(), [3.0, 4.0, 1.0, 2.0]);
        assert_eq!(a.rot::<3>().to_array(), [4.0, 1.0, 2.0, 3.0]);
        assert_eq!(super::eq_bits(&[7, u32::MAX, 7, 1], 7), 0b0101);
        assert_eq!(super::eq_bits(&[7, u32::MAX, 7, 1], u32::MAX), 0b0010);
        assert_eq!(super::eq_bits(&[7, u32::MAX, 7, 1], 2), 0);
        assert_eq!(a.le(b).and(b.le(a)).bits(), 0);
        assert_eq!(a.le(a).and(b.le(b)).bits(), 0b1111);
    }

    #[test]
    fn boxes() {
        use super::{node_box, overlap, prim_box};
        use crate::bvh::{Node, PrimBounds};

        let n = Node::leaf([1.0, 2.0, 3.0], [4.0, 5.0, 6.0], 7, 1);
        let (lo, hi) = node_box(&n);
        assert_eq!(&lo.to_array()[..3], &[1.0, 2.0, 3.0]);
        assert_eq!(&hi.to_array()[..3], &[4.0, 5.0, 6.0]);
        let p = PrimBounds {
            min: [1.0, 2.0, 3.0],
            max: [4.0, 5.0, 6.0],
        };
        let (plo, phi) = prim_box(&p);
        assert_eq!(&plo.to_array()[..3], &[1.0, 2.0, 3.0]);
        assert_eq!(&phi.to_array()[..3], &[4.0, 5.0, 6.0]);
        assert!(overlap(lo, hi, plo, phi));
        let far = F4::new(4.5, 0.0, 0.0, 0.0);
        assert!(!overlap(lo, hi, far, far));
        let touch = F4::new(4.0, 5.0, 6.0, -1.0);
        assert!(overlap(lo, hi, touch, touch));
        let a = crate::aabb::Aabb::from_arrays([1.0, 2.0, 3.0], [4.0, 5.0, 6.0]);
        let (alo, ahi) = super::aabb_box(&a);
        assert_eq!(&alo.to_array()[..3], &[1.0, 2.0, 3.0]);
        assert_eq!(&ahi.to_array()[..3], &[4.0, 5.0, 6.0]);
        assert_eq!(
            F4::new(-1.0, 2.0, -0.0, -3.5).abs().to_array(),
            [1.0, 2.0, 0.0, 3.5]
        );
    }
}
