//! LBVH builder: a linear BVH over Morton codes (Lauterbach et al. 2009; the hierarchy is the
//! binary radix tree of Karras 2012, built top-down).
//!
//! 1. Morton codes of the centroids in the centroid bounds, `b` bits per axis with `b` chosen
//!    from `n` (`morton_bits`): enough to separate the primitives, few enough that the code and
//!    the primitive index pack into one `u64` key (`code << index_bits | index`). Keys are then
//!    unique and their order is the stable order of the codes.
//! 2. Radix sort of the keys on the code bits only (at most four 11-bit passes; constant digits
//!    skipped; comparison sort for short inputs).
//! 3. Layout: a top-down pass writes the depth-first node array. A range of sorted keys splits
//!    where its highest differing bit turns on (a binary search): the radix tree of Karras 2012
//!    (the index bits break ties between equal codes), without the nodes inside leaves: ranges
//!    of at most `max_leaf_size` primitives become leaves. Boxes come bottom-up on the way back;
//!    the halves of large ranges run in parallel with `rayon::join`.

use super::f4::{aabb_box, box_ok_lanes, prim_box, F4};
use super::{append_subtree, radix_sort::radix_sort_keys, Bounds, BuildOptions};
use crate::aabb::Aabb;
use crate::bvh::{Bvh, Node, PrimBounds};
use rayon::prelude::*;
use std::mem::MaybeUninit;

/// Ranges with at least this many primitives are laid out in parallel.
const PARALLEL_THRESHOLD: usize = 4096;
/// Below this many primitives, the data-parallel steps run serially.
const PARALLEL_MIN: usize = 1 << 14;

/// Bits per axis of the Morton codes for `n` primitives whose index takes `index_bits`: far
/// beyond one primitive per cell for uniform input (`n^(1/3)` cells per axis) to leave room
/// for clustered input, at least 11 (33 bits: three radix passes up to 2M primitives), capped
/// at 21 and by what fits next to the index (which wins over the 11: 10 bits for indices of
/// 32 bits, more than 2^31 primitives). Short inputs, sorted by comparison, take all the bits
/// that fit.
fn morton_bits(n: usize, index_bits: u32) -> u32 {
    let fit = ((64 - index_bits) / 3).min(21);
    if n <= 1024 {
        fit
    } else {
        (index_bits / 3 + 5).max(11).min(fit)
    }
}

/// Builds the tree, or returns the index of the first invalid box.
pub(super) fn build(aabbs: &[Aabb], options: &BuildOptions) -> Result<Bvh, usize> {
    let n = aabbs.len();
    let parallel = options.parallel && n >= PARALLEL_MIN;

    // 1. Keys: Morton code of the centroid, then the primitive index. The pass over the boxes
    // that finds the centroid bounds also checks them.
    const CHUNK: usize = 4096;
    let (cb, valid) = if parallel {
        aabbs.par_chunks(CHUNK).map(centroid_bounds).reduce(
            || (Bounds::EMPTY, true),
            |a, b| (a.0.merged(&b.0), a.1 & b.1),
        )
    } else {
        aabbs
            .chunks(CHUNK)
            .map(centroid_bounds)
            .fold((Bounds::EMPTY, true), |a, b| (a.0.merged(&b.0), a.1 & b.1))
    };
    if !valid {
        return Err(super::first_invalid(aabbs).expect("an invalid box"));
    }
    let index_bits = (usize::BITS - (n - 1).leading_zeros()).max(1);
    let bits = morton_bits(n, index_bits);
    let scale = ((1u32 << bits) - 1) as f32;
    let mut mul = [0.0f32; 3];
    for (i, v) in mul.iter_mut().enumerate() {
        let e = cb.max[i] - cb.min[i];
        if e > 0.0 && (scale / e).is_finite() {
            *v = scale / e;
        }
    }
    let km = KeyMap {
        origin: F4::new(cb.min[0], cb.min[1], cb.min[2], 0.0),
        mul: F4::new(mul[0], mul[1], mul[2], 0.0),
        scale: F4::splat(scale),
        index_bits,
    };
    let mut keys = if bits > SPREAD_BITS {
        km.keys::<true>(aabbs, parallel)
    } else {
        km.keys::<false>(aabbs, parallel)
    };

    // 2. Sort on the code bits, then gather indices and boxes in leaf order.
    radix_sort_keys(&mut keys, index_bits, 3 * bits, parallel);
    let index_mask = (1u64 << index_bits) - 1;
    let mut prim_indices: Vec<u32> = Vec::with_capacity(n);
    let mut prim_bounds: Vec<PrimBounds> = Vec::with_capacity(n);
    if parallel {
        keys.par_iter()
            .map(|&k| {
                let i = (k & index_mask) as u32;
                (i, PrimBounds::from_aabb(&aabbs[i as usize]))
            })
            .unzip_into_vecs(&mut prim_indices, &mut prim_bounds);
    } else {
        gather(
            &keys,
            index_mask,
            aabbs,
            &mut prim_indices.spare_capacity_mut()[..n],
            &mut prim_bounds.spare_capacity_mut()[..n],
        );
        // SAFETY: `gather` wrote all `n` slots of both.
        unsafe {
            prim_indices.set_len(n);
            prim_bounds.set_len(n);
        }
    }

    // 3. Depth-first layout with bottom-up boxes. At most `2n - 1` nodes (ranges split in two
    // nonempty halves); leaves of `max_leaf_size` (4) average above 2.8 primitives on most
    // inputs, which the estimate covers; growing past it is rare. The unused end is given back
    // only when it is more than an eighth of the array: shrinking copies the array (nodes are
    // over-aligned, so no in-place `realloc`).
    let cap = (3 * n / options.max_leaf_size as usize + 1).min(2 * n - 1);
    let mut nodes = Vec::with_capacity(cap);
    let ctx = Layout {
        keys: &keys,
        prims: &prim_bounds,
        max_leaf: options.max_leaf_size as usize,
        parallel,
    };
    ctx.emit(0, n, &mut nodes);
    if nodes.capacity() - nodes.len() > nodes.len() / 8 {
        nodes.shrink_to_fit();
    }
    Ok(Bvh {
        nodes,
        prim_indices,
        prim_bounds,
        ..Default::default()
    })
}

/// Writes the primitive index and box of every sorted key. The box reads are random: each is
/// prefetched a few keys ahead so that the misses overlap.
fn gather(
    keys: &[u64],
    index_mask: u64,
    aabbs: &[Aabb],
    indices: &mut [MaybeUninit<u32>],
    bounds: &mut [MaybeUninit<PrimBounds>],
) {
    assert!(indices.len() == keys.len() && bounds.len() == keys.len());
    const AHEAD: usize = 16;
    for (j, ((&k, i_out), b_out)) in keys.iter().zip(indices).zip(bounds).enumerate() {
        if let Some(&ka) = keys.get(j + AHEAD) {
            prefetch(&aabbs[(ka & index_mask) as usize]);
        }
        let i = (k & index_mask) as usize;
        i_out.write(i as u32);
        b_out.write(PrimBounds::from_aabb(&aabbs[i]));
    }
}

/// Hints the processor to load `r`'s cache line.
#[inline(always)]
fn prefetch<T>(r: &T) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: a prefetch never faults and `r` is a valid reference anyway.
    unsafe {
        std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
            (r as *const T).cast::<i8>(),
        );
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = r;
}

/// Centroid bounds of `aabbs`, and whether every box is valid ([`super::box_ok`]).
fn centroid_bounds(aabbs: &[Aabb]) -> (Bounds, bool) {
    let half = F4::splat(0.5);
    let (mut lo_acc, mut hi_acc) = (F4::splat(f32::INFINITY), F4::splat(f32::NEG_INFINITY));
    let mut ok = F4::mask(true);
    for a in aabbs {
        let (lo, hi) = aabb_box(a);
        ok = ok.and(box_ok_lanes(lo, hi));
        // Centroids `min / 2 + max / 2` (no overflow near `f32::MAX`); `c.min(acc)` keeps
        // `acc` on ties, as `Bounds::grow` does.
        let c = lo.mul(half).add(hi.mul(half));
        lo_acc = c.min(lo_acc);
        hi_acc = c.max(hi_acc);
    }
    let (l, h) = (lo_acc.to_array(), hi_acc.to_array());
    let b = Bounds {
        min: [l[0], l[1], l[2]],
        max: [h[0], h[1], h[2]],
    };
    (b, ok.bits() & 7 == 7)
}

/// How a box becomes its sort key: the centroid, quantized in the centroid bounds (`origin`,
/// `mul` cells per unit, at most `scale`), Morton-encoded, shifted above the index bits.
struct KeyMap {
    origin: F4,
    mul: F4,
    scale: F4,
    index_bits: u32,
}

impl KeyMap {
    /// The key of box `a` of index `i`. `WIDE`: codes of more than [`SPREAD_BITS`] bits per
    /// axis.
    #[inline(always)]
    fn key<const WIDE: bool>(&self, i: usize, a: &Aabb) -> u64 {
        let half = F4::splat(0.5);
        let (lo, hi) = aabb_box(a);
        // Finite input: the clamps need no NaN care, and the cast is in range.
        let q = lo
            .mul(half)
            .add(hi.mul(half))
            .sub(self.origin)
            .mul(self.mul)
            .max(F4::splat(0.0))
            .min(self.scale)
            .to_i32();
        let code = morton_encode_lut::<WIDE>(q[0] as u32, q[1] as u32, q[2] as u32);
        (code << self.index_bits) | i as u64
    }

    /// The keys of all boxes, in input order.
    fn keys<const WIDE: bool>(&self, aabbs: &[Aabb], parallel: bool) -> Vec<u64> {
        if parallel {
            aabbs
                .par_iter()
                .enumerate()
                .map(|(i, a)| self.key::<WIDE>(i, a))
                .collect()
        } else {
            aabbs
                .iter()
                .enumerate()
                .map(|(i, a)| self.key::<WIDE>(i, a))
                .collect()
        }
    }
}

/// Bits per axis that one lookup in [`SPREAD`] spreads.
const SPREAD_BITS: u32 = 11;

/// Bit `i` of the index moved to bit `3 * i`, for 11-bit indices.
static SPREAD: [u32; 1 << SPREAD_BITS] = {
    let mut t = [0u32; 1 << SPREAD_BITS];
    let mut v = 0;
    while v < t.len() {
        let mut i = 0;
        while i < SPREAD_BITS {
            t[v] |= (((v >> i) & 1) as u32) << (3 * i);
            i += 1;
        }
        v += 1;
    }
    t
};

/// [`crate::morton::morton_encode`] by table, for coordinates below `2^21`; below
/// `2^SPREAD_BITS` unless `WIDE`.
#[inline(always)]
fn morton_encode_lut<const WIDE: bool>(x: u32, y: u32, z: u32) -> u64 {
    let part = |s: u32| -> u64 {
        let t = |v: u32| SPREAD[((v >> s) as usize) & ((1 << SPREAD_BITS) - 1)] as u64;
        t(x) | (t(y) << 1) | (t(z) << 2)
    };
    if WIDE {
        part(0) | (part(SPREAD_BITS) << (3 * SPREAD_BITS))
    } else {
        part(0)
    }
}

struct Layout<'a> {
    /// Sorted unique keys.
    keys: &'a [u64],
    prims: &'a [PrimBounds],
    max_leaf: usize,
    parallel: bool,
}

impl Layout<'_> {
    /// First slot of the right half of `lo..hi` (at least two keys): the first key with the
    /// highest bit in which the range's keys differ.
    #[inline]
    fn split(&self, lo: usize, hi: usize) -> usize {
        let (a, b) = (self.keys[lo], self.keys[hi - 1]);
        let mask = 1u64 << (63 - (a ^ b).leading_zeros());
        let inner = &self.keys[lo + 1..hi - 1];
        // The keys with the bit clear come first: short ranges count them (no dependent
        // loads), long ones search.
        lo + 1
            + if inner.len() <= 64 {
                inner
                    .iter()
                    .map(|&k| ((k & mask) == 0) as usize)
                    .sum::<usize>()
            } else {
                inner.partition_point(|&k| k & mask == 0)
            }
    }

    /// Writes the subtree over sorted primitives `lo..hi` at the end of `out`, and returns its
    /// box (lane 3 junk).
    fn emit(&self, lo: usize, hi: usize, out: &mut Vec<Node>) -> (F4, F4) {
        let count = hi - lo;
        if count <= self.max_leaf {
            // `l.min(acc)` keeps `acc` on ties, as `Bounds::grow` does.
            let (mut bl, mut bh) = prim_box(&self.prims[lo]);
            for p in &self.prims[lo + 1..hi] {
                let (l, h) = prim_box(p);
                bl = l.min(bl);
                bh = h.max(bh);
            }
            out.push(Node::leaf(xyz(bl), xyz(bh), lo as u32, count as u32));
            return (bl, bh);
        }
        let me = out.len();
        out.push(Node::leaf([0.0; 3], [0.0; 3], lo as u32, 1)); // placeholder
        let s = self.split(lo, hi);
        let ((ll, lh), (rl, rh), right) = if self.parallel && count >= PARALLEL_THRESHOLD {
            let (lb, (rb, v)) = rayon::join(
                || self.emit(lo, s, out),
                || {
                    let mut v = Vec::with_capacity(2 * (hi - s) - 1);
                    let rb = self.emit(s, hi, &mut v);
                    (rb, v)
                },
            );
            (lb, rb, append_subtree(out, v))
        } else {
            let lb = self.emit(lo, s, out);
            let right = out.len() as u32;
            let rb = self.emit(s, hi, out);
            (lb, rb, right)
        };
        let (bl, bh) = (rl.min(ll), rh.max(lh));
        out[me] = Node::interior(xyz(bl), xyz(bh), right);
        (bl, bh)
    }
}

/// Lanes 0..3 of `v`.
#[inline(always)]
fn xyz(v: F4) -> [f32; 3] {
    let a = v.to_array();
    [a[0], a[1], a[2]]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// For every index width up to the largest input (`u32::MAX - 1` primitives), the code
    /// and the index fit in the 64-bit key, with at least 10 bits per axis; for more than 2^31
    /// primitives this used to panic (`clamp` with its minimum above its maximum).
    #[test]
    fn morton_bits_fit_next_to_every_index_width() {
        for index_bits in 1..=32u32 {
            let smallest = if index_bits == 1 {
                1
            } else {
                (1usize << (index_bits - 1)) + 1
            };
            let largest = (1usize << index_bits).min(u32::MAX as usize - 1);
            for n in [smallest, largest] {
                let bits = morton_bits(n, index_bits);
                assert!(3 * bits + index_bits <= 64, "n {n}: {bits} bits per axis");
                assert!((10..=21).contains(&bits), "n {n}: {bits} bits per axis");
                if n > 1024 && index_bits <= 31 {
                    assert!(bits >= 11, "n {n}: {bits} bits per axis");
                }
            }
        }
    }

    #[test]
    fn table_encoding_matches_morton_encode() {
        let mut s = 1u32;
        for _ in 0..10_000 {
            s = s.wrapping_mul(1664525).wrapping_add(1013904223);
            let (x, y, z) = (s >> 11, (s >> 3) & 0x1f_ffff, s.rotate_left(7) & 0x1f_ffff);
            assert_eq!(
                morton_encode_lut::<true>(x, y, z),
                crate::morton::morton_encode(x, y, z)
            );
            let (x, y, z) = (x & 0x7ff, y & 0x7ff, z & 0x7ff);
            assert_eq!(
                morton_encode_lut::<false>(x, y, z),
                crate::morton::morton_encode(x, y, z)
            );
        }
    }
}
