//! The walk of [`Bvh::self_pairs`] and [`Bvh::self_pairs_marked`]: the bounding volume test
//! tree of the four-wide copy of the tree (`Ray4`, made on first use and shared with the ray
//! casts, see `ray.rs`) against itself. The marked walk ([`LaneMarks`]) skips nodes and lane
//! pairs with no marked primitive under them, and primitive pairs of two unmarked ones.
//!
//! Every `Node4` is taken against itself once, in reverse storage order (children are stored
//! after their parent, so a subtree's nodes are mostly visited, and still in cache, just before
//! its root): the pairs within its leaf lanes, and each pair of different lanes. Two
//! overlapping interior lanes make a node-pair task, run at once from a stack (depth first):
//! each lane of one node against the four lanes of the other. Lane tests are SSE tests of four
//! boxes against four (a node's lanes against a rotation of the other's). Of the overlapping
//! lane pairs, two interior lanes push a task, two one-primitive leaves are reported, a leaf
//! against an interior lane becomes a query of each of the leaf's primitives down that
//! subtree, and two leaves compare their primitives (each leaf first cut down to the primitives
//! that overlap the other leaf's box). In a tree larger than the caches the tasks pass through
//! a small window that prefetches their nodes a few tasks ahead. The primitive tests take no
//! branch on their outcome (nor on the marks): every pair tested is written to a small buffer
//! that advances only when the boxes overlap and a side is marked, and the buffer goes to the
//! callback when full and at the end of the walk. A leaf's pairs within itself are tested four
//! at a time (its boxes laid out by face), and only the overlapping pairs are written.

use super::ray::{Node4, Ray4, INTERIOR};
use super::{prefetch, prefetch_node};
use crate::build::f4::{overlap, prim_box, F4};
use crate::bvh::{Bvh, PrimBounds};
use rayon::prelude::*;

/// One box in every lane, to test against the four lanes of a [`Node4`].
#[derive(Clone, Copy)]
struct Splat {
    lo: [F4; 3],
    hi: [F4; 3],
}

impl Splat {
    /// The box of lane `lane` of `n`.
    #[inline(always)]
    fn lane(n: &Node4, lane: usize) -> Self {
        Self {
            lo: [0, 1, 2].map(|a| F4::splat(n.b[a][lane])),
            hi: [0, 1, 2].map(|a| F4::splat(n.b[3 + a][lane])),
        }
    }

    /// A primitive's box.
    #[inline(always)]
    fn prim(p: &PrimBounds) -> Self {
        Self {
            lo: p.min.map(F4::splat),
            hi: p.max.map(F4::splat),
        }
    }

    /// Bit `i` set when the box overlaps the box of lane `i` of `n` (closed boxes; an empty
    /// lane's inverted box overlaps nothing).
    #[inline(always)]
    fn hits(&self, n: &Node4) -> u32 {
        self.hits_faces(&n.b)
    }

    /// [`Splat::hits`] on four boxes laid out by face as a [`Node4`]'s are (`b[a]`: the lower
    /// coordinates along axis `a`, `b[3 + a]` the upper ones).
    #[inline(always)]
    fn hits_faces(&self, b: &[[f32; 4]; 6]) -> u32 {
        let mut m = F4::load4(&b[0])
            .le(self.hi[0])
            .and(self.lo[0].le(F4::load4(&b[3])));
        for a in 1..3 {
            m = m
                .and(F4::load4(&b[a]).le(self.hi[a]))
                .and(self.lo[a].le(F4::load4(&b[3 + a])));
        }
        m.bits()
    }
}

/// The four boxes of a [`Node4`] loaded by face: `lo[a]` the smallest coordinates along axis
/// `a`, `hi[a]` the largest.
#[derive(Clone, Copy)]
struct Rows {
    lo: [F4; 3],
    hi: [F4; 3],
}

impl Rows {
    #[inline(always)]
    fn of(n: &Node4) -> Self {
        Self {
            lo: [0, 1, 2].map(|a| F4::load4(&n.b[a])),
            hi: [0, 1, 2].map(|a| F4::load4(&n.b[3 + a])),
        }
    }

    /// The lanes moved down by `K` (lane `i` holds lane `(i + K) % 4`).
    #[inline(always)]
    fn rot<const K: i32>(&self) -> Self {
        Self {
            lo: self.lo.map(F4::rot::<K>),
            hi: self.hi.map(F4::rot::<K>),
        }
    }

    /// Bit `i` set when lane `i` of `self` overlaps lane `i` of `o`.
    #[inline(always)]
    fn hits(&self, o: &Rows) -> u32 {
        let mut m = self.lo[0].le(o.hi[0]).and(o.lo[0].le(self.hi[0]));
        for a in 1..3 {
            m = m.and(self.lo[a].le(o.hi[a])).and(o.lo[a].le(self.hi[a]));
        }
        m.bits()
    }
}

/// The box of lane `lane` of `n` as two vectors (lane 3 zero), as [`prim_box`] gives.
#[inline(always)]
fn lane_box(n: &Node4, lane: usize) -> (F4, F4) {
    (
        F4::new(n.b[0][lane], n.b[1][lane], n.b[2][lane], 0.0),
        F4::new(n.b[3][lane], n.b[4][lane], n.b[5][lane], 0.0),
    )
}

/// Pairs a walk gathers before handing them to its callback (see [`Walk::emit`]).
const PAIR_BUFFER: usize = 64;

/// Leaves of at most this many primitives are cut down to the primitives that overlap the
/// other leaf's box before their pairs are tested (`Walk::leaf_leaf`).
const FILTERED_LEAF: usize = 16;

/// Number of tasks taken off the stack ahead of their turn, so that the lines they read are
/// on their way while the tasks before them run.
const WINDOW: usize = 8;

/// How many nodes ahead of its turn in [`Walk::run`] a node's multi-primitive leaves are
/// prefetched (in a tree that takes the window; 100k boxes: 5.5 -> 5.3 ms; in a small tree
/// it only costs instructions).
const LEAF_AHEAD: usize = 4;

/// Size of the four-wide tree beyond which the walk goes through the window: in a tree larger
/// than a core's caches the tasks wait on memory; in a smaller one the window's bookkeeping
/// costs more than it saves (10k boxes: 0.37 ms without, 0.40 with; 100k: 5.9 either way; 1M:
/// 73 ms without, 62 with).
const WINDOW_BYTES: usize = 1 << 20;

/// Which primitives a self walk is about: per `Node4`, the lanes with a marked primitive under
/// them; per primitive slot, whether it is marked. Pairs of two unmarked primitives are not
/// reported, and node pairs with no marked lane are not visited.
pub(crate) trait LaneMarks: Sync {
    /// Everything marked (the plain walk): every check below is skipped at compile time.
    const ALL: bool;
    /// Bit `i` set when lane `i` of `Node4` `k` has a marked primitive under it (for a lane of
    /// one primitive: when that primitive is marked).
    fn lanes(&self, k: u32) -> u32;
    /// Whether the primitive in slot `s` is marked.
    fn slot(&self, s: usize) -> bool;
}

/// Everything marked.
pub(crate) struct AllMarked;

impl LaneMarks for AllMarked {
    const ALL: bool = true;
    #[inline(always)]
    fn lanes(&self, _: u32) -> u32 {
        0xf
    }
    #[inline(always)]
    fn slot(&self, _: usize) -> bool {
        true
    }
}

/// Lane marks of a [`crate::PairMarks`] made for the walked tree.
pub(crate) struct Marked<'a> {
    pub(crate) lanes: &'a [u8],
    pub(crate) slots: &'a [bool],
}

impl LaneMarks for Marked<'_> {
    const ALL: bool = false;
    #[inline(always)]
    fn lanes(&self, k: u32) -> u32 {
        self.lanes[k as usize] as u32
    }
    #[inline(always)]
    fn slot(&self, s: usize) -> bool {
        self.slots[s]
    }
}

/// The lane bits of `m` rotated down by `k` within four bits (bit `i` of the result is bit
/// `(i + k) % 4` of `m`).
#[inline(always)]
fn rot4(m: u32, k: u32) -> u32 {
    ((m >> k) | (m << (4 - k))) & 0xf
}

/// The state of one self walk.
struct Walk<'a, F, M> {
    t: &'a Bvh,
    r4: &'a Ray4,
    marks: &'a M,
    /// Node-pair tasks: two different nodes whose boxes overlap.
    tasks: Vec<(u32, u32)>,
    /// Scratch stack of the primitive queries.
    qstack: Vec<u32>,
    /// Whether tasks go through the prefetch window (large trees) rather than being prefetched
    /// as they are pushed.
    ahead: bool,
    /// Pairs waiting for `f` (`pairs[..waiting]`), smaller index first; see [`Walk::emit`].
    pairs: [(u32, u32); PAIR_BUFFER],
    waiting: usize,
    f: F,
}

impl<'a, F: FnMut(u32, u32), M: LaneMarks> Walk<'a, F, M> {
    /// A walk of `t` with marks `marks`, the window on or off (`ahead`), handing its pairs to
    /// `f`.
    fn new(t: &'a Bvh, marks: &'a M, ahead: bool, f: F) -> Self {
        Walk {
            t,
            r4: t.four_wide(),
            marks,
            tasks: Vec::with_capacity(256),
            qstack: Vec::with_capacity(64),
            ahead,
            pairs: [(0, 0); PAIR_BUFFER],
            waiting: 0,
            f,
        }
    }

    /// For tests: `leaf_self` by groups, or pair by pair.
    #[cfg(test)]
    fn leaf_self_either(&mut self, first: usize, count: usize, by_groups: bool) {
        if by_groups {
            self.leaf_self(first, count);
        } else {
            self.leaf_self_pairwise(first, count);
        }
    }

    /// Writes the pair of primitives `a` and `b` (different) at the end of the pair buffer and
    /// keeps it when `hit`: the leaves' tests take no branch on their outcome, which no
    /// predictor guesses where boxes crowd. The buffer goes to `f` when full and at the end of
    /// the walk, in the order the pairs were kept.
    #[inline(always)]
    fn emit(&mut self, a: u32, b: u32, hit: bool) {
        self.pairs[self.waiting] = (a.min(b), a.max(b));
        self.waiting += hit as usize;
        if self.waiting == PAIR_BUFFER {
            self.flush();
        }
    }

    /// Hands the waiting pairs to `f`.
    fn flush(&mut self) {
        for &(a, b) in &self.pairs[..self.waiting] {
            (self.f)(a, b);
        }
        self.waiting = 0;
    }

    /// Pushes the task of nodes `a` and `b` (prefetching them now unless the window will).
    #[inline(always)]
    fn push(&mut self, a: u32, b: u32) {
        if !self.ahead {
            prefetch_node(self.r4, a);
            prefetch_node(self.r4, b);
        }
        self.tasks.push((a, b));
    }

    /// Every node of `nodes` against itself, in reverse storage order, each followed by the
    /// node-pair tasks it made.
    fn run(&mut self, nodes: std::ops::Range<usize>) {
        let start = nodes.start;
        for k in nodes.rev() {
            if self.ahead && k >= start + LEAF_AHEAD {
                self.prefetch_leaves(k - LEAF_AHEAD);
            }
            if !M::ALL && self.marks.lanes(k as u32) == 0 {
                // Every pair this node makes is of two primitives under it, none marked.
                continue;
            }
            self.node_self(k);
            if self.ahead {
                self.drain_ahead();
            } else {
                while let Some((a, b)) = self.tasks.pop() {
                    self.node_pair(a, b);
                }
            }
        }
    }

    /// Starts loading the first primitive box of each leaf lane of node `k` with more than one
    /// primitive, which [`Walk::node_self`] will read (the walk reaches `k` `LEAF_AHEAD` nodes
    /// later).
    #[inline(always)]
    fn prefetch_leaves(&self, k: usize) {
        let n = self.r4.at(k);
        for i in 0..4 {
            if n.meta[i] > 1 && n.meta[i] != INTERIOR {
                prefetch(
                    self.t
                        .prim_bounds
                        .as_ptr()
                        .wrapping_add(n.first[i] as usize),
                );
            }
        }
    }

    /// Runs the tasks on the stack (and those they make) through the prefetch window: the
    /// next `WINDOW` tasks are taken off the stack and prefetched ahead of their turn.
    fn drain_ahead(&mut self) {
        let mut window = [(0u32, 0u32); WINDOW];
        let (mut head, mut len) = (0usize, 0usize);
        loop {
            while len < WINDOW {
                let Some((a, b)) = self.tasks.pop() else {
                    break;
                };
                prefetch_node(self.r4, a);
                prefetch_node(self.r4, b);
                window[(head + len) % WINDOW] = (a, b);
                len += 1;
            }
            if len == 0 {
                return;
            }
            let (a, b) = window[head];
            head = (head + 1) % WINDOW;
            len -= 1;
            self.node_pair(a, b);
        }
    }

    /// Node `k` against itself: the pairs within its leaf lanes, and each pair of different
    /// lanes (their subtrees' pairs).
    #[inline(always)]
    fn node_self(&mut self, k: usize) {
        let n = self.r4.at(k);
        let lm = self.marks.lanes(k as u32);
        for i in 0..4 {
            let meta = n.meta[i];
            if meta > 1 && meta != INTERIOR && lm >> i & 1 != 0 {
                self.leaf_self(n.first[i] as usize, meta as usize);
            }
        }
        // Lane pairs `(i, i + 1)` (all four, cyclically; bits 0..4) and `(i, i + 2)` (`i` = 0,
        // 1; bits 4..6): each pair of different lanes once.
        let r = Rows::of(n);
        let mut m = r.hits(&r.rot::<1>()) | (r.hits(&r.rot::<2>()) & 0b0011) << 4;
        if !M::ALL {
            // Only lane pairs with a marked side.
            m &= (lm | rot4(lm, 1)) | ((lm | rot4(lm, 2)) & 0b0011) << 4;
        }
        self.dispatch((n, lm), (n, lm), m, |k| (k + 1 + (k >> 2)) & 3);
    }

    /// Nodes `a` and `b` (different, boxes overlapping) against each other.
    #[inline(always)]
    fn node_pair(&mut self, a: u32, b: u32) {
        let r4 = self.r4;
        let (na, nb) = (r4.at(a as usize), r4.at(b as usize));
        // Bit `4 * k + i`: lane `i` of `na` against lane `(i + k) % 4` of `nb`.
        let (ra, rb) = (Rows::of(na), Rows::of(nb));
        let mut m = ra.hits(&rb)
            | ra.hits(&rb.rot::<1>()) << 4
            | ra.hits(&rb.rot::<2>()) << 8
            | ra.hits(&rb.rot::<3>()) << 12;
        let (la, lb) = (self.marks.lanes(a), self.marks.lanes(b));
        if !M::ALL {
            // Only lane pairs with a marked side: lane `i` of `na` marked (in every group of
            // four bits), or lane `(i + k) % 4` of `nb` (group `k`).
            m &= (la * 0x1111)
                | rot4(lb, 0)
                | rot4(lb, 1) << 4
                | rot4(lb, 2) << 8
                | rot4(lb, 3) << 12;
        }
        self.dispatch((na, la), (nb, lb), m, |k| (k + (k >> 2)) & 3);
    }

    /// The overlapping lane pairs `m` of `na` and `nb` (each with its lane marks): bit `k` is
    /// lane `k % 4` of `na` against lane `j_of(k)` of `nb`.
    #[inline(always)]
    fn dispatch(
        &mut self,
        (na, la): (&Node4, u32),
        (nb, lb): (&Node4, u32),
        mut m: u32,
        j_of: impl Fn(usize) -> usize,
    ) {
        while m != 0 {
            let k = m.trailing_zeros() as usize;
            m &= m - 1;
            let (i, j) = (k & 3, j_of(k));
            self.lanes(na, i, la >> i & 1 != 0, nb, j, lb >> j & 1 != 0);
        }
    }

    /// Lane `i` of `na` against lane `j` of `nb`, whose boxes overlap (different subtrees);
    /// `mi` and `mj` say whether each has a marked primitive under it (at least one does).
    #[inline(always)]
    fn lanes(&mut self, na: &Node4, i: usize, mi: bool, nb: &Node4, j: usize, mj: bool) {
        match (na.meta[i] == INTERIOR, nb.meta[j] == INTERIOR) {
            (true, true) => {
                self.push(na.first[i], nb.first[j]);
            }
            (false, true) => self.leaf_into(na, i, mi, nb, j, mj),
            (true, false) => self.leaf_into(nb, j, mj, na, i, mi),
            (false, false) => {
                if na.meta[i] == 1 && nb.meta[j] == 1 {
                    // One-primitive leaves have their primitive's box, seen to overlap (and
                    // one of the two is marked).
                    self.emit(na.first[i], nb.first[j], true);
                } else {
                    self.leaf_leaf(na, i, mi, nb, j, mj);
                }
            }
        }
    }

    /// The pairs within the leaf of `count` primitives from slot `first` (with a marked side).
    /// Up to `FILTERED_LEAF` primitives: their boxes laid out by face, four to a group, and
    /// each primitive tested against the groups after it four at a time; only the overlapping
    /// pairs with a marked side are written, in the same order as the pair-by-pair loop
    /// (`leaf_self_pairwise`, which larger leaves take).
    fn leaf_self(&mut self, first: usize, count: usize) {
        if count <= 4 || count > FILTERED_LEAF {
            // At most six pairs: a group would cost about as much.
            self.leaf_self_pairwise(first, count);
            return;
        }
        let t = self.t;
        let prims = &t.prim_bounds[first..first + count];
        let groups = count.div_ceil(4);
        // Group `g`, face `f` (min x, y, z, max x, y, z), lane `l`: primitive `4 g + l`, laid
        // out as a `Node4`'s boxes. The lanes past `count` keep an empty node's inverted box,
        // which overlaps nothing.
        let mut faces = [Node4::EMPTY.b; FILTERED_LEAF / 4];
        let mut marked = 0u32;
        for (k, p) in prims.iter().enumerate() {
            let g = &mut faces[k / 4];
            for a in 0..3 {
                g[a][k % 4] = p.min[a];
                g[3 + a][k % 4] = p.max[a];
            }
            marked |= ((M::ALL || self.marks.slot(first + k)) as u32) << k;
        }
        for (s, prim) in prims[..count - 1].iter().enumerate() {
            let p = Splat::prim(prim);
            let mut hits = 0u32;
            for (g, group) in faces.iter().enumerate().take(groups).skip((s + 1) / 4) {
                hits |= p.hits_faces(group) << (4 * g);
            }
            // The primitives after `s`, with a marked side.
            hits &= !((2u32 << s) - 1);
            if marked >> s & 1 == 0 {
                hits &= marked;
            }
            let ip = t.prim_indices[first + s];
            while hits != 0 {
                let u = hits.trailing_zeros() as usize;
                hits &= hits - 1;
                self.emit(ip, t.prim_indices[first + u], true);
            }
        }
    }

    /// [`Walk::leaf_self`] pair by pair, for leaves of up to four primitives or more than
    /// `FILTERED_LEAF`.
    fn leaf_self_pairwise(&mut self, first: usize, count: usize) {
        let t = self.t;
        for s in first..first + count {
            let (plo, phi) = prim_box(&t.prim_bounds[s]);
            let ms = self.marks.slot(s);
            for u in s + 1..first + count {
                // With a marked side (no branch on the marks either).
                let marked = M::ALL || ms | self.marks.slot(u);
                let (ulo, uhi) = prim_box(&t.prim_bounds[u]);
                let hit = overlap(plo, phi, ulo, uhi) & marked;
                self.emit(t.prim_indices[s], t.prim_indices[u], hit);
            }
        }
    }

    /// The primitive pairs of leaf lanes `i` of `na` and `j` of `nb` (not both of one
    /// primitive), with a marked side.
    fn leaf_leaf(&mut self, na: &Node4, i: usize, mi: bool, nb: &Node4, j: usize, mj: bool) {
        let t = self.t;
        let marks = self.marks;
        let prims = |n: &Node4, lane: usize| {
            let (first, meta) = (n.first[lane] as usize, n.meta[lane] as usize);
            if meta == 1 {
                // Slot-free: the lane holds the primitive index and its box.
                (first..first + 1, true)
            } else {
                (first..first + meta, false)
            }
        };
        let get = |n: &Node4, lane: usize, single: bool, s: usize| {
            if single {
                (lane_box(n, lane), s as u32)
            } else {
                (prim_box(&t.prim_bounds[s]), t.prim_indices[s])
            }
        };
        // Whether the primitive of slot `s` is marked; a one-primitive lane's mark is its
        // primitive's.
        let marked = |single: bool, s: usize, lane_marked: bool| {
            if single {
                lane_marked
            } else {
                marks.slot(s)
            }
        };
        let (ra, sa) = prims(na, i);
        let (rb, sb) = prims(nb, j);
        if !sa && !sb && ra.len() <= FILTERED_LEAF && rb.len() <= FILTERED_LEAF {
            // Two leaves of several primitives: only a primitive that overlaps the other
            // leaf's box can overlap one of its primitives (the leaf's box holds them all).
            // Each side is cut down to those first (kept in slot order, so the pairs come in
            // the same order as from the full loop), then the pairs of what is left.
            let (blo, bhi) = lane_box(nb, j);
            let (alo, ahi) = lane_box(na, i);
            let mut keep_a = [0u32; FILTERED_LEAF];
            let mut keep_b = [0u32; FILTERED_LEAF];
            let (mut ka, mut kb) = (0, 0);
            for s in ra {
                let (plo, phi) = prim_box(&t.prim_bounds[s]);
                keep_a[ka] = s as u32;
                ka += overlap(plo, phi, blo, bhi) as usize;
            }
            for u in rb {
                let (ulo, uhi) = prim_box(&t.prim_bounds[u]);
                keep_b[kb] = u as u32;
                kb += overlap(ulo, uhi, alo, ahi) as usize;
            }
            for &s in &keep_a[..ka] {
                let s = s as usize;
                let (plo, phi) = prim_box(&t.prim_bounds[s]);
                let ms = M::ALL || marks.slot(s);
                let ip = t.prim_indices[s];
                for &u in &keep_b[..kb] {
                    let u = u as usize;
                    let with_mark = ms | marks.slot(u);
                    let (ulo, uhi) = prim_box(&t.prim_bounds[u]);
                    let hit = overlap(plo, phi, ulo, uhi) & with_mark;
                    self.emit(ip, t.prim_indices[u], hit);
                }
            }
            return;
        }
        for s in ra {
            let ((plo, phi), ip) = get(na, i, sa, s);
            let ms = M::ALL || marked(sa, s, mi);
            for u in rb.clone() {
                // With a marked side (no branch on the marks either).
                let with_mark = ms | marked(sb, u, mj);
                let ((ulo, uhi), iu) = get(nb, j, sb, u);
                let hit = overlap(plo, phi, ulo, uhi) & with_mark;
                self.emit(ip, iu, hit);
            }
        }
    }

    /// Leaf lane `i` of `nl` against interior lane `j` of `ns` (boxes overlapping; `ml` and
    /// `ms` say which has a marked primitive, at least one does): each of the leaf's
    /// primitives whose box overlaps the lane's is queried down that subtree (an unmarked one
    /// only when the subtree has a marked primitive).
    fn leaf_into(&mut self, nl: &Node4, i: usize, ml: bool, ns: &Node4, j: usize, ms: bool) {
        let root = ns.first[j];
        let (first, meta) = (nl.first[i], nl.meta[i]);
        if meta == 1 {
            self.query(&Splat::lane(nl, i), lane_box(nl, i), first, ml, root);
            return;
        }
        let (slo, shi) = lane_box(ns, j);
        let t = self.t;
        for s in first as usize..first as usize + meta as usize {
            let pm = M::ALL || self.marks.slot(s);
            if !pm && !ms {
                continue;
            }
            let p = &t.prim_bounds[s];
            let (plo, phi) = prim_box(p);
            if overlap(plo, phi, slo, shi) {
                self.query(&Splat::prim(p), (plo, phi), t.prim_indices[s], pm, root);
            }
        }
    }

    /// Reports the pairs of primitive `ip` (box `p`, also as `pbox`; marked when `pm`) with the
    /// primitives under `Node4` `root` (whose box it overlaps; `ip` is not under it). An
    /// unmarked `ip` only follows lanes with a marked primitive, and only reports those.
    fn query(&mut self, p: &Splat, pbox: (F4, F4), ip: u32, pm: bool, root: u32) {
        let (t, r4) = (self.t, self.r4);
        self.qstack.clear();
        let mut cur = root;
        loop {
            let n = r4.at(cur as usize);
            let mut m = p.hits(n);
            if !M::ALL && !pm {
                m &= self.marks.lanes(cur);
            }
            let mut next = None;
            while m != 0 {
                let lane = m.trailing_zeros() as usize;
                m &= m - 1;
                let (first, meta) = (n.first[lane], n.meta[lane]);
                if meta == INTERIOR {
                    prefetch_node(r4, first);
                    if let Some(x) = next.replace(first) {
                        self.qstack.push(x);
                    }
                } else if meta == 1 {
                    self.emit(ip, first, true);
                } else {
                    for s in first as usize..first as usize + meta as usize {
                        // An unmarked `ip` reports marked primitives only (no branch on it).
                        let marked = M::ALL || pm | self.marks.slot(s);
                        let (ulo, uhi) = prim_box(&t.prim_bounds[s]);
                        let hit = overlap(pbox.0, pbox.1, ulo, uhi) & marked;
                        self.emit(ip, t.prim_indices[s], hit);
                    }
                }
            }
            match next.or_else(|| self.qstack.pop()) {
                Some(c) => cur = c,
                None => return,
            }
        }
    }
}

/// Every overlapping pair of primitives of the non-empty tree `t` with a marked side (all of
/// them with [`AllMarked`]), once each, to `f`.
pub(crate) fn self_pairs4<M: LaneMarks>(t: &Bvh, marks: &M, f: impl FnMut(u32, u32)) {
    let r4 = t.four_wide();
    walk(t, marks, large(r4), 0..r4.nodes.len(), f);
}

/// The pairs of [`self_pairs4`] in a `Vec`, found on the current rayon pool: the nodes are cut
/// into `tasks` ranges (fewer in a small tree), walked independently and concatenated from the
/// last range to the first, which is the serial order whatever the thread count.
pub(crate) fn par_self_pairs4<M: LaneMarks>(t: &Bvh, marks: &M, tasks: usize) -> Vec<(u32, u32)> {
    let r4 = t.four_wide();
    let (n, ahead) = (r4.nodes.len(), large(r4));
    if rayon::current_num_threads() == 1 {
        let mut out = Vec::with_capacity(t.len());
        walk(t, marks, ahead, 0..n, |a, b| out.push((a, b)));
        return out;
    }
    let tasks = tasks.clamp(1, n);
    let parts: Vec<Vec<(u32, u32)>> = (0..tasks)
        .into_par_iter()
        .map(|c| {
            // Range `c` from the top: nodes `n * (tasks - 1 - c) / tasks ..`.
            let cut = |i: usize| (n as u64 * i as u64 / tasks as u64) as usize;
            let mut v = Vec::new();
            walk(
                t,
                marks,
                ahead,
                cut(tasks - 1 - c)..cut(tasks - c),
                |a, b| v.push((a, b)),
            );
            v
        })
        .collect();
    let mut out = Vec::with_capacity(parts.iter().map(Vec::len).sum());
    for p in parts {
        out.extend_from_slice(&p);
    }
    out
}

/// Whether a walk of `r4` goes through the prefetch window.
fn large(r4: &Ray4) -> bool {
    std::mem::size_of_val(&r4.nodes[..]) > WINDOW_BYTES
}

/// The pairs found from the nodes `nodes` of `t` (all of them: [`self_pairs4`]), with the
/// window on or off (`ahead`).
fn walk<M: LaneMarks>(
    t: &Bvh,
    marks: &M,
    ahead: bool,
    nodes: std::ops::Range<usize>,
    f: impl FnMut(u32, u32),
) {
    let mut w = Walk::new(t, marks, ahead, f);
    w.run(nodes);
    w.flush();
}

/// The lane marks of `t`'s four-wide copy for the primitive marks `slots` (per slot) and
/// `marked` (per primitive index, for lanes of one primitive, which hold the index): one pass
/// over the nodes, children before parents.
pub(crate) fn lane_marks(t: &Bvh, slots: &[bool], marked: impl Fn(u32) -> bool) -> Vec<u8> {
    let r4 = t.four_wide();
    let mut lanes = vec![0u8; r4.nodes.len()];
    for k in (0..r4.nodes.len()).rev() {
        let n = r4.at(k);
        let mut m = 0u8;
        for i in 0..4 {
            let (first, meta) = (n.first[i], n.meta[i]);
            let hit = match meta {
                0 => false,
                INTERIOR => lanes[first as usize] != 0,
                1 => marked(first),
                count => slots[first as usize..(first + count) as usize]
                    .iter()
                    .any(|&b| b),
            };
            m |= (hit as u8) << i;
        }
        lanes[k] = m;
    }
    lanes
}

#[cfg(test)]
mod tests {
    use crate::testing::rng;
    use crate::{Aabb, BuildOptions, Builder, Bvh};
    use nalgebra::{Point3, Vector3};

    /// `n` boxes in a cube of side `side`, half-extents up to `h` (some of size zero, some
    /// repeated).
    fn boxes(n: usize, side: f32, h: f32, r: &mut impl FnMut(f32, f32) -> f32) -> Vec<Aabb> {
        let mut v: Vec<Aabb> = (0..n)
            .map(|i| {
                let c = Point3::new(r(0.0, side), r(0.0, side), r(0.0, side));
                let e = if i % 7 == 0 {
                    Vector3::zeros()
                } else {
                    Vector3::new(r(0.0, h), r(0.0, h), r(0.0, h))
                };
                Aabb::from_center_half_extents(c, e)
            })
            .collect();
        for i in (0..n).step_by(11) {
            v[i] = v[i / 2];
        }
        v
    }

    fn sorted_pairs(t: &Bvh, ahead: bool) -> Vec<(u32, u32)> {
        let mut v = Vec::new();
        super::walk(
            t,
            &super::AllMarked,
            ahead,
            0..t.four_wide().nodes.len(),
            |a, b| v.push((a, b)),
        );
        v.sort_unstable();
        v
    }

    /// The marked walk, in both modes, against brute force over the pairs with a marked side,
    /// for marks of about `density` in four primitives.
    fn check_marked(t: &Bvh, b: &[Aabb], density: u64) {
        let mark = |i: u32| {
            (i as u64)
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .rotate_left(17)
                % 4
                < density
        };
        let m = t.marks(mark);
        let view = m.lane_view();
        let n = b.len();
        let mut expect = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                if b[i].intersects(&b[j]) && (mark(i as u32) || mark(j as u32)) {
                    expect.push((i as u32, j as u32));
                }
            }
        }
        for ahead in [false, true] {
            let mut v = Vec::new();
            super::walk(t, &view, ahead, 0..t.four_wide().nodes.len(), |a, b| {
                v.push((a, b))
            });
            v.sort_unstable();
            assert_eq!(v, expect, "density {density}, ahead {ahead}");
        }
    }

    fn check(t: &Bvh, b: &[Aabb]) {
        let n = b.len();
        let mut expect = Vec::new();
        for i in 0..n {
            for j in i + 1..n {
                if b[i].intersects(&b[j]) {
                    expect.push((i as u32, j as u32));
                }
            }
        }
        assert_eq!(sorted_pairs(t, false), expect);
        assert_eq!(sorted_pairs(t, true), expect);
        for density in 0..4 {
            check_marked(t, b, density);
        }
    }

    #[test]
    fn both_modes_match_brute_force() {
        let mut r = rng(11);
        for builder in [Builder::BinnedSah, Builder::Lbvh] {
            // 20: leaves too large for `leaf_leaf`'s filtered loop and `leaf_self`'s groups
            // take the pair-by-pair loops; 13 and 16 fill the groups partly and wholly.
            for leaf in [1, 3, 8, 13, 16, 20] {
                for n in [1, 2, 5, 17, 300, 1500] {
                    let b = boxes(n, (n as f32).cbrt() * 2.0, 1.0, &mut r);
                    let options = BuildOptions {
                        builder,
                        max_leaf_size: leaf,
                        ..Default::default()
                    };
                    let mut t = Bvh::build(&b, options).unwrap();
                    check(&t, &b);
                    // After a refit, the four-wide copy made above follows the new boxes.
                    let b = boxes(n, (n as f32).cbrt() * 2.0, 1.0, &mut r);
                    t.refit(&b).unwrap();
                    check(&t, &b);
                }
            }
        }
    }

    /// `leaf_self` by groups of four writes the same pairs in the same order as pair by pair,
    /// for every leaf of trees with leaves of up to 16 primitives (crowded boxes, so that
    /// many pairs within a leaf overlap), with no marks and with marks of each density.
    #[test]
    fn leaf_self_by_groups_matches_pair_by_pair() {
        let mut r = rng(14);
        for leaf in [2, 5, 12, 16] {
            let b = boxes(400, 6.0, 1.0, &mut r);
            let options = BuildOptions {
                max_leaf_size: leaf,
                ..Default::default()
            };
            let t = Bvh::build(&b, options).unwrap();
            let r4 = t.four_wide();
            let leaves: Vec<(usize, usize)> = (0..r4.nodes.len())
                .flat_map(|k| {
                    let n = r4.at(k);
                    (0..4)
                        .filter(move |&i| n.meta[i] > 1 && n.meta[i] != super::INTERIOR)
                        .map(move |i| (n.first[i] as usize, n.meta[i] as usize))
                })
                .collect();
            // Leaves fill more than one group of four wherever they may.
            let largest = leaves.iter().map(|&(_, c)| c).max().unwrap_or(0);
            assert!(largest > 4 || leaf < 5, "leaf {leaf}: largest {largest}");
            for density in 0..5u64 {
                let pm = t.marks(|i| {
                    (i as u64)
                        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                        .rotate_left(17)
                        % 4
                        < density
                });
                let view = pm.lane_view();
                // Every leaf's own pairs, by groups or pair by pair, with marks `marks`.
                fn leaf_pairs<M: super::LaneMarks>(
                    t: &Bvh,
                    marks: &M,
                    leaves: &[(usize, usize)],
                    by_groups: bool,
                ) -> Vec<(u32, u32)> {
                    let mut out = Vec::new();
                    let mut w = super::Walk::new(t, marks, false, |a, b| out.push((a, b)));
                    for &(first, count) in leaves {
                        w.leaf_self_either(first, count, by_groups);
                    }
                    w.flush();
                    drop(w);
                    out
                }
                let (grouped, pairwise) = if density == 4 {
                    let all = &super::AllMarked;
                    (
                        leaf_pairs(&t, all, &leaves, true),
                        leaf_pairs(&t, all, &leaves, false),
                    )
                } else {
                    (
                        leaf_pairs(&t, &view, &leaves, true),
                        leaf_pairs(&t, &view, &leaves, false),
                    )
                };
                // Nothing is marked at density 0.
                assert_eq!(
                    pairwise.is_empty(),
                    density == 0,
                    "leaf {leaf}, density {density}"
                );
                assert_eq!(grouped, pairwise, "leaf {leaf}, density {density}");
            }
        }
    }

    #[test]
    fn large_tree_takes_the_window_and_matches_the_binary_walk() {
        let mut r = rng(12);
        let b = boxes(40_000, 70.0, 0.8, &mut r);
        let t = Bvh::build(&b, BuildOptions::default()).unwrap();
        assert!(super::large(t.four_wide()));
        let mut serial = Vec::new();
        t.self_pairs(|a, b| serial.push((a, b)));
        // Same order on one thread and on several.
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let four = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap();
        let par1 = one.install(|| t.par_self_pairs());
        assert_eq!(par1, four.install(|| t.par_self_pairs()));
        assert_eq!(par1, serial);
        let mut got = serial;
        got.sort_unstable();
        assert!(got.windows(2).all(|w| w[0] != w[1]));
        // The binary walk on the wide array: marks made for another tree mean "all marked".
        let mut expect = Vec::new();
        t.self_pairs_marked(&crate::PairMarks::default(), |a, b| expect.push((a, b)));
        expect.sort_unstable();
        assert!(!expect.is_empty());
        assert_eq!(got, expect);
    }

    #[test]
    fn parallel_order_does_not_depend_on_the_thread_count() {
        let mut r = rng(13);
        for n in [1, 2, 40, 700] {
            let b = boxes(n, (n as f32).cbrt() * 2.0, 1.0, &mut r);
            let t = Bvh::build(&b, BuildOptions::default()).unwrap();
            let mut serial = Vec::new();
            t.self_pairs(|a, b| serial.push((a, b)));
            for threads in [1, 2, 3] {
                let pool = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                assert_eq!(pool.install(|| t.par_self_pairs()), serial);
                for tasks in [1, 3, 256, 10_000] {
                    let got = pool.install(|| super::par_self_pairs4(&t, &super::AllMarked, tasks));
                    assert_eq!(got, serial);
                }
            }
        }
    }
}
