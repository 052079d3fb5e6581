//! LBVH builder (Karras 2012, "Maximizing parallelism in the construction of BVHs, octrees and
//! k-d trees").
//!
//! 1. Morton codes (63-bit) of the centroids in the centroid bounds, in parallel.
//! 2. Stable radix sort of `(code, index)`; equal codes keep index order, and Karras' common-
//!    prefix function falls back to the index so identical codes still split evenly.
//! 3. The hierarchy: every internal node `i` finds its key range and split independently
//!    (data-parallel, one rayon task per node chunk, exactly as on a GPU).
//! 4. Layout: a top-down pass from the root writes the depth-first node array, collapsing
//!    ranges of at most `max_leaf_size` primitives into leaves, and computes every box bottom-up
//!    on the way back (the halves of large ranges in parallel with `rayon::join`). On a CPU this
//!    replaces Apetrei's atomic-counter bottom-up pass at lower cost with the same result.

use super::{append_subtree, centroid, radix_sort_pairs, Bounds, BuildOptions};
use crate::aabb::Aabb;
use crate::bvh::{Bvh, Node, PrimBounds};
use crate::morton::morton_code;
use rayon::prelude::*;

/// Ranges with at least this many primitives are laid out in parallel.
const PARALLEL_THRESHOLD: usize = 4096;
/// Below this many primitives, the data-parallel steps run serially.
const PARALLEL_MIN: usize = 1 << 14;

/// An internal node of the Karras hierarchy: it covers sorted primitives `lo..=hi` and splits
/// after `split` (left child covers `lo..=split`, right child `split+1..=hi`).
#[derive(Clone, Copy, Debug)]
struct KNode {
    lo: u32,
    hi: u32,
    split: u32,
}

pub(super) fn build(aabbs: &[Aabb], options: &BuildOptions) -> Bvh {
    let n = aabbs.len();
    let parallel = options.parallel && n >= PARALLEL_MIN;

    // 1. Morton codes of centroids.
    let cb = if parallel {
        aabbs
            .par_iter()
            .fold(
                || Bounds::EMPTY,
                |mut b, a| {
                    b.grow_point(&centroid(&a.min_array(), &a.max_array()));
                    b
                },
            )
            .reduce(|| Bounds::EMPTY, |a, b| a.merged(&b))
    } else {
        let mut b = Bounds::EMPTY;
        for a in aabbs {
            b.grow_point(&centroid(&a.min_array(), &a.max_array()));
        }
        b
    };
    let mut inv = [0.0f32; 3];
    for (i, v) in inv.iter_mut().enumerate() {
        let e = cb.max[i] - cb.min[i];
        if e > 0.0 && (1.0 / e).is_finite() {
            *v = 1.0 / e;
        }
    }
    let code = |a: &Aabb| morton_code(centroid(&a.min_array(), &a.max_array()), cb.min, inv);
    let mut keys: Vec<u64> = if parallel {
        aabbs.par_iter().map(code).collect()
    } else {
        aabbs.iter().map(code).collect()
    };
    let mut prim_indices: Vec<u32> = (0..n as u32).collect();

    // 2. Sort.
    radix_sort_pairs(&mut keys, &mut prim_indices, parallel);
    let gather = |&i: &u32| PrimBounds::from_aabb(&aabbs[i as usize]);
    let prim_bounds: Vec<PrimBounds> = if parallel {
        prim_indices.par_iter().map(gather).collect()
    } else {
        prim_indices.iter().map(gather).collect()
    };

    // 3. Hierarchy.
    let mut nodes = Vec::with_capacity(2 * n / options.max_leaf_size as usize + 1);
    let ctx = Layout {
        knodes: if n < 2 {
            Vec::new()
        } else if parallel {
            (0..n as u32 - 1)
                .into_par_iter()
                .map(|i| karras_node(&keys, i))
                .collect()
        } else {
            (0..n as u32 - 1).map(|i| karras_node(&keys, i)).collect()
        },
        prims: &prim_bounds,
        max_leaf: options.max_leaf_size as usize,
        parallel,
    };

    // 4. Depth-first layout with bottom-up boxes.
    ctx.emit(0, 0, n as u32 - 1, &mut nodes);
    Bvh {
        nodes,
        prim_indices,
        prim_bounds,
        slot_of: Vec::new(),
    }
}

/// Length of the common prefix of keys `i` and `j` (Karras' δ), with the index as tie-break;
/// -1 when `j` is outside the array.
#[inline(always)]
fn delta(keys: &[u64], i: u32, j: i64) -> i32 {
    if j < 0 || j >= keys.len() as i64 {
        return -1;
    }
    let (a, b) = (keys[i as usize], keys[j as usize]);
    if a == b {
        64 + (i ^ j as u32).leading_zeros() as i32
    } else {
        (a ^ b).leading_zeros() as i32
    }
}

/// Range and split of internal node `i` (Karras 2012, Figure 4).
fn karras_node(keys: &[u64], i: u32) -> KNode {
    let ii = i as i64;
    let d: i64 = if delta(keys, i, ii + 1) > delta(keys, i, ii - 1) {
        1
    } else {
        -1
    };
    let delta_min = delta(keys, i, ii - d);
    let mut l_max: i64 = 2;
    while delta(keys, i, ii + l_max * d) > delta_min {
        l_max *= 2;
    }
    let mut l: i64 = 0;
    let mut t = l_max / 2;
    while t >= 1 {
        if delta(keys, i, ii + (l + t) * d) > delta_min {
            l += t;
        }
        t /= 2;
    }
    let j = ii + l * d;
    let delta_node = delta(keys, i, j);
    let mut s: i64 = 0;
    let mut step = l;
    loop {
        step = (step + 1) / 2;
        if delta(keys, i, ii + (s + step) * d) > delta_node {
            s += step;
        }
        if step <= 1 {
            break;
        }
    }
    let split = ii + s * d + d.min(0);
    KNode {
        lo: ii.min(j) as u32,
        hi: ii.max(j) as u32,
        split: split as u32,
    }
}

struct Layout<'a> {
    knodes: Vec<KNode>,
    prims: &'a [PrimBounds],
    max_leaf: usize,
    parallel: bool,
}

impl Layout<'_> {
    /// Writes the subtree of Karras node `k` (covering `lo..=hi`) at the end of `out`, and
    /// returns its box.
    fn emit(&self, k: u32, lo: u32, hi: u32, out: &mut Vec<Node>) -> Bounds {
        let count = (hi - lo + 1) as usize;
        if count <= self.max_leaf {
            let b = Bounds::of_prims(&self.prims[lo as usize..=hi as usize]);
            out.push(Node::leaf(b.min, b.max, lo, count as u32));
            return b;
        }
        let kn = self.knodes[k as usize];
        debug_assert!(kn.lo == lo && kn.hi == hi);
        let me = out.len();
        out.push(Node::leaf([0.0; 3], [0.0; 3], lo, 1)); // placeholder
        let s = kn.split;
        // Karras: the left child is internal node `s` (or leaf `s`), the right child internal
        // node `s + 1` (or leaf `s + 1`); leaves are handled by the size check above.
        let (lb, rb, right) = if self.parallel && count >= PARALLEL_THRESHOLD {
            let (lb, (rb, v)) = rayon::join(
                || self.emit(s, lo, s, out),
                || {
                    let mut v = Vec::with_capacity(2 * (hi - s) as usize / self.max_leaf + 1);
                    let rb = self.emit(s + 1, s + 1, hi, &mut v);
                    (rb, v)
                },
            );
            (lb, rb, append_subtree(out, v))
        } else {
            let lb = self.emit(s, lo, s, out);
            let right = out.len() as u32;
            let rb = self.emit(s + 1, s + 1, hi, out);
            (lb, rb, right)
        };
        let b = lb.merged(&rb);
        out[me] = Node::interior(b.min, b.max, right);
        b
    }
}
