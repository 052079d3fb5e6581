//! Top-down binned SAH builder (Wald 2007, "On fast construction of SAH-based bounding volume
//! hierarchies"), with an exact sweep for small nodes.
//!
//! Primitive references (box + index, 32 bytes, four-lane vectors) live in two buffers: a node
//! bins its references' centroids on all three axes in one pass, sweeps the bins for the
//! cheapest split, and then partitions its references out of place into the other buffer,
//! branch-free, computing its children's centroid bounds on the way (their boxes come from the
//! bins). The children then work the other way round. A node of at most [`SMALL`] references
//! sorts them on each axis instead and tries every split (exact SAH). A node becomes a leaf
//! when no split beats `intersection_cost * n` and the leaf-size limit allows, and writes its
//! references straight into the tree's primitive arrays.
//!
//! The two halves of large nodes are built with `rayon::join` on disjoint halves of every
//! buffer; the tree does not depend on the thread count. Below the depth limit a node whose
//! centroids coincide, or a node too deep (pathological inputs), is split at the object median
//! instead, which keeps the depth, and so the recursion, bounded.

use super::f4::F4;
use super::{append_subtree, BuildOptions};
use crate::aabb::Aabb;
use crate::bvh::{Bvh, Node, PrimBounds};

/// Nodes with at least this many primitives build their children in parallel.
const PARALLEL_THRESHOLD: usize = 4096;
/// Past this depth, nodes split at the object median (the tree then ends within 32 levels).
const MAX_SAH_DEPTH: u32 = 64;
const MAX_BINS: usize = 32;
/// Nodes of at most this many primitives try every split along every axis.
const SMALL: usize = 16;

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

    /// Bounds (and centroid bounds, centroids doubled: `min + max`) of `refs`.
    fn of_refs(refs: &[PrimRef]) -> (Box4, Box4) {
        let mut b = Box4::empty();
        let mut cb = Box4::empty();
        for r in refs {
            let (lo, hi) = (r.lo(), r.hi());
            b.grow(lo, hi);
            let c = lo.add(hi);
            cb.grow(c, c);
        }
        (b, cb)
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
    small: usize,
    binfn: usize,
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
        n <= self.max_leaf
            && self.c_trav * area + self.c_isect * cost >= self.c_isect * n as f32 * area
    }
}

/// The subtree being built: its references in `src`, scratch of the same length in `dst`, and
/// its slots of the output primitive arrays (starting at slot `first`).
struct Task<'a> {
    src: &'a mut [PrimRef],
    dst: &'a mut [PrimRef],
    idx: &'a mut [u32],
    bnd: &'a mut [PrimBounds],
    first: u32,
    depth: u32,
}

impl<'a> Task<'a> {
    /// Splits into the tasks of the children `..mid` and `mid..`. With `swap`, the children's
    /// references are in `dst` (after an out-of-place partition) and `src` becomes scratch.
    fn split(self, mid: usize, swap: bool) -> (Task<'a>, Task<'a>) {
        let (src, dst) = if swap {
            (self.dst, self.src)
        } else {
            (self.src, self.dst)
        };
        let (sl, sr) = src.split_at_mut(mid);
        let (dl, dr) = dst.split_at_mut(mid);
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
            *i = r.index();
            *p = PrimBounds {
                min: [r.min[0], r.min[1], r.min[2]],
                max: [r.max[0], r.max[1], r.max[2]],
            };
        }
        out.push(Node::leaf(
            b.min3(),
            b.max3(),
            self.first,
            self.src.len() as u32,
        ));
    }
}

pub(super) fn build(aabbs: &[Aabb], options: &BuildOptions) -> Bvh {
    let n = aabbs.len();
    let mut refs: Vec<PrimRef> = aabbs
        .iter()
        .enumerate()
        .map(|(i, a)| PrimRef {
            min: [a.min.x, a.min.y, a.min.z, f32::from_bits(i as u32)],
            max: [a.max.x, a.max.y, a.max.z, 0.0],
        })
        .collect();
    let mut scratch = vec![PrimRef::ZERO; n];
    let mut prim_indices = vec![0u32; n];
    let mut prim_bounds = vec![
        PrimBounds {
            min: [0.0; 3],
            max: [0.0; 3],
        };
        n
    ];
    let (bounds, cbounds) = Box4::of_refs(&refs);
    let ctx = Ctx {
        area: AreaScale::for_root(&bounds),
        small: std::env::var("SMALL").ok().and_then(|v| v.parse().ok()).unwrap_or(8),
        binfn: std::env::var("BINFN").ok().and_then(|v| v.parse().ok()).unwrap_or(0),
        bins: options.bins as usize,
        max_leaf: options.max_leaf_size as usize,
        c_trav: options.traversal_cost,
        c_isect: options.intersection_cost,
        parallel: options.parallel,
    };
    let mut nodes = Vec::with_capacity(2 * n / options.max_leaf_size.max(1) as usize + 1);
    let task = Task {
        src: &mut refs,
        dst: &mut scratch,
        idx: &mut prim_indices,
        bnd: &mut prim_bounds,
        first: 0,
        depth: 0,
    };
    build_node(task, bounds, cbounds, &mut nodes, &ctx);
    Bvh {
        nodes,
        prim_indices,
        prim_bounds,
        slot_of: Vec::new(),
    }
}

/// Builds the subtree of `t` (bounds `b`, doubled-centroid bounds `cb`) at the end of `out`.
fn build_node(t: Task<'_>, b: Box4, cb: Box4, out: &mut Vec<Node>, ctx: &Ctx) {
    let n = t.src.len();
    if n == 1 {
        return t.leaf(&b, out);
    }
    if t.depth >= MAX_SAH_DEPTH {
        if n <= ctx.max_leaf {
            return t.leaf(&b, out);
        }
        let mid = median_split(t.src, &cb);
        return recurse_by_pass(t, mid, b, out, ctx);
    }
    if n <= ctx.small {
        return small_node(t, b, out, ctx);
    }
    match find_split(t.src, &cb, ctx) {
        Some(s) => {
            if ctx.prefers_leaf(n, ctx.area.of_box(&b), s.cost) {
                return t.leaf(&b, out);
            }
            let (lcb, rcb) = partition(t.src, t.dst, &cb, &s);
            let (lt, rt) = t.split(s.left_count, true);
            join(b, (lt, s.left, lcb), (rt, s.right, rcb), out, ctx);
        }
        None if n > ctx.max_leaf => {
            // Every centroid is the same point: split in the middle.
            recurse_by_pass(t, n / 2, b, out, ctx)
        }
        None => t.leaf(&b, out),
    }
}

/// Recurses into `..mid` and `mid..` of `t.src` (in place), computing the children's bounds
/// with one pass over the references.
fn recurse_by_pass(t: Task<'_>, mid: usize, b: Box4, out: &mut Vec<Node>, ctx: &Ctx) {
    let (lb, lcb) = Box4::of_refs(&t.src[..mid]);
    let (rb, rcb) = Box4::of_refs(&t.src[mid..]);
    let (lt, rt) = t.split(mid, false);
    join(b, (lt, lb, lcb), (rt, rb, rcb), out, ctx);
}

/// Writes an interior node of bounds `b` with the two given subtrees.
fn join(
    b: Box4,
    (lt, lb, lcb): (Task<'_>, Box4, Box4),
    (rt, rb, rcb): (Task<'_>, Box4, Box4),
    out: &mut Vec<Node>,
    ctx: &Ctx,
) {
    let me = out.len();
    out.push(Node::interior(b.min3(), b.max3(), 0));
    let n = lt.src.len() + rt.src.len();
    let right_index = if ctx.parallel && n >= PARALLEL_THRESHOLD {
        let cap = 2 * rt.src.len() / ctx.max_leaf + 1;
        let ((), right_nodes) = rayon::join(
            || build_node(lt, lb, lcb, out, ctx),
            || {
                let mut v = Vec::with_capacity(cap);
                build_node(rt, rb, rcb, &mut v, ctx);
                v
            },
        );
        append_subtree(out, right_nodes)
    } else {
        build_node(lt, lb, lcb, out, ctx);
        let r = out.len() as u32;
        build_node(rt, rb, rcb, out, ctx);
        r
    };
    out[me].first = right_index;
}

/// The chosen split of a binned node.
struct Split {
    axis: usize,
    /// References in bins `0..=bin` go left.
    bin: usize,
    bins: usize,
    /// Sum over the children of half-area (scaled) times primitive count.
    cost: f32,
    left_count: usize,
    left: Box4,
    right: Box4,
}

/// Bin positions of the doubled centroid `c`: `(c - k0) * k1` clamped to the last bin.
#[inline(always)]
fn bin_coords(c: F4, k0: F4, k1: F4, last: F4) -> [i32; 4] {
    // `c >= k0` (k0 is the smallest doubled centroid), so only the top needs clamping.
    c.sub(k0).mul(k1).min(last).to_i32()
}

/// Bin count for a node of `n` primitives.
#[inline(always)]
fn bin_count(n: usize, max: usize, f: usize) -> usize {
    match f {
        0 => max.min(n.max(4)),
        1 => max.min((n / 2).max(4)),
        2 => max.min((n / 4).max(4)),
        3 => max.min(4 + 2 * (n as f32).sqrt() as usize),
        _ => f.min(32),
    }
}

/// Bins the centroids on every axis of non-zero extent and returns the cheapest split.
#[inline(never)]
fn find_split(refs: &[PrimRef], cb: &Box4, ctx: &Ctx) -> Option<Split> {
    let n = refs.len();
    let nb = bin_count(n, ctx.bins, ctx.binfn);
    let (k0, k1) = bin_params(cb, nb);
    let k1a = k1.to_array();
    if k1a[0] == 0.0 && k1a[1] == 0.0 && k1a[2] == 0.0 {
        return None;
    }
    let last = F4::splat((nb - 1) as f32);

    let empty = Box4::empty();
    let mut bins = [[empty; MAX_BINS]; 3];
    let mut counts = [[0u32; MAX_BINS]; 3];
    for r in refs {
        let (lo, hi) = (r.lo(), r.hi());
        let j = bin_coords(lo.add(hi), k0, k1, last);
        for a in 0..3 {
            let j = j[a] as usize & (MAX_BINS - 1);
            bins[a][j].grow(lo, hi);
            counts[a][j] += 1;
        }
    }

    let mut best: Option<(usize, usize, f32, usize)> = None;
    let mut right_area = [0.0f32; MAX_BINS];
    let mut right_count = [0u32; MAX_BINS];
    for a in 0..3 {
        if k1a[a] == 0.0 {
            continue;
        }
        let (bins, counts) = (&bins[a], &counts[a]);
        // right_*[i]: bins i..nb.
        let mut acc = Box4::empty();
        let mut cnt = 0u32;
        for i in (1..nb).rev() {
            acc.merge(&bins[i]);
            cnt += counts[i];
            right_area[i] = ctx.area.of_box(&acc);
            right_count[i] = cnt;
        }
        let mut acc = Box4::empty();
        let mut cnt = 0u32;
        for i in 0..nb - 1 {
            acc.merge(&bins[i]);
            cnt += counts[i];
            let rc = right_count[i + 1];
            if cnt == 0 || rc == 0 {
                continue;
            }
            let cost = ctx.area.of_box(&acc) * cnt as f32 + right_area[i + 1] * rc as f32;
            if best.is_none_or(|b| cost < b.2) {
                best = Some((a, i, cost, cnt as usize));
            }
        }
    }
    let (axis, bin, cost, left_count) = best?;
    let mut left = Box4::empty();
    let mut right = Box4::empty();
    for (i, bin_box) in bins[axis].iter().enumerate().take(nb) {
        if i <= bin {
            left.merge(bin_box);
        } else {
            right.merge(bin_box);
        }
    }
    Some(Split {
        axis,
        bin,
        bins: nb,
        cost,
        left_count,
        left,
        right,
    })
}

/// Binning offsets and scales for doubled-centroid bounds `cb` and `nb` bins; the scale is 0
/// on axes of zero extent (or too small an extent to bin).
#[inline(always)]
fn bin_params(cb: &Box4, nb: usize) -> (F4, F4) {
    let e = cb.hi.sub(cb.lo).to_array();
    let mut k1 = [0.0f32; 4];
    for a in 0..3 {
        if e[a] > 0.0 {
            // Slightly below `nb / extent` so the largest centroid lands in the last bin.
            let s = (nb as f32 * (1.0 - 1e-6)) / e[a];
            if s.is_finite() {
                k1[a] = s;
            }
        }
    }
    (cb.lo, F4::new(k1[0], k1[1], k1[2], 0.0))
}

/// Partitions `src` into `dst` (references in bins `0..=split.bin` first, order kept) and
/// returns the doubled-centroid bounds of both sides.
#[inline(never)]
fn partition(src: &[PrimRef], dst: &mut [PrimRef], cb: &Box4, s: &Split) -> (Box4, Box4) {
    let (k0, k1) = bin_params(cb, s.bins);
    let (k0, k1) = (k0.lane(s.axis), k1.lane(s.axis));
    let last = (s.bins - 1) as f32;
    let split_bin = s.bin as i32;
    let a = s.axis;
    let inf = F4::splat(f32::INFINITY);
    let ninf = F4::splat(f32::NEG_INFINITY);
    let mut l_lo = inf;
    let mut l_hi = ninf;
    let mut r_lo = inf;
    let mut r_hi = ninf;
    let (mut l, mut r) = (0usize, s.left_count);
    for e in src {
        let c = e.lo().add(e.hi());
        // The same operations as `bin_coords`, on one lane: the same bin.
        let f = (e.min[a] + e.max[a] - k0) * k1;
        let f = if f < last { f } else { last };
        let goes_left = (f as i32) <= split_bin;
        let pos = if goes_left { l } else { r };
        dst[pos] = *e;
        l += goes_left as usize;
        r += !goes_left as usize;
        let m = F4::mask(goes_left);
        l_lo = l_lo.min(F4::select(m, c, inf));
        l_hi = l_hi.max(F4::select(m, c, ninf));
        r_lo = r_lo.min(F4::select(m, inf, c));
        r_hi = r_hi.max(F4::select(m, ninf, c));
    }
    assert!(
        l == s.left_count && r == src.len(),
        "partition disagrees with the bins"
    );
    let z = |lo: F4, hi: F4| Box4 {
        lo: lo.xyz0(),
        hi: hi.xyz0(),
    };
    (z(l_lo, l_hi), z(r_lo, r_hi))
}

/// Largest node that tries every partition of its references (`2^(n-1) - 1` of them).
const ENUMERATE: usize = 5;

/// A node of `2..=SMALL` references, split exactly: two references directly, up to
/// [`ENUMERATE`] by trying every partition, more by sorting the references by centroid on every
/// axis and trying every split of each order.
fn small_node(t: Task<'_>, b: Box4, out: &mut Vec<Node>, ctx: &Ctx) {
    match t.src.len() {
        2 => pair_node(t, b, out, ctx),
        n if n <= ENUMERATE => enumerate_node(t, b, out, ctx),
        _ => sweep_node(t, b, out, ctx),
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
        t.idx[k] = r.index();
        let p = PrimBounds {
            min: [r.min[0], r.min[1], r.min[2]],
            max: [r.max[0], r.max[1], r.max[2]],
        };
        t.bnd[k] = p;
        out.push(Node::leaf(p.min, p.max, t.first + k as u32, 1));
    }
}

/// `3..=ENUMERATE` references: the bounds of every subset (each from a smaller one), then the
/// cheapest of all partitions into two non-empty sets.
fn enumerate_node(t: Task<'_>, b: Box4, out: &mut Vec<Node>, ctx: &Ctx) {
    let n = t.src.len();
    debug_assert!((3..=ENUMERATE).contains(&n));
    let full = (1usize << n) - 1;
    let mut sub = [Box4::empty(); 1 << ENUMERATE];
    let mut area = [0.0f32; 1 << ENUMERATE];
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
        if m >> k & 1 == 1 {
            t.dst[l] = *e;
            l += 1;
        } else {
            t.dst[r] = *e;
            r += 1;
        }
    }
    let (lt, rt) = t.split(left, true);
    let dummy = Box4::empty();
    join(b, (lt, sub[m], dummy), (rt, sub[full ^ m], dummy), out, ctx);
}

/// `ENUMERATE+1..=SMALL` references: sorts them by centroid on every axis and tries every split
/// of each order (an exact sweep).
fn sweep_node(t: Task<'_>, b: Box4, out: &mut Vec<Node>, ctx: &Ctx) {
    let n = t.src.len();
    debug_assert!((2..=SMALL).contains(&n));
    let mut lo = [F4::splat(0.0); SMALL];
    let mut hi = [F4::splat(0.0); SMALL];
    let mut cen = [[0.0f32; SMALL]; 3];
    for (i, r) in t.src.iter().enumerate() {
        lo[i] = r.lo();
        hi[i] = r.hi();
        let c = lo[i].add(hi[i]).to_array();
        for a in 0..3 {
            cen[a][i] = c[a];
        }
    }

    let mut best_cost = f32::INFINITY;
    let mut best_order = [0u8; SMALL];
    let mut best_k = 0usize;
    let mut best_lb = Box4::empty();
    let mut right_area = [0.0f32; SMALL];
    for cen in &cen {
        // Insertion sort of the indices by centroid (stable: ties keep reference order).
        let mut order = [0u8; SMALL];
        for i in 0..n {
            let key = cen[i];
            let mut j = i;
            while j > 0 && cen[order[j - 1] as usize] > key {
                order[j] = order[j - 1];
                j -= 1;
            }
            order[j] = i as u8;
        }
        if cen[order[0] as usize] == cen[order[n - 1] as usize] {
            continue; // every centroid at one coordinate: no split on this axis
        }
        let mut acc = Box4::empty();
        for k in (1..n).rev() {
            let o = order[k] as usize;
            acc.grow(lo[o], hi[o]);
            right_area[k] = ctx.area.of_box(&acc);
        }
        let mut acc = Box4::empty();
        for k in 1..n {
            let o = order[k - 1] as usize;
            acc.grow(lo[o], hi[o]);
            // Left: order[..k], right: order[k..].
            let cost = ctx.area.of_box(&acc) * k as f32 + right_area[k] * (n - k) as f32;
            if cost < best_cost {
                best_cost = cost;
                best_k = k;
                best_order = order;
                best_lb = acc;
            }
        }
    }
    if best_k == 0 {
        // All centroids coincide.
        if n <= ctx.max_leaf {
            return t.leaf(&b, out);
        }
        return recurse_by_pass(t, n / 2, b, out, ctx);
    }
    if ctx.prefers_leaf(n, ctx.area.of_box(&b), best_cost) {
        return t.leaf(&b, out);
    }
    let mut best_rb = Box4::empty();
    for &o in &best_order[best_k..n] {
        best_rb.grow(lo[o as usize], hi[o as usize]);
    }
    for (d, &o) in t.dst.iter_mut().zip(&best_order[..n]) {
        *d = t.src[o as usize];
    }
    let (lt, rt) = t.split(best_k, true);
    let dummy = Box4::empty();
    join(b, (lt, best_lb, dummy), (rt, best_rb, dummy), out, ctx);
}

/// Splits at the object median along the widest centroid axis (or at the middle index when all
/// centroids coincide); always returns `1..n`.
fn median_split(refs: &mut [PrimRef], cb: &Box4) -> usize {
    let mid = refs.len() / 2;
    let e = cb.hi.sub(cb.lo).to_array();
    let axis = (0..3).max_by(|&x, &y| e[x].total_cmp(&e[y])).unwrap_or(0);
    if e[axis] > 0.0 {
        let key = |r: &PrimRef| r.min[axis] * 0.5 + r.max[axis] * 0.5;
        refs.select_nth_unstable_by(mid, |p, q| {
            key(p).total_cmp(&key(q)).then(p.index().cmp(&q.index()))
        });
    }
    mid
}
