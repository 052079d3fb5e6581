//! Top-down binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding volume
//! hierarchies"), with an exact search for small nodes.
//!
//! Primitive references (box + index, 32 bytes, four-lane vectors) live in one buffer. A node
//! bins its references' centroids along the widest axis of its box (the next one when that gives
//! no split) in one pass, sweeps the bins for the cheapest split, and partitions its references
//! without branches: in place (by blocks) above [`LOCAL`] references, below that out of place
//! between the references and a scratch buffer of the subtree's size, the children then working
//! the other way round. The children's boxes come from the bins. A node of at most [`SWEEP`]
//! references orders them by centroid along the widest axis (ranks counted with vector compares,
//! without branches) and tries every split of that order instead (a sweep: cheaper than binning
//! there, and exact along that axis); one of at most
//! [`SMALL`] tries every partition into two sets (exact SAH). A node becomes a leaf
//! when no split beats `intersection_cost * n` and the leaf-size limit allows, and writes its
//! references straight into the tree's primitive arrays.
//!
//! Binning one axis over the node's box (rather than three over the centroids' box) and the
//! exact small nodes and sweeps keep the trees within about a percent of a three-axis binned
//! build, at a fraction of the cost. Areas are computed in `f32`, scaled by the root's extent so that
//! nothing overflows.
//!
//! The two halves of large nodes are built with `rayon::join` on disjoint halves of the
//! reference and output arrays (the right half with scratch of its own); the tree does not
//! depend on the thread count. Below the depth limit a node whose
//! centroids coincide, or a node too deep (pathological inputs), is split at the object median
//! instead, which keeps the depth, and so the recursion, bounded.

use super::f4::{aabb_box, box_ok_lanes, F4};
use super::{append_subtree, first_invalid, BuildOptions};
use crate::aabb::Aabb;
use crate::bvh::{Bvh, Node, PrimBounds};
use std::mem::MaybeUninit;

/// Nodes with at least this many primitives build their children in parallel.
const PARALLEL_THRESHOLD: usize = 4096;
/// Nodes of more primitives partition in place; a subtree of at most this many has scratch
/// of its own size (from a buffer of this size) and partitions out of place.
const LOCAL: usize = 1024;
const _: () = assert!(LOCAL <= PARALLEL_THRESHOLD && LOCAL >= SWEEP);
/// Past this depth, nodes split at the object median (the tree then ends within 32 levels).
const MAX_SAH_DEPTH: u32 = 64;
const MAX_BINS: usize = 32;
/// Nodes with at least this many primitives bin into two sets of bins.
const TWO_BIN_SETS: usize = 64;
/// Nodes of at most this many primitives try every partition into two sets (at most 15).
const SMALL: usize = 3;
/// Nodes of at most this many primitives (and more than [`SMALL`]) sort their centroids along
/// the widest axis and try every split of that order (a full sweep instead of bins).
const SWEEP: usize = 16;

/// A primitive reference: lanes 0..3 of `min`/`max` hold the box, `min[3]` the primitive
/// index's bits, `max[3]` zero.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct PrimRef {
    min: [f32; 4],
    max: [f32; 4],
}

const _: () = assert!(std::mem::size_of::<PrimRef>() == 32);

impl PrimRef {
    const ZERO: PrimRef = PrimRef {
        min: [0.0; 4],
        max: [0.0; 4],
    };

    #[inline(always)]
    fn lo(&self) -> F4 {
        F4::load4(&self.min).xyz0()
    }

    #[inline(always)]
    fn hi(&self) -> F4 {
        F4::load4(&self.max)
    }

    #[inline(always)]
    fn index(&self) -> u32 {
        self.min[3].to_bits()
    }
}

/// Bounds as two vectors (lane 3 zero).
#[derive(Clone, Copy)]
struct Box4 {
    lo: F4,
    hi: F4,
}

impl Box4 {
    #[inline(always)]
    fn empty() -> Box4 {
        Box4 {
            lo: F4::new(f32::INFINITY, f32::INFINITY, f32::INFINITY, 0.0),
            hi: F4::new(f32::NEG_INFINITY, f32::NEG_INFINITY, f32::NEG_INFINITY, 0.0),
        }
    }

    #[inline(always)]
    fn grow(&mut self, lo: F4, hi: F4) {
        self.lo = self.lo.min(lo);
        self.hi = self.hi.max(hi);
    }

    #[inline(always)]
    fn merge(&mut self, o: &Box4) {
        self.grow(o.lo, o.hi);
    }

    fn min3(&self) -> [f32; 3] {
        let a = self.lo.to_array();
        [a[0], a[1], a[2]]
    }

    fn max3(&self) -> [f32; 3] {
        let a = self.hi.to_array();
        [a[0], a[1], a[2]]
    }

    /// Bounds of `refs`.
    fn of_refs(refs: &[PrimRef]) -> Box4 {
        let mut b = Box4::empty();
        for r in refs {
            b.grow(r.lo(), r.hi());
        }
        b
    }
}

/// How the builder measures areas: half surface areas of extents multiplied by `scale`, one
/// over the largest extent of the root, so that every scaled extent is at most 1 and no cost
/// overflows. When the root's extent itself overflows (`huge`, boxes near `f32::MAX`), extents
/// are taken of halved coordinates.
#[derive(Clone, Copy)]
struct AreaScale {
    scale: F4,
    huge: bool,
}

impl AreaScale {
    fn for_root(b: &Box4) -> AreaScale {
        let e = b.hi.sub(b.lo).to_array();
        let m = e[0].max(e[1]).max(e[2]);
        if m.is_finite() {
            let s = if m > 0.0 { 1.0 / m } else { 1.0 };
            let s = if s.is_finite() { s } else { 1.0 };
            return AreaScale {
                scale: F4::splat(s),
                huge: false,
            };
        }
        let h = F4::splat(0.5);
        let e = b.hi.mul(h).sub(b.lo.mul(h)).to_array();
        let m = e[0].max(e[1]).max(e[2]);
        AreaScale {
            scale: F4::splat(1.0 / m),
            huge: true,
        }
    }

    /// Scaled half surface area of the box `[lo, hi]`.
    #[inline(always)]
    fn of(&self, lo: F4, hi: F4) -> f32 {
        let e = if self.huge {
            let h = F4::splat(0.5);
            hi.mul(h).sub(lo.mul(h))
        } else {
            hi.sub(lo)
        };
        e.mul(self.scale).half_area()
    }

    #[inline(always)]
    fn of_box(&self, b: &Box4) -> f32 {
        self.of(b.lo, b.hi)
    }
}

struct Ctx {
    area: AreaScale,
    bins: usize,
    max_leaf: usize,
    c_trav: f32,
    c_isect: f32,
    parallel: bool,
}

impl Ctx {
    /// `true` when a split of raw cost `cost` (sum of child half-areas times counts) should
    /// become a leaf of `n` primitives instead, in a node of half-area `area`.
    #[inline(always)]
    fn prefers_leaf(&self, n: usize, area: f32, cost: f32) -> bool {
        (n <= self.max_leaf)
            & (self.c_trav * area + self.c_isect * cost >= self.c_isect * n as f32 * area)
    }
}

/// The subtree being built: its references in `src`, scratch of the same length in `dst`
/// (empty above [`LOCAL`] references), and its slots of the output primitive arrays (starting
/// at slot `first`).
struct Task<'a> {
    src: &'a mut [PrimRef],
    dst: &'a mut [PrimRef],
    idx: &'a mut [MaybeUninit<u32>],
    bnd: &'a mut [MaybeUninit<PrimBounds>],
    first: u32,
    depth: u32,
}

impl<'a> Task<'a> {
    /// Splits into the tasks of the children `..mid` and `mid..`. With `swap`, the children's
    /// references are in `dst` (after an out-of-place partition) and `src` becomes scratch.
    #[inline(always)]
    fn split(self, mid: usize, swap: bool) -> (Task<'a>, Task<'a>) {
        let (src, dst) = if swap {
            (self.dst, self.src)
        } else {
            (self.src, self.dst)
        };
        let (sl, sr) = src.split_at_mut(mid);
        let (dl, dr) = if dst.is_empty() {
            (Default::default(), Default::default())
        } else {
            dst.split_at_mut(mid)
        };
        let (il, ir) = self.idx.split_at_mut(mid);
        let (bl, br) = self.bnd.split_at_mut(mid);
        let depth = self.depth + 1;
        (
            Task {
                src: sl,
                dst: dl,
                idx: il,
                bnd: bl,
                first: self.first,
                depth,
            },
            Task {
                src: sr,
                dst: dr,
                idx: ir,
                bnd: br,
                first: self.first + mid as u32,
                depth,
            },
        )
    }

    /// Writes this task's references as one leaf.
    fn leaf(self, b: &Box4, out: &mut Vec<Node>) {
        for ((r, i), p) in self
            .src
            .iter()
            .zip(self.idx.iter_mut())
            .zip(self.bnd.iter_mut())
        {
            i.write(r.index());
            p.write(PrimBounds {
                min: [r.min[0], r.min[1], r.min[2]],
                max: [r.max[0], r.max[1], r.max[2]],
            });
        }
        out.push(Node::leaf(
            b.min3(),
            b.max3(),
            self.first,
            self.src.len() as u32,
        ));
    }
}

/// Builds the tree of `aabbs` (not empty), or returns the index of the first invalid box.
pub(super) fn build(aabbs: &[Aabb], options: &BuildOptions) -> Result<Bvh, usize> {
    let n = aabbs.len();
    // One pass makes the references, checks the boxes ([`super::box_ok`]) and bounds them.
    let lane3 = F4::new(0.0, 0.0, 0.0, f32::from_bits(u32::MAX));
    let mut ok = F4::mask(true);
    let mut bounds = Box4::empty();
    let mut refs: Vec<PrimRef> = aabbs
        .iter()
        .enumerate()
        .map(|(i, a)| {
            let (lo, hi) = aabb_box(a);
            ok = ok.and(box_ok_lanes(lo, hi));
            let (lo, hi) = (lo.xyz0(), hi.xyz0());
            bounds.grow(lo, hi);
            let lo = F4::select(lane3, F4::splat(f32::from_bits(i as u32)), lo);
            PrimRef {
                min: lo.to_array(),
                max: hi.to_array(),
            }
        })
        .collect();
    if ok.bits() & 7 != 7 {
        return Err(first_invalid(aabbs).unwrap_or(0));
    }
    let mut scratch = vec![PrimRef::ZERO; n.min(LOCAL)];
    // Every slot of the primitive arrays is written by the leaf that holds it.
    let mut prim_indices: Vec<u32> = Vec::with_capacity(n);
    let mut prim_bounds: Vec<PrimBounds> = Vec::with_capacity(n);
    let ctx = Ctx {
        area: AreaScale::for_root(&bounds),
        bins: options.bins as usize,
        max_leaf: options.max_leaf_size as usize,
        c_trav: options.traversal_cost,
        c_isect: options.intersection_cost,
        parallel: options.parallel,
    };
    let mut nodes = Vec::with_capacity(2 * n);
    let task = Task {
        src: &mut refs,
        dst: &mut [],
        idx: &mut prim_indices.spare_capacity_mut()[..n],
        bnd: &mut prim_bounds.spare_capacity_mut()[..n],
        first: 0,
        depth: 0,
    };
    build_node(task, bounds, &mut scratch, &mut nodes, &ctx);
    // SAFETY: every reference ends in one leaf (`Task::leaf` or `pair_node`), which writes
    // its slots of both arrays; the tasks' slots partition `0..n`.
    unsafe {
        prim_indices.set_len(n);
        prim_bounds.set_len(n);
    }
    Ok(Bvh {
        nodes,
        prim_indices,
        prim_bounds,
        ..Default::default()
    })
}

/// Builds the subtree of `t` (bounds `b`) at the end of `out`. `tmp`: at least
/// `min(n, LOCAL)` references of scratch, for a task of `n <= LOCAL` references without its own.
fn build_node(t: Task<'_>, b: Box4, tmp: &mut [PrimRef], out: &mut Vec<Node>, ctx: &Ctx) {
    let n = t.src.len();
    if n <= LOCAL && t.dst.len() < n {
        let t = Task {
            src: t.src,
            dst: &mut tmp[..n],
            idx: t.idx,
            bnd: t.bnd,
            first: t.first,
            depth: t.depth,
        };
        return build_node(t, b, &mut [], out, ctx);
    }
    if n == 1 {
        return t.leaf(&b, out);
    }
    if t.depth >= MAX_SAH_DEPTH {
        if n <= ctx.max_leaf {
            return t.leaf(&b, out);
        }
        let mid = median_split(t.src, &b);
        return recurse_by_pass(t, mid, b, tmp, out, ctx);
    }
    if n <= SMALL {
        return small_node(t, b, out, ctx);
    }
    if n <= SWEEP {
        return sweep_node(t, b, out, ctx);
    }
    match find_split(t.src, &b, ctx) {
        Some(s) => {
            if ctx.prefers_leaf(n, ctx.area.of_box(&b), s.cost) {
                return t.leaf(&b, out);
            }
            let in_place = t.dst.is_empty();
            if in_place {
                partition_in_place(t.src, &s);
            } else {
                partition(t.src, t.dst, &s);
            }
            let (lt, rt) = t.split(s.left_count, !in_place);
            join(b, (lt, s.left), (rt, s.right), tmp, out, ctx);
        }
        None if n > ctx.max_leaf => {
            // Every centroid is the same point: split in the middle.
            recurse_by_pass(t, n / 2, b, tmp, out, ctx)
        }
        None => t.leaf(&b, out),
    }
}

/// Recurses into `..mid` and `mid..` of `t.src` (in place), computing the children's bounds
/// with one pass over the references.
fn recurse_by_pass(
    t: Task<'_>,
    mid: usize,
    b: Box4,
    tmp: &mut [PrimRef],
    out: &mut Vec<Node>,
    ctx: &Ctx,
) {
    let lb = Box4::of_refs(&t.src[..mid]);
    let rb = Box4::of_refs(&t.src[mid..]);
    let (lt, rt) = t.split(mid, false);
    join(b, (lt, lb), (rt, rb), tmp, out, ctx);
}

/// Writes an interior node of bounds `b` with the two given subtrees (`tmp` as for
/// [`build_node`]).
fn join(
    b: Box4,
    (lt, lb): (Task<'_>, Box4),
    (rt, rb): (Task<'_>, Box4),
    tmp: &mut [PrimRef],
    out: &mut Vec<Node>,
    ctx: &Ctx,
) {
    let me = out.len();
    out.push(Node::interior(b.min3(), b.max3(), 0));
    let n = lt.src.len() + rt.src.len();
    let right_index = if ctx.parallel && n >= PARALLEL_THRESHOLD {
        let cap = 2 * rt.src.len() / ctx.max_leaf + 1;
        let ((), right_nodes) = rayon::join(
            || build_node(lt, lb, tmp, out, ctx),
            || {
                let mut v = Vec::with_capacity(cap);
                let mut tmp = vec![PrimRef::ZERO; rt.src.len().min(LOCAL)];
                build_node(rt, rb, &mut tmp, &mut v, ctx);
                v
            },
        );
        append_subtree(out, right_nodes)
    } else {
        // Single references become leaves here, without a call.
        if lt.src.len() == 1 {
            lt.leaf(&lb, out);
        } else {
            build_node(lt, lb, tmp, out, ctx);
        }
        let r = out.len() as u32;
        if rt.src.len() == 1 {
            rt.leaf(&rb, out);
        } else {
            build_node(rt, rb, tmp, out, ctx);
        }
        r
    };
    out[me].first = right_index;
}

/// Binning of one axis: a reference goes to bin `(min + max - k0) * k1`, clamped to
/// `0..=last`. The same function classifies references in [`partition`], so the counts of the
/// bins are exactly the sizes of the children.
#[derive(Clone, Copy)]
struct Binning {
    axis: usize,
    k0: f32,
    k1: f32,
    last: f32,
}

impl Binning {
    /// Binning of `axis` over the node bounds `b` with `nb` bins; `None` when the axis has no
    /// extent to bin (or too small a one).
    #[inline(always)]
    fn new(b: &Box4, axis: usize, nb: usize) -> Option<Binning> {
        // Doubled centroids `min + max` lie in `[2 b.min, 2 b.max]`.
        let (lo, hi) = (b.lo.lane(axis) * 2.0, b.hi.lane(axis) * 2.0);
        let e = hi - lo;
        if e.is_nan() || e <= 0.0 {
            return None;
        }
        // Slightly below `nb / extent` so the largest centroid lands in the last bin.
        let k1 = (nb as f32 * (1.0 - 1e-6)) / e;
        (k1.is_finite() && k1 > 0.0).then_some(Binning {
            axis,
            k0: lo,
            k1,
            last: (nb - 1) as f32,
        })
    }

    #[inline(always)]
    fn bin(&self, r: &PrimRef) -> usize {
        let f = (r.min[self.axis] + r.max[self.axis] - self.k0) * self.k1;
        // NaN (from infinite sums near f32::MAX) goes to the last bin.
        let f = if f < self.last { f } else { self.last };
        let f = if f > 0.0 { f } else { 0.0 };
        // SAFETY: `f` is finite and in `0..=last`, and `last < MAX_BINS`.
        unsafe { f.to_int_unchecked::<u32>() as usize }
    }
}

/// The chosen split of a binned node.
struct Split {
    binning: Binning,
    /// References in bins `0..=bin` go left.
    bin: usize,
    /// Sum over the children of half-area (scaled) times primitive count.
    cost: f32,
    left_count: usize,
    left: Box4,
    right: Box4,
}

/// Bin count for a node of `n` primitives: the option, but no more bins than primitives.
#[inline(always)]
fn bin_count(n: usize, max: usize) -> usize {
    max.min(n.max(2))
}

/// Bins the centroids along the widest axis of `b` (the next widest when that gives no
/// split) and returns the cheapest split.
#[inline(never)]
fn find_split(refs: &[PrimRef], b: &Box4, ctx: &Ctx) -> Option<Split> {
    let nb = bin_count(refs.len(), ctx.bins);
    let e = b.hi.sub(b.lo).to_array();
    // Axes by decreasing extent.
    let (mut a0, mut a1, mut a2) = (0usize, 1usize, 2usize);
    if e[a1] > e[a0] {
        std::mem::swap(&mut a0, &mut a1);
    }
    if e[a2] > e[a1] {
        std::mem::swap(&mut a1, &mut a2);
        if e[a1] > e[a0] {
            std::mem::swap(&mut a0, &mut a1);
        }
    }
    let axes = [a0, a1, a2];
    axes.iter().find_map(|&a| {
        Binning::new(b, a, nb).and_then(|bn| {
            // Arrays only as large as needed (fewer bins to clear).
            if nb <= MAX_BINS / 2 {
                split_axis::<{ MAX_BINS / 2 }>(refs, bn, nb, ctx)
            } else {
                split_axis::<MAX_BINS>(refs, bn, nb, ctx)
            }
        })
    })
}

/// Bins `refs` with `bn` (`nb <= NB` bins, `NB` a power of two) and sweeps the bins for the
/// cheapest split.
#[inline(always)]
fn split_axis<const NB: usize>(
    refs: &[PrimRef],
    bn: Binning,
    nb: usize,
    ctx: &Ctx,
) -> Option<Split> {
    let mut bins = [Box4::empty(); NB];
    let mut counts = [0u32; NB];
    if refs.len() >= TWO_BIN_SETS {
        // Even and odd references in separate bins, so that consecutive references in one bin
        // do not wait for each other's update.
        let mut bins2 = [Box4::empty(); NB];
        let mut counts2 = [0u32; NB];
        let mut pairs = refs.chunks_exact(2);
        for p in &mut pairs {
            let (r0, r1) = (&p[0], &p[1]);
            let j0 = bn.bin(r0) & (NB - 1);
            let j1 = bn.bin(r1) & (NB - 1);
            bins[j0].grow(r0.lo(), r0.hi());
            counts[j0] += 1;
            bins2[j1].grow(r1.lo(), r1.hi());
            counts2[j1] += 1;
        }
        for r in pairs.remainder() {
            let j = bn.bin(r) & (NB - 1);
            bins[j].grow(r.lo(), r.hi());
            counts[j] += 1;
        }
        for i in 0..nb {
            bins[i].merge(&bins2[i]);
            counts[i] += counts2[i];
        }
    } else {
        for r in refs {
            let j = bn.bin(r) & (NB - 1);
            bins[j].grow(r.lo(), r.hi());
            counts[j] += 1;
        }
    }

    let mut right_area = [0.0f32; NB];
    let mut right_count = [0u32; NB];
    // right_*[i]: bins i..nb.
    let mut acc = Box4::empty();
    let mut cnt = 0u32;
    for i in (1..nb).rev() {
        acc.merge(&bins[i]);
        cnt += counts[i];
        right_area[i] = ctx.area.of_box(&acc);
        right_count[i] = cnt;
    }
    // The first cheapest split, chosen without branches; splits with an empty side cost
    // infinity (every real cost is finite).
    let (mut cost, mut bin, mut left_count) = (f32::INFINITY, 0usize, 0u32);
    let mut acc = Box4::empty();
    let mut cnt = 0u32;
    for i in 0..nb - 1 {
        acc.merge(&bins[i]);
        cnt += counts[i];
        let rc = right_count[i + 1];
        let c = ctx.area.of_box(&acc) * cnt as f32 + right_area[i + 1] * rc as f32;
        let c = if cnt == 0 || rc == 0 {
            f32::INFINITY
        } else {
            c
        };
        let better = c < cost;
        cost = if better { c } else { cost };
        bin = if better { i } else { bin };
        left_count = if better { cnt } else { left_count };
    }
    if cost == f32::INFINITY {
        return None;
    }
    let left_count = left_count as usize;
    let mut left = Box4::empty();
    let mut right = Box4::empty();
    for bin_box in &bins[..=bin] {
        left.merge(bin_box);
    }
    for bin_box in &bins[bin + 1..nb] {
        right.merge(bin_box);
    }
    Some(Split {
        binning: bn,
        bin,
        cost,
        left_count,
        left,
        right,
    })
}

/// Partitions `src` into `dst`: references in bins `0..=s.bin` first, order kept.
#[inline(never)]
fn partition(src: &[PrimRef], dst: &mut [PrimRef], s: &Split) {
    // `f < s.bin + 1` exactly when the clamped bin of `f` is at most `s.bin` (a NaN goes to
    // the last bin, never on the left).
    let (axis, k0, k1) = (s.binning.axis & 3, s.binning.k0, s.binning.k1);
    let limit = (s.bin + 1) as f32;
    let (mut l, mut r) = (0usize, s.left_count);
    for e in src {
        let goes_left = (e.min[axis] + e.max[axis] - k0) * k1 < limit;
        let pos = if goes_left { l } else { r };
        dst[pos] = *e;
        l += goes_left as usize;
        r += !goes_left as usize;
    }
    assert!(
        l == s.left_count && r == src.len(),
        "partition disagrees with the bins"
    );
}

/// [`partition`] in place (the order within each side is not kept, but depends only on the
/// input order). Blocks at both ends (Edelkamp and Weiss 2016, "BlockQuicksort"): the
/// references of each block on the wrong side are found without branches, then swapped
/// pairwise; what is left in the middle goes by Lomuto's scheme, also without branches.
#[inline(never)]
fn partition_in_place(refs: &mut [PrimRef], s: &Split) {
    const BLOCK: usize = 64;
    let (axis, k0, k1) = (s.binning.axis & 3, s.binning.k0, s.binning.k1);
    let limit = (s.bin + 1) as f32;
    let goes_left = |e: &PrimRef| (e.min[axis] + e.max[axis] - k0) * k1 < limit;
    // Everything before `lo` goes left, everything from `hi` on goes right.
    let (mut lo, mut hi) = (0usize, refs.len());
    let (mut off_l, mut off_r) = ([0u8; BLOCK], [0u8; BLOCK]);
    let (mut start_l, mut num_l, mut start_r, mut num_r) = (0usize, 0usize, 0usize, 0usize);
    while hi - lo >= 2 * BLOCK {
        if num_l == 0 {
            start_l = 0;
            for (i, e) in refs[lo..lo + BLOCK].iter().enumerate() {
                off_l[num_l] = i as u8;
                num_l += !goes_left(e) as usize;
            }
        }
        if num_r == 0 {
            start_r = 0;
            for (i, e) in refs[hi - BLOCK..hi].iter().rev().enumerate() {
                off_r[num_r] = i as u8;
                num_r += goes_left(e) as usize;
            }
        }
        let k = num_l.min(num_r);
        for m in 0..k {
            let a = lo + off_l[(start_l + m) % BLOCK] as usize;
            let b = hi - 1 - off_r[(start_r + m) % BLOCK] as usize;
            refs.swap(a, b);
        }
        (start_l, num_l) = (start_l + k, num_l - k);
        (start_r, num_r) = (start_r + k, num_r - k);
        if num_l == 0 {
            lo += BLOCK;
        }
        if num_r == 0 {
            hi -= BLOCK;
        }
    }
    let mid = &mut refs[lo..hi];
    let mut l = 0usize;
    for i in 0..mid.len() {
        let e = mid[i];
        let left = goes_left(&e);
        mid[i] = mid[l];
        mid[l] = e;
        l += left as usize;
    }
    assert!(lo + l == s.left_count, "partition disagrees with the bins");
}

/// A node of `2..=SMALL` references, split exactly: two references directly, more by trying
/// every partition.
fn small_node(t: Task<'_>, b: Box4, out: &mut Vec<Node>, ctx: &Ctx) {
    if t.src.len() == 2 {
        pair_node(t, b, out, ctx)
    } else {
        enumerate_node(t, b, out, ctx)
    }
}

/// Two references: a leaf, or an interior node over two single-primitive leaves.
fn pair_node(t: Task<'_>, b: Box4, out: &mut Vec<Node>, ctx: &Ctx) {
    let (r0, r1) = (t.src[0], t.src[1]);
    let cost = ctx.area.of(r0.lo(), r0.hi()) + ctx.area.of(r1.lo(), r1.hi());
    if ctx.prefers_leaf(2, ctx.area.of_box(&b), cost) {
        return t.leaf(&b, out);
    }
    let me = out.len() as u32;
    out.push(Node::interior(b.min3(), b.max3(), me + 2));
    for (k, r) in [r0, r1].iter().enumerate() {
        t.idx[k].write(r.index());
        let p = PrimBounds {
            min: [r.min[0], r.min[1], r.min[2]],
            max: [r.max[0], r.max[1], r.max[2]],
        };
        t.bnd[k].write(p);
        out.push(Node::leaf(p.min, p.max, t.first + k as u32, 1));
    }
}

/// `3..=SMALL` references: the bounds of every subset (each from a smaller one), then the
/// cheapest of all partitions into two non-empty sets.
fn enumerate_node(t: Task<'_>, b: Box4, out: &mut Vec<Node>, ctx: &Ctx) {
    let n = t.src.len();
    debug_assert!((3..=SMALL).contains(&n));
    let full = (1usize << n) - 1;
    let mut sub = [Box4::empty(); 1 << SMALL];
    let mut area = [0.0f32; 1 << SMALL];
    for m in 1..=full {
        let r = &t.src[m.trailing_zeros() as usize];
        let mut bm = sub[m & (m - 1)];
        bm.grow(r.lo(), r.hi());
        sub[m] = bm;
        area[m] = ctx.area.of_box(&bm);
    }
    // The last reference always goes right, so every partition is seen once.
    let mut best = (f32::INFINITY, 0usize);
    for m in 1..(1usize << (n - 1)) {
        let rm = full ^ m;
        let cost = area[m] * m.count_ones() as f32 + area[rm] * rm.count_ones() as f32;
        if cost < best.0 {
            best = (cost, m);
        }
    }
    let (cost, m) = best;
    if ctx.prefers_leaf(n, area[full], cost) {
        return t.leaf(&b, out);
    }
    let left = m.count_ones() as usize;
    let (mut l, mut r) = (0, left);
    for (k, e) in t.src.iter().enumerate() {
        let goes_left = m >> k & 1 == 1;
        t.dst[if goes_left { l } else { r }] = *e;
        l += goes_left as usize;
        r += !goes_left as usize;
    }
    let (lt, rt) = t.split(left, true);
    join(b, (lt, sub[m]), (rt, sub[full ^ m]), &mut [], out, ctx);
}

/// A node of `SMALL + 1..=SWEEP` references: sorts them by centroid along the widest axis of
/// `b` and takes the cheapest split of that order (exact SAH along one axis).
fn sweep_node(t: Task<'_>, b: Box4, out: &mut Vec<Node>, ctx: &Ctx) {
    let n = t.src.len();
    debug_assert!((SMALL + 1..=SWEEP).contains(&n));
    let axis = widest_axis(&b);
    // Centroid keys (halved so that nothing overflows), in a stable order: the rank of each
    // key is the number of keys before it (smaller, or equal and earlier), found without
    // branches.
    let mut key = [f32::INFINITY; SWEEP];
    for (k, r) in key.iter_mut().zip(t.src.iter()) {
        *k = r.min[axis] * 0.5 + r.max[axis] * 0.5;
    }
    let ord = stable_order(&key, n);
    let refs = &t.src[..n];
    let at = |i: usize| &refs[ord[i] as usize];
    // right_area[i]: references ord[i..n].
    let mut right_area = [0.0f32; SWEEP];
    let mut acc = Box4::empty();
    for i in (1..n).rev() {
        let r = at(i);
        acc.grow(r.lo(), r.hi());
        right_area[i] = ctx.area.of_box(&acc);
    }
    // The first cheapest split, chosen without branches.
    let mut acc = Box4::empty();
    let (mut best_cost, mut best) = (f32::INFINITY, 1usize);
    for i in 0..n - 1 {
        let r = at(i);
        acc.grow(r.lo(), r.hi());
        let cost = ctx.area.of_box(&acc) * (i + 1) as f32 + right_area[i + 1] * (n - 1 - i) as f32;
        let better = cost < best_cost;
        best_cost = if better { cost } else { best_cost };
        best = if better { i + 1 } else { best };
    }
    if ctx.prefers_leaf(n, ctx.area.of_box(&b), best_cost) {
        return t.leaf(&b, out);
    }
    // The children's boxes, bounded again while the references move to `dst` in order.
    let (mut left, mut right) = (Box4::empty(), Box4::empty());
    let (dl, dr) = t.dst.split_at_mut(best);
    for (d, &o) in dl.iter_mut().zip(&ord[..best]) {
        *d = refs[o as usize];
        left.grow(d.lo(), d.hi());
    }
    for (d, &o) in dr.iter_mut().zip(&ord[best..n]) {
        *d = refs[o as usize];
        right.grow(d.lo(), d.hi());
    }
    let (lt, rt) = t.split(best, true);
    join(b, (lt, left), (rt, right), &mut [], out, ctx);
}

/// The order of the first `n` keys of `key` (the others infinite, all finite or infinite):
/// `ord[r]` is the index of the key of rank `r`, ties in index order (a stable sort). The rank of
/// key `i` counts the keys `j < i` with `key[j] <= key[i]` and the keys `j > i` with
/// `key[j] < key[i]`, four `i` at a time (counts as `f32` lanes, exact).
#[inline(always)]
fn stable_order(key: &[f32; SWEEP], n: usize) -> [u8; SWEEP] {
    let one = F4::splat(1.0);
    let mut ord = [0u8; SWEEP];
    for c in 0..n.div_ceil(4) {
        let ki = F4::load4(&[key[4 * c], key[4 * c + 1], key[4 * c + 2], key[4 * c + 3]]);
        let mut acc = F4::splat(0.0);
        for &k in &key[..4 * c] {
            acc = acc.add(F4::splat(k).le(ki).and(one));
        }
        for (j, &k) in key[4 * c..4 * c + 4].iter().enumerate() {
            let kj = F4::splat(k);
            // Lane l > j: key j comes first, counts when <=; otherwise only when <.
            let first = F4::splat(j as f32).lt(F4::new(0.0, 1.0, 2.0, 3.0));
            acc = acc.add(F4::select(first, kj.le(ki), kj.lt(ki)).and(one));
        }
        for &k in &key[4 * c + 4..n.max(4 * c + 4)] {
            acc = acc.add(F4::splat(k).lt(ki).and(one));
        }
        // Lanes past `n` (infinite keys, counted by index) have rank `i` and write `ord[i]`,
        // past the ranks of the real keys: no test needed.
        let r = acc.to_i32();
        for (l, &rank) in r.iter().enumerate() {
            ord[rank as usize & (SWEEP - 1)] = (4 * c + l) as u8;
        }
    }
    ord
}

/// The axis of the largest extent of `b` (the first of equals).
#[inline(always)]
fn widest_axis(b: &Box4) -> usize {
    let e = b.hi.sub(b.lo).to_array();
    let mut a = 0;
    if e[1] > e[a] {
        a = 1;
    }
    if e[2] > e[a] {
        a = 2;
    }
    a
}

/// Splits at the object median along the widest axis of the bounds `b` (or at the middle
/// index when all centroids coincide); always returns `1..n`.
fn median_split(refs: &mut [PrimRef], b: &Box4) -> usize {
    let mid = refs.len() / 2;
    let e = b.hi.sub(b.lo).to_array();
    let axis = (0..3).max_by(|&x, &y| e[x].total_cmp(&e[y])).unwrap_or(0);
    let key = |r: &PrimRef| r.min[axis] * 0.5 + r.max[axis] * 0.5;
    refs.select_nth_unstable_by(mid, |p, q| {
        key(p).total_cmp(&key(q)).then(p.index().cmp(&q.index()))
    });
    mid
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The shared generator (`crate::testing::rng`), uniform in `[0, 1)`.
    fn rng(seed: u64) -> impl FnMut() -> f32 {
        let mut r = crate::testing::rng(seed);
        move || r(0.0, 1.0)
    }

    #[test]
    fn in_place_partition_matches_bins() {
        let mut r = rng(7);
        for n in [
            1usize, 2, 5, 63, 64, 127, 128, 129, 200, 255, 256, 257, 1000, 3001,
        ] {
            for coarse in [false, true] {
                let refs: Vec<PrimRef> = (0..n)
                    .map(|i| {
                        let mut c = [r() * 10.0, r() * 10.0, r() * 10.0];
                        if coarse {
                            // Many equal centroids.
                            c = c.map(|v| v.floor());
                        }
                        PrimRef {
                            min: [c[0], c[1], c[2], f32::from_bits(i as u32)],
                            max: [c[0] + 0.5, c[1] + 0.5, c[2] + 0.5, 0.0],
                        }
                    })
                    .collect();
                let b = Box4::of_refs(&refs);
                for axis in 0..3 {
                    let Some(binning) = Binning::new(&b, axis, 16) else {
                        continue;
                    };
                    for bin in [0usize, 3, 7, 14] {
                        let left_count = refs.iter().filter(|e| binning.bin(e) <= bin).count();
                        let s = Split {
                            binning,
                            bin,
                            cost: 0.0,
                            left_count,
                            left: Box4::empty(),
                            right: Box4::empty(),
                        };
                        let mut a = refs.clone();
                        partition_in_place(&mut a, &s);
                        assert!(a[..left_count].iter().all(|e| binning.bin(e) <= bin));
                        assert!(a[left_count..].iter().all(|e| binning.bin(e) > bin));
                        let mut ids: Vec<u32> = a.iter().map(PrimRef::index).collect();
                        ids.sort_unstable();
                        assert!(ids.iter().copied().eq(0..n as u32));
                        let mut o = vec![PrimRef::ZERO; n];
                        partition(&refs, &mut o, &s);
                        assert!(o[..left_count].iter().all(|e| binning.bin(e) <= bin));
                    }
                }
            }
        }
    }

    #[test]
    fn large_degenerate_inputs() {
        use crate::aabb::Aabb;
        use nalgebra::Point3;
        let mut r = rng(11);
        let n = 6000;
        let sets: Vec<Vec<Aabb>> = vec![
            // All the same box.
            vec![Aabb::new(Point3::new(1.0, 2.0, 3.0), Point3::new(2.0, 3.0, 4.0)); n],
            // Two clusters of equal boxes and a few others.
            (0..n)
                .map(|i| {
                    let c = match i % 7 {
                        0 => r() * 100.0,
                        1..=3 => 5.0,
                        _ => 50.0,
                    };
                    Aabb::new(Point3::new(c, c, 0.0), Point3::new(c + 1.0, c + 1.0, 1.0))
                })
                .collect(),
            // Points on a line.
            (0..n)
                .map(|i| {
                    let x = (i % 1500) as f32;
                    Aabb::new(Point3::new(x, 0.0, 0.0), Point3::new(x, 0.0, 0.0))
                })
                .collect(),
        ];
        for boxes in &sets {
            for max_leaf in [1u32, 4, 2000] {
                let opts = BuildOptions::default().with_max_leaf_size(max_leaf);
                let par = Bvh::build(boxes, opts).unwrap();
                let ser = Bvh::build(boxes, opts.with_parallel(false)).unwrap();
                par.validate_with_primitives(boxes).unwrap();
                assert_eq!(par.nodes(), ser.nodes());
                assert_eq!(par.primitive_indices(), ser.primitive_indices());
            }
        }
    }
}
