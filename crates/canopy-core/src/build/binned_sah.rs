//! Top-down binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding volume
//! hierarchies").
//!
//! Primitive references (box + index, 32 bytes) are partitioned in place, so every pass reads
//! memory sequentially. Each node bins centroids on all three axes in one pass, sweeps the bins
//! for the cheapest split, and becomes a leaf when no split beats `intersection_cost * n` and the
//! leaf-size limit allows. The two halves of large nodes are built with `rayon::join`; the tree
//! does not depend on the thread count. Below the depth limit a node whose centroids coincide,
//! or a node too deep (pathological inputs), is split at the object median instead, which keeps
//! the depth, and so the recursion, bounded.

use super::{append_subtree, Bounds, BuildOptions};
use crate::aabb::{surface_area, Aabb};
use crate::bvh::{Bvh, Node, PrimBounds};

/// Nodes with at least this many primitives build their children in parallel.
const PARALLEL_THRESHOLD: usize = 4096;
/// Past this depth, nodes split at the object median (the tree then ends within 32 levels).
const MAX_SAH_DEPTH: u32 = 64;
const MAX_BINS: usize = 32;

#[derive(Clone, Copy)]
#[repr(C)]
struct PrimRef {
    min: [f32; 3],
    index: u32,
    max: [f32; 3],
    _pad: u32,
}

const _: () = assert!(std::mem::size_of::<PrimRef>() == 32);

impl PrimRef {
    #[inline(always)]
    fn centroid(&self, axis: usize) -> f32 {
        self.min[axis] * 0.5 + self.max[axis] * 0.5
    }
}

#[derive(Clone, Copy)]
struct Bin {
    bounds: Bounds,
    count: u32,
}

struct Ctx {
    bins: usize,
    max_leaf: usize,
    c_trav: f64,
    c_isect: f64,
    parallel: bool,
}

#[derive(Clone, Copy)]
struct Split {
    axis: usize,
    /// Primitives in bins `0..=bin` go left.
    bin: usize,
    cost: f64,
}

pub(super) fn build(aabbs: &[Aabb], options: &BuildOptions) -> Bvh {
    let mut refs: Vec<PrimRef> = aabbs
        .iter()
        .enumerate()
        .map(|(i, a)| PrimRef {
            min: a.min_array(),
            index: i as u32,
            max: a.max_array(),
            _pad: 0,
        })
        .collect();
    let mut bounds = Bounds::EMPTY;
    let mut cbounds = Bounds::EMPTY;
    for r in &refs {
        bounds.grow(&r.min, &r.max);
        cbounds.grow_point(&[r.centroid(0), r.centroid(1), r.centroid(2)]);
    }
    let ctx = Ctx {
        bins: options.bins as usize,
        max_leaf: options.max_leaf_size as usize,
        c_trav: options.traversal_cost as f64,
        c_isect: options.intersection_cost as f64,
        parallel: options.parallel,
    };
    let mut nodes = Vec::with_capacity(2 * refs.len() / options.max_leaf_size.max(1) as usize + 1);
    build_node(&mut refs, bounds, cbounds, 0, 0, &mut nodes, &ctx);
    let prim_indices = refs.iter().map(|r| r.index).collect();
    let prim_bounds = refs
        .iter()
        .map(|r| PrimBounds {
            min: r.min,
            max: r.max,
        })
        .collect();
    Bvh {
        nodes,
        prim_indices,
        prim_bounds,
        slot_of: Vec::new(),
    }
}

fn build_node(
    refs: &mut [PrimRef],
    bounds: Bounds,
    cbounds: Bounds,
    first: u32,
    depth: u32,
    out: &mut Vec<Node>,
    ctx: &Ctx,
) {
    let n = refs.len();
    let me = out.len();
    out.push(Node::leaf(bounds.min, bounds.max, first, n as u32));
    if n == 1 {
        return;
    }

    let split = if depth < MAX_SAH_DEPTH {
        find_split(refs, &bounds, &cbounds, ctx)
    } else {
        None
    };
    let leaf_cost = ctx.c_isect * n as f64;
    let mid = match split {
        Some(s) if s.cost < leaf_cost || n > ctx.max_leaf => partition(refs, &cbounds, s, ctx),
        None if n > ctx.max_leaf => median_split(refs, &cbounds),
        _ => return, // a leaf: already written
    };

    let (left, right) = refs.split_at_mut(mid);
    let (lb, lcb) = bounds_of(left);
    let (rb, rcb) = bounds_of(right);
    let right_index = if ctx.parallel && n >= PARALLEL_THRESHOLD {
        let rfirst = first + mid as u32;
        let ((), right_nodes) = rayon::join(
            || build_node(left, lb, lcb, first, depth + 1, out, ctx),
            || {
                let mut v = Vec::with_capacity(2 * right.len() / ctx.max_leaf + 1);
                build_node(right, rb, rcb, rfirst, depth + 1, &mut v, ctx);
                v
            },
        );
        append_subtree(out, right_nodes)
    } else {
        build_node(left, lb, lcb, first, depth + 1, out, ctx);
        let r = out.len() as u32;
        build_node(right, rb, rcb, first + mid as u32, depth + 1, out, ctx);
        r
    };
    out[me] = Node::interior(bounds.min, bounds.max, right_index);
}

fn bounds_of(refs: &[PrimRef]) -> (Bounds, Bounds) {
    let mut b = Bounds::EMPTY;
    let mut cb = Bounds::EMPTY;
    for r in refs {
        b.grow(&r.min, &r.max);
        cb.grow_point(&[r.centroid(0), r.centroid(1), r.centroid(2)]);
    }
    (b, cb)
}

#[inline(always)]
fn bin_of(c: f32, cmin: f32, scale: f32, bins: usize) -> usize {
    // `as usize` saturates (NaN -> 0), so tiny extents cannot index out of range.
    (((c - cmin) * scale) as usize).min(bins - 1)
}

fn scales(cbounds: &Bounds, bins: usize) -> [f32; 3] {
    let mut s = [0.0f32; 3];
    for (a, s) in s.iter_mut().enumerate() {
        let extent = cbounds.max[a] - cbounds.min[a];
        if extent > 0.0 {
            // Slightly below `bins / extent` so the largest centroid lands in the last bin.
            *s = (bins as f32 * (1.0 - 1e-6)) / extent;
        }
    }
    s
}

/// Bins the centroids on every axis with a non-zero extent and returns the cheapest split.
#[inline(never)]
fn find_split(refs: &[PrimRef], bounds: &Bounds, cbounds: &Bounds, ctx: &Ctx) -> Option<Split> {
    let nb = ctx.bins;
    let scale = scales(cbounds, nb);
    let empty = Bin {
        bounds: Bounds::EMPTY,
        count: 0,
    };
    let mut bins = [[empty; MAX_BINS]; 3];
    for r in refs {
        for a in 0..3 {
            let b = bin_of(r.centroid(a), cbounds.min[a], scale[a], nb);
            let bin = &mut bins[a][b];
            bin.bounds.grow(&r.min, &r.max);
            bin.count += 1;
        }
    }

    let inv_area = 1.0 / surface_area(bounds.min, bounds.max).max(f64::MIN_POSITIVE);
    let mut best: Option<Split> = None;
    let mut right_area = [0.0f64; MAX_BINS];
    let mut right_count = [0u32; MAX_BINS];
    for (a, bins) in bins.iter().enumerate() {
        if scale[a] == 0.0 {
            continue;
        }
        // right_*[i]: bins i..nb.
        let mut acc = Bounds::EMPTY;
        let mut cnt = 0u32;
        for i in (1..nb).rev() {
            acc = acc.merged(&bins[i].bounds);
            cnt += bins[i].count;
            right_area[i] = surface_area(acc.min, acc.max);
            right_count[i] = cnt;
        }
        let mut acc = Bounds::EMPTY;
        let mut cnt = 0u32;
        for i in 0..nb - 1 {
            acc = acc.merged(&bins[i].bounds);
            cnt += bins[i].count;
            let rc = right_count[i + 1];
            if cnt == 0 || rc == 0 {
                continue;
            }
            let cost = ctx.c_trav
                + ctx.c_isect
                    * (surface_area(acc.min, acc.max) * cnt as f64 + right_area[i + 1] * rc as f64)
                    * inv_area;
            if best.is_none_or(|b| cost < b.cost) {
                best = Some(Split {
                    axis: a,
                    bin: i,
                    cost,
                });
            }
        }
    }
    best
}

/// Partitions `refs` so that primitives in bins `0..=split.bin` come first; returns their count.
fn partition(refs: &mut [PrimRef], cbounds: &Bounds, split: Split, ctx: &Ctx) -> usize {
    let a = split.axis;
    let scale = scales(cbounds, ctx.bins)[a];
    let cmin = cbounds.min[a];
    let goes_left = |r: &PrimRef| bin_of(r.centroid(a), cmin, scale, ctx.bins) <= split.bin;
    let (mut i, mut j) = (0usize, refs.len());
    loop {
        while i < j && goes_left(&refs[i]) {
            i += 1;
        }
        while i < j && !goes_left(&refs[j - 1]) {
            j -= 1;
        }
        if i >= j {
            break;
        }
        refs.swap(i, j - 1);
        i += 1;
        j -= 1;
    }
    i
}

/// Splits at the object median along the widest centroid axis (or at the middle index when all
/// centroids coincide); always returns `1..n`.
fn median_split(refs: &mut [PrimRef], cbounds: &Bounds) -> usize {
    let mid = refs.len() / 2;
    let ext = |a: usize| cbounds.max[a] - cbounds.min[a];
    let axis = (0..3)
        .max_by(|&x, &y| ext(x).total_cmp(&ext(y)))
        .unwrap_or(0);
    if ext(axis) > 0.0 {
        refs.select_nth_unstable_by(mid, |p, q| {
            p.centroid(axis)
                .total_cmp(&q.centroid(axis))
                .then(p.index.cmp(&q.index))
        });
    }
    mid
}
