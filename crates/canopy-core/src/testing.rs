//! Test helpers shared by the unit tests of several modules (compiled for tests only).

/// A small deterministic generator (SplitMix64), uniform in `[lo, hi)`.
pub(crate) fn rng(seed: u64) -> impl FnMut(f32, f32) -> f32 {
    let mut s = seed;
    move |lo, hi| {
        s = s.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        lo + (hi - lo) * ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}
