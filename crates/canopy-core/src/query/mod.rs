//! Queries on a built [`crate::Bvh`], one family per file: `overlap.rs` (boxes and points),
//! `ray.rs` (closest and any hit), `nearest.rs` (best-first), `pairs.rs` (self and
//! tree-vs-tree pairs, serial and rayon-parallel), `pairs4.rs` (the serial self-pair walk).

pub mod nearest;
pub mod overlap;
pub mod pairs;
mod pairs4;
pub mod ray;

use smallvec::SmallVec;

/// Traversal stack: 64 entries inline (deeper than any tree the builders make for realistic
/// inputs), spilling to the heap beyond.
pub(crate) type Stack<T> = SmallVec<[T; 64]>;

/// A hint to load the cache line holding `p` into all cache levels; no effect on targets
/// without a prefetch instruction in `core::arch` on stable Rust.
#[inline(always)]
pub(crate) fn prefetch<T>(p: *const T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch is only a hint: it never faults and never changes memory, whatever
    // the address; SSE is part of the x86_64 baseline.
    unsafe {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        _mm_prefetch::<_MM_HINT_T0>(p.cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// A hint to start loading `Node4` `i` of `r4` (both of its lines).
#[inline(always)]
pub(crate) fn prefetch_node(r4: &ray::Ray4, i: u32) {
    let p = r4.nodes.as_ptr().wrapping_add(i as usize).cast::<u8>();
    prefetch(p);
    prefetch(p.wrapping_add(64));
}
