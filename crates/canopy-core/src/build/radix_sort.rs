//! Stable LSD radix sort of `(u64 key, u32 value)` pairs, 11-bit digits, with rayon-parallel
//! histogram and scatter for large inputs. The LBVH builder sorts Morton codes with it. A stable
//! sort has one answer, so the output does not depend on the thread count.

use crate::BvhError;
use rayon::prelude::*;

const DIGIT_BITS: u32 = 11;
const BUCKETS: usize = 1 << DIGIT_BITS;
const PASSES: u32 = 64_u32.div_ceil(DIGIT_BITS);
/// Inputs at least this long sort in parallel (when asked to).
const PARALLEL_THRESHOLD: usize = 1 << 16;

#[inline(always)]
fn digit(key: u64, pass: u32) -> usize {
    ((key >> (pass * DIGIT_BITS)) as usize) & (BUCKETS - 1)
}

/// Sorts `keys` ascending, applying the same permutation to `values`; equal keys keep their
/// order. `parallel` uses the current rayon pool for large inputs.
///
/// # Errors
/// [`BvhError::KeysValuesMismatch`] when `keys` and `values` differ in length; both are then
/// left as they were.
///
/// ```
/// let mut keys = vec![5u64, 1, 5, 0];
/// let mut vals = vec![0u32, 1, 2, 3];
/// canopy_core::build::radix_sort_pairs(&mut keys, &mut vals, false)?;
/// assert_eq!(keys, [0, 1, 5, 5]);
/// assert_eq!(vals, [3, 1, 0, 2]);
/// assert!(canopy_core::build::radix_sort_pairs(&mut keys, &mut vec![0], false).is_err());
/// assert_eq!(keys, [0, 1, 5, 5]);
/// # Ok::<(), canopy_core::BvhError>(())
/// ```
pub fn radix_sort_pairs(
    keys: &mut Vec<u64>,
    values: &mut Vec<u32>,
    parallel: bool,
) -> Result<(), BvhError> {
    if keys.len() != values.len() {
        return Err(BvhError::KeysValuesMismatch {
            keys: keys.len(),
            values: values.len(),
        });
    }
    let n = keys.len();
    if n < 2 {
        return Ok(());
    }
    // Digits every key shares need no pass.
    let or = keys.iter().fold(0u64, |a, &k| a | k);
    let and = keys.iter().fold(u64::MAX, |a, &k| a & k);
    let varying = or ^ and;

    let mut tmp_keys = vec![0u64; n];
    let mut tmp_vals = vec![0u32; n];
    for pass in 0..PASSES {
        if digit(varying, pass) == 0 {
            continue;
        }
        if parallel && n >= PARALLEL_THRESHOLD {
            scatter_parallel(keys, values, &mut tmp_keys, &mut tmp_vals, pass);
        } else {
            scatter_serial(keys, values, &mut tmp_keys, &mut tmp_vals, pass);
        }
        std::mem::swap(keys, &mut tmp_keys);
        std::mem::swap(values, &mut tmp_vals);
    }
    Ok(())
}

fn scatter_serial(keys: &[u64], vals: &[u32], dk: &mut [u64], dv: &mut [u32], pass: u32) {
    let mut offsets = vec![0usize; BUCKETS];
    for &k in keys {
        offsets[digit(k, pass)] += 1;
    }
    let mut sum = 0;
    for o in offsets.iter_mut() {
        let c = *o;
        *o = sum;
        sum += c;
    }
    for (&k, &v) in keys.iter().zip(vals) {
        let d = digit(k, pass);
        let o = offsets[d];
        dk[o] = k;
        dv[o] = v;
        offsets[d] = o + 1;
    }
}

/// Destination pointers shared by the scatter tasks; each writes a disjoint set of slots.
#[derive(Clone, Copy)]
struct Dest {
    keys: *mut u64,
    vals: *mut u32,
}
// SAFETY: tasks write disjoint indices (their own bucket ranges), see `scatter_parallel`.
unsafe impl Send for Dest {}
unsafe impl Sync for Dest {}

impl Dest {
    /// Writes `(k, v)` at slot `o`.
    ///
    /// # Safety
    /// `o` is in bounds of both destinations and no other thread writes slot `o`.
    #[inline(always)]
    unsafe fn write(&self, o: usize, k: u64, v: u32) {
        *self.keys.add(o) = k;
        *self.vals.add(o) = v;
    }
}

/// Per-chunk histograms of `dig` over `keys` in chunks of `chunk_len`, turned into exclusive
/// offsets in (bucket, chunk) order: chunk c writes bucket b starting after every earlier
/// bucket and after bucket b of the chunks before c. The offsets partition `0..keys.len()`.
fn chunk_offsets(
    keys: &[u64],
    chunk_len: usize,
    buckets: usize,
    dig: impl Fn(u64) -> usize + Sync,
) -> Vec<Vec<usize>> {
    let mut hist: Vec<Vec<usize>> = keys
        .par_chunks(chunk_len)
        .map(|c| {
            let mut h = vec![0usize; buckets];
            for &k in c {
                h[dig(k)] += 1;
            }
            h
        })
        .collect();
    let mut sum = 0;
    for b in 0..buckets {
        for h in hist.iter_mut() {
            let c = h[b];
            h[b] = sum;
            sum += c;
        }
    }
    debug_assert_eq!(sum, keys.len());
    hist
}

fn scatter_parallel(keys: &[u64], vals: &[u32], dk: &mut [u64], dv: &mut [u32], pass: u32) {
    let n = keys.len();
    let chunks = (rayon::current_num_threads() * 4).clamp(1, n.div_ceil(4096));
    let chunk_len = n.div_ceil(chunks);
    let mut hist = chunk_offsets(keys, chunk_len, BUCKETS, |k| digit(k, pass));
    let dest = Dest {
        keys: dk.as_mut_ptr(),
        vals: dv.as_mut_ptr(),
    };
    keys.par_chunks(chunk_len)
        .zip(vals.par_chunks(chunk_len))
        .zip(hist.par_iter_mut())
        .for_each(|((ck, cv), offsets)| {
            for (&k, &v) in ck.iter().zip(cv) {
                let d = digit(k, pass);
                let o = offsets[d];
                // SAFETY: `o < n` and no other chunk owns slot `o` (offsets above are a
                // partition of 0..n); the destination slices outlive this scope.
                unsafe { dest.write(o, k, v) };
                offsets[d] = o + 1;
            }
        });
}

/// Most bits of one digit of [`radix_sort_keys`].
const KEY_DIGIT_MAX: u32 = 11;

/// Sorts `keys` ascending by their bits `lo_bit .. lo_bit + bits`, stably (keys equal in those
/// bits keep their order). Short inputs fall back to a comparison sort of whole keys, which
/// gives the same order when the bits below `lo_bit` already ascend in input order (the LBVH
/// packs the primitive index there).
///
/// LSD passes of at most 11 bits (all histograms from one read of the keys); digits every key
/// shares are skipped.
pub(crate) fn radix_sort_keys(keys: &mut Vec<u64>, lo_bit: u32, bits: u32, parallel: bool) {
    let n = keys.len();
    if n < 2 || bits == 0 {
        return;
    }
    if n <= SMALL_SORT {
        keys.sort_unstable();
        return;
    }
    let passes = bits.div_ceil(KEY_DIGIT_MAX);
    let width = bits.div_ceil(passes);
    let buckets = 1usize << width;
    let mask = buckets as u64 - 1;
    let dig = move |k: u64, p: u32| ((k >> (lo_bit + p * width)) & mask) as usize;
    let mut tmp: Vec<u64> = Vec::with_capacity(n);
    if parallel && n >= PARALLEL_THRESHOLD {
        let or = keys
            .par_iter()
            .fold(|| 0u64, |a, &k| a | k)
            .reduce(|| 0, |a, b| a | b);
        let and = keys
            .par_iter()
            .fold(|| u64::MAX, |a, &k| a & k)
            .reduce(|| u64::MAX, |a, b| a & b);
        let varying = or ^ and;
        tmp.resize(n, 0);
        for p in (0..passes).filter(|&p| dig(varying, p) != 0) {
            scatter_keys_parallel(keys, &mut tmp, |k| dig(k, p), buckets);
            std::mem::swap(keys, &mut tmp);
        }
        return;
    }
    // One read of the keys fills the histograms of every pass; a digit that every key shares
    // (one bucket holds them all) needs no pass.
    let mut shifts = [0u32; KEY_PASSES_MAX];
    for (p, s) in shifts.iter_mut().enumerate().take(passes as usize) {
        *s = lo_bit + p as u32 * width;
    }
    let mut hist = vec![0u32; passes as usize * buckets];
    match passes {
        1 => count_digits::<1>(keys, &mut hist, &shifts, mask),
        2 => count_digits::<2>(keys, &mut hist, &shifts, mask),
        3 => count_digits::<3>(keys, &mut hist, &shifts, mask),
        4 => count_digits::<4>(keys, &mut hist, &shifts, mask),
        5 => count_digits::<5>(keys, &mut hist, &shifts, mask),
        _ => count_digits::<KEY_PASSES_MAX>(keys, &mut hist, &shifts, mask),
    }
    let active: Vec<u32> = (0..passes)
        .filter(|&p| {
            let h = &hist[p as usize * buckets..(p as usize + 1) * buckets];
            h[dig(keys[0], p)] as usize != n
        })
        .collect();
    if active.is_empty() {
        return;
    }
    for &p in &active {
        let offsets = &mut hist[p as usize * buckets..(p as usize + 1) * buckets];
        let mut sum = 0u32;
        for o in offsets.iter_mut() {
            let c = *o;
            *o = sum;
            sum += c;
        }
        let shift = shifts[p as usize];
        let out = tmp.as_mut_ptr();
        for &k in keys.iter() {
            let d = ((k >> shift) & mask) as usize;
            // SAFETY: `d < buckets` (masked digit); the offsets partition `0..n`, so every slot
            // of `tmp` (capacity `n`) is written once and `*o < n`.
            unsafe {
                let o = offsets.get_unchecked_mut(d);
                out.add(*o as usize).write(k);
                *o += 1;
            }
        }
        // SAFETY: all `n` slots were written above.
        unsafe { tmp.set_len(n) };
        std::mem::swap(keys, &mut tmp);
    }
}

/// Most passes of [`radix_sort_keys`] (64 bits in digits of at most 11).
const KEY_PASSES_MAX: usize = 64_usize.div_ceil(KEY_DIGIT_MAX as usize);

/// Adds the digits of every key to the histograms of `P` passes (`hist`: `P` blocks of
/// `mask + 1` counts; digit `p` of `k` is `(k >> shifts[p]) & mask`).
#[inline(never)]
fn count_digits<const P: usize>(
    keys: &[u64],
    hist: &mut [u32],
    shifts: &[u32; KEY_PASSES_MAX],
    mask: u64,
) {
    let buckets = mask as usize + 1;
    assert!(P <= KEY_PASSES_MAX && hist.len() >= P * buckets);
    for &k in keys {
        for (p, &s) in shifts[..P].iter().enumerate() {
            // SAFETY: `p < P` and the digit is masked below `buckets` (asserted above).
            unsafe { *hist.get_unchecked_mut(p * buckets + ((k >> s) & mask) as usize) += 1 };
        }
    }
}

/// Inputs up to this long are sorted by comparison in [`radix_sort_keys`].
const SMALL_SORT: usize = 1024;

fn scatter_keys_parallel(
    keys: &[u64],
    dk: &mut [u64],
    dig: impl Fn(u64) -> usize + Sync,
    buckets: usize,
) {
    let n = keys.len();
    let chunks = (rayon::current_num_threads() * 4).clamp(1, n.div_ceil(4096));
    let chunk_len = n.div_ceil(chunks);
    let mut hist = chunk_offsets(keys, chunk_len, buckets, &dig);
    let dest = KeyDest(dk.as_mut_ptr());
    keys.par_chunks(chunk_len)
        .zip(hist.par_iter_mut())
        .for_each(|(ck, offsets)| {
            for &k in ck {
                let d = dig(k);
                let o = offsets[d];
                // SAFETY: `o < n` and no other chunk owns slot `o` (the offsets partition
                // 0..n); the destination outlives this scope.
                unsafe { dest.write(o, k) };
                offsets[d] = o + 1;
            }
        });
}

/// Destination of [`scatter_keys_parallel`]; each task writes a disjoint set of slots.
#[derive(Clone, Copy)]
struct KeyDest(*mut u64);
// SAFETY: tasks write disjoint indices, see `scatter_keys_parallel`.
unsafe impl Send for KeyDest {}
unsafe impl Sync for KeyDest {}

impl KeyDest {
    /// # Safety
    /// `o` is in bounds and no other thread writes slot `o`.
    #[inline(always)]
    unsafe fn write(&self, o: usize, k: u64) {
        *self.0.add(o) = k;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(keys: Vec<u64>, parallel: bool) {
        let mut k = keys.clone();
        let mut v: Vec<u32> = (0..keys.len() as u32).collect();
        radix_sort_pairs(&mut k, &mut v, parallel).expect("same lengths");
        let mut expect: Vec<(u64, u32)> = keys.iter().copied().zip(0..).collect();
        expect.sort(); // (key, original index): the stable order
        assert_eq!(k, expect.iter().map(|e| e.0).collect::<Vec<_>>());
        assert_eq!(v, expect.iter().map(|e| e.1).collect::<Vec<_>>());
    }

    #[test]
    fn key_sort_sorts_bit_ranges_stably() {
        let mut s = 99u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for &n in &[0usize, 1, 2, 17, 1000, 1025, 5000, 100_000] {
            for &(lo, bits) in &[(20u32, 44u32), (14, 30), (17, 3), (40, 24)] {
                let idx_mask = (1u64 << lo) - 1;
                let keys: Vec<u64> = (0..n as u64)
                    .map(|i| {
                        let hi = if bits == 3 { rnd() % 3 } else { rnd() };
                        ((hi & ((1u64 << bits) - 1)) << lo) | (i & idx_mask)
                    })
                    .collect();
                let field = |k: u64| k >> lo;
                let mut expect = keys.clone();
                expect.sort_by_key(|&k| field(k)); // stable
                for par in [false, true] {
                    let mut k = keys.clone();
                    radix_sort_keys(&mut k, lo, bits, par);
                    assert_eq!(k, expect, "n {n} lo {lo} bits {bits} par {par}");
                }
            }
        }
    }

    #[test]
    fn sorts_like_std_stable_sort() {
        let mut s = 7u64;
        let mut rnd = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        for &n in &[0usize, 1, 2, 17, 1000, 100_000] {
            let keys: Vec<u64> = (0..n).map(|_| rnd() >> 1).collect();
            check(keys.clone(), false);
            check(keys, true);
            let few: Vec<u64> = (0..n).map(|_| rnd() % 5).collect();
            check(few.clone(), true);
            check(few, false);
        }
    }

    /// Keys and values of different lengths are refused, serial or parallel, with both left as
    /// they were.
    #[test]
    fn mismatched_lengths_are_refused_untouched() {
        for (nk, nv) in [(2usize, 1usize), (0, 1), (1, 0), (5, 7), (1000, 999)] {
            let keys: Vec<u64> = (0..nk as u64).rev().collect();
            let values: Vec<u32> = (0..nv as u32).collect();
            for parallel in [false, true] {
                let (mut k, mut v) = (keys.clone(), values.clone());
                assert_eq!(
                    radix_sort_pairs(&mut k, &mut v, parallel),
                    Err(BvhError::KeysValuesMismatch {
                        keys: nk,
                        values: nv
                    })
                );
                assert_eq!((k, v), (keys.clone(), values.clone()));
            }
        }
    }
}
