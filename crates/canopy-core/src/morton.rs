//! 63-bit Morton codes (21 bits per axis): interleaved coordinates that sort points along a
//! Z-order curve. The LBVH builder (`build/lbvh.rs`) uses an equivalent table-driven encoder.

/// Spreads the low 21 bits of `v` so that bit `i` lands on bit `3 * i`.
#[inline]
pub fn spread_bits_21(v: u32) -> u64 {
    let mut x = (v as u64) & 0x1f_ffff;
    x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
    x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
    x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
    x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
    x = (x | (x << 2)) & 0x1249_2492_4924_9249;
    x
}

/// Interleaves three 21-bit integers into a 63-bit Morton code (`x` in the lowest bit).
#[inline]
pub fn morton_encode(x: u32, y: u32, z: u32) -> u64 {
    spread_bits_21(x) | (spread_bits_21(y) << 1) | (spread_bits_21(z) << 2)
}

/// Morton code of `p` quantised in the box `[min, min + extent]` (21 bits per axis).
///
/// `inv_extent` is `1 / extent` per axis, or 0 for an axis of zero extent. Points outside the
/// box are clamped to it.
#[inline]
pub fn morton_code(p: [f32; 3], min: [f32; 3], inv_extent: [f32; 3]) -> u64 {
    const SCALE: f32 = ((1u32 << 21) - 1) as f32;
    let q = |i: usize| -> u32 {
        let t = ((p[i] - min[i]) * inv_extent[i]).clamp(0.0, 1.0);
        (t * SCALE) as u32
    };
    morton_encode(q(0), q(1), q(2))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive(x: u32, y: u32, z: u32) -> u64 {
        let mut code = 0u64;
        for i in 0..21 {
            code |= (((x >> i) & 1) as u64) << (3 * i);
            code |= (((y >> i) & 1) as u64) << (3 * i + 1);
            code |= (((z >> i) & 1) as u64) << (3 * i + 2);
        }
        code
    }

    #[test]
    fn matches_naive_interleave() {
        let mut s = 12345u32;
        for _ in 0..10_000 {
            s = s.wrapping_mul(1664525).wrapping_add(1013904223);
            let (x, y, z) = (
                s & 0x1f_ffff,
                (s >> 5) & 0x1f_ffff,
                s.rotate_left(11) & 0x1f_ffff,
            );
            assert_eq!(morton_encode(x, y, z), naive(x, y, z));
        }
        let m = 0x1f_ffff;
        assert_eq!(morton_encode(m, m, m), (1u64 << 63) - 1);
    }
}
