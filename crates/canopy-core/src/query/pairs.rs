//! Overlapping pairs: every pair of primitives whose boxes overlap within one tree (each pair
//! once), or between two trees; serial with a callback, and rayon-parallel into a `Vec` whose
//! order depends only on the trees, never on the thread count.
//!
//! Both walk the bounding volume test tree with an explicit stack of node pairs: a node against
//! itself expands to its two children against themselves and against each other; two different
//! nodes, when their boxes overlap, expand the larger one. The parallel versions first expand
//! the root task breadth-first into a fixed number of independent tasks, run those on rayon, and
//! concatenate the results in task order.
//!
//! [`Bvh::self_pairs`] walks the four-wide copy of the tree instead (see `pairs4.rs`). The
//! serial unmarked tree-vs-tree walk and the parallel self query run on the tree's wide array
//! (both children of a node in one cache line); the others on the nodes. The parallel self
//! query has a walk of its own: tasks are pairs of references to wide entries, pushed without
//! branches (every candidate is written, the stack length grows by the box test's result), and
//! the children line of a right child is prefetched as its tasks are pushed.
//!
//! The `_marked` variants report only pairs with at least one *marked* primitive (a broadphase
//! marks the proxies that moved). [`PairMarks`] summarises the marks per node, so whole
//! subtrees without a marked primitive are skipped: one pass finds every new pair of every
//! moved proxy, cheaper than one query per proxy once many moved.

use crate::aabb::overlaps;
use crate::build::f4::{node_box, overlap, prim_box};
use crate::bvh::{wide_at, Bvh, Node, Wide};
use rayon::prelude::*;

/// The parallel pair queries split the work into at least this many tasks (a fixed number, so
/// the output order does not depend on the thread count).
const PARALLEL_TASKS: usize = 256;

#[inline(always)]
fn nodes_overlap(a: &Node, b: &Node) -> bool {
    let (alo, ahi) = node_box(a);
    let (blo, bhi) = node_box(b);
    overlap(alo, ahi, blo, bhi)
}

#[inline(always)]
fn half_area(n: &Node) -> f32 {
    let d = [
        n.max[0] - n.min[0],
        n.max[1] - n.min[1],
        n.max[2] - n.min[2],
    ];
    d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
}

/// Which primitives a marked pair query is about, summarised per node: made by
/// [`Bvh::marks`] for one tree, valid for that tree until it is rebuilt (refit keeps it valid).
/// Marks made for another tree are treated as "everything marked": never a missed pair.
#[derive(Clone, Debug, Default)]
pub struct PairMarks {
    nodes: Vec<bool>,
    slots: Vec<bool>,
    any: bool,
}

impl PairMarks {
    /// `true` when at least one primitive is marked.
    pub fn any(&self) -> bool {
        self.any
    }
}

/// Node and primitive-slot filters of a pair walk.
trait Mask: Sync {
    fn node(&self, i: u32) -> bool;
    fn slot(&self, s: usize) -> bool;
}

/// Everything marked: the plain pair queries.
struct All;
impl Mask for All {
    #[inline(always)]
    fn node(&self, _: u32) -> bool {
        true
    }
    #[inline(always)]
    fn slot(&self, _: usize) -> bool {
        true
    }
}

impl Mask for PairMarks {
    #[inline(always)]
    fn node(&self, i: u32) -> bool {
        self.nodes[i as usize]
    }
    #[inline(always)]
    fn slot(&self, s: usize) -> bool {
        self.slots[s]
    }
}

/// A pair-walk task: node `a` of the first tree against node `b` of the second. In a self walk
/// (`SELF = true`, both trees the same) `a == b` means "the subtree against itself".
type Task = (u32, u32);

/// Expands one task into the tasks it generates, or returns `false` when it is a leaf task
/// (`a` and `b` leaves, or a leaf against itself) to be handled by `leaf_task`.
#[inline(always)]
fn expand<const SELF: bool, M1: Mask, M2: Mask>(
    t1: &Bvh,
    m1: &M1,
    t2: &Bvh,
    m2: &M2,
    (a, b): Task,
    mut push: impl FnMut(Task),
) -> bool {
    let na = &t1.nodes[a as usize];
    if SELF && a == b {
        if na.is_leaf() {
            return false;
        }
        let (l, r) = (a + 1, na.right());
        let (ml, mr) = (m1.node(l), m1.node(r));
        if (ml || mr) && nodes_overlap(&t1.nodes[l as usize], &t1.nodes[r as usize]) {
            push((l, r));
        }
        if mr {
            push((r, r));
        }
        if ml {
            push((l, l));
        }
        return true;
    }
    let nb = &t2.nodes[b as usize];
    let split_a = match (na.is_leaf(), nb.is_leaf()) {
        (true, true) => return false,
        (true, false) => false,
        (false, true) => true,
        (false, false) => half_area(na) >= half_area(nb),
    };
    if split_a {
        let mb = m2.node(b);
        for c in [na.right(), a + 1] {
            if (mb || m1.node(c)) && nodes_overlap(&t1.nodes[c as usize], nb) {
                push((c, b));
            }
        }
    } else {
        let ma = m1.node(a);
        for c in [nb.right(), b + 1] {
            if (ma || m2.node(c)) && nodes_overlap(na, &t2.nodes[c as usize]) {
                push((a, c));
            }
        }
    }
    true
}

/// Reports the overlapping primitive pairs of a leaf task.
#[inline(always)]
fn leaf_task<const SELF: bool, M1: Mask, M2: Mask>(
    t1: &Bvh,
    m1: &M1,
    t2: &Bvh,
    m2: &M2,
    (a, b): Task,
    f: &mut impl FnMut(u32, u32),
) {
    let na = &t1.nodes[a as usize];
    if SELF && a == b {
        let r = na.leaf_range();
        for s in r.clone() {
            let ps = &t1.prim_bounds[s];
            let ms = m1.slot(s);
            for u in s + 1..r.end {
                let pu = &t1.prim_bounds[u];
                if (ms || m1.slot(u)) && overlaps(&ps.min, &ps.max, &pu.min, &pu.max) {
                    let (x, y) = (t1.prim_indices[s], t1.prim_indices[u]);
                    f(x.min(y), x.max(y));
                }
            }
        }
        return;
    }
    let nb = &t2.nodes[b as usize];
    for s in na.leaf_range() {
        let ps = &t1.prim_bounds[s];
        if !overlaps(&ps.min, &ps.max, &nb.min, &nb.max) {
            continue;
        }
        let ms = m1.slot(s);
        for u in nb.leaf_range() {
            let pu = &t2.prim_bounds[u];
            if (ms || m2.slot(u)) && overlaps(&ps.min, &ps.max, &pu.min, &pu.max) {
                let (x, y) = (t1.prim_indices[s], t2.prim_indices[u]);
                if SELF {
                    f(x.min(y), x.max(y));
                } else {
                    f(x, y);
                }
            }
        }
    }
}

/// Walks task `start` depth-first and reports its pairs.
///
/// Tasks on the stack always hold two overlapping nodes (or a node against itself). Two
/// interior nodes descend together (four child pairs); a leaf of one primitive against a
/// subtree becomes a query of that primitive's box down the subtree, which tests one box
/// against both children of every node on its way; other leaves descend the other side.
fn walk<const SELF: bool, M1: Mask, M2: Mask>(
    t1: &Bvh,
    m1: &M1,
    t2: &Bvh,
    m2: &M2,
    start: Task,
    f: &mut impl FnMut(u32, u32),
) {
    let mut stack: Vec<Task> = Vec::with_capacity(128);
    let mut qstack: Vec<u32> = Vec::with_capacity(64);
    stack.push(start);
    while let Some((a, b)) = stack.pop() {
        let na = &t1.nodes[a as usize];
        if SELF && a == b {
            if na.is_leaf() {
                leaf_task::<SELF, M1, M2>(t1, m1, t2, m2, (a, b), f);
                continue;
            }
            let (l, r) = (a + 1, na.right());
            let (ml, mr) = (m1.node(l), m1.node(r));
            // A leaf of one primitive has no pairs of its own.
            if mr && t1.nodes[r as usize].count != 1 {
                stack.push((r, r));
            }
            if ml && t1.nodes[l as usize].count != 1 {
                stack.push((l, l));
            }
            if (ml || mr) && nodes_overlap(&t1.nodes[l as usize], &t1.nodes[r as usize]) {
                stack.push((l, r));
            }
            continue;
        }
        let nb = &t2.nodes[b as usize];
        match (na.is_leaf(), nb.is_leaf()) {
            (true, true) => leaf_task::<SELF, M1, M2>(t1, m1, t2, m2, (a, b), f),
            (true, false) if na.count == 1 => {
                let s = na.first as usize;
                prim_query::<SELF, false, M1, M2>(t1, m1, s, t2, m2, b, &mut qstack, f);
            }
            (false, true) if nb.count == 1 => {
                let s = nb.first as usize;
                prim_query::<SELF, true, M2, M1>(t2, m2, s, t1, m1, a, &mut qstack, f);
            }
            (true, false) => {
                let ma = m1.node(a);
                let (alo, ahi) = node_box(na);
                for c in [nb.right(), b + 1] {
                    let (clo, chi) = node_box(&t2.nodes[c as usize]);
                    if (ma || m2.node(c)) && overlap(alo, ahi, clo, chi) {
                        stack.push((a, c));
                    }
                }
            }
            (false, true) => {
                let mb = m2.node(b);
                let (blo, bhi) = node_box(nb);
                for c in [na.right(), a + 1] {
                    let (clo, chi) = node_box(&t1.nodes[c as usize]);
                    if (mb || m1.node(c)) && overlap(clo, chi, blo, bhi) {
                        stack.push((c, b));
                    }
                }
            }
            (false, false) => {
                let (b0, b1) = (b + 1, nb.right());
                let (b0lo, b0hi) = node_box(&t2.nodes[b0 as usize]);
                let (b1lo, b1hi) = node_box(&t2.nodes[b1 as usize]);
                let (mb0, mb1) = (m2.node(b0), m2.node(b1));
                for c in [na.right(), a + 1] {
                    let (clo, chi) = node_box(&t1.nodes[c as usize]);
                    let mc = m1.node(c);
                    if (mc || mb1) && overlap(clo, chi, b1lo, b1hi) {
                        stack.push((c, b1));
                    }
                    if (mc || mb0) && overlap(clo, chi, b0lo, b0hi) {
                        stack.push((c, b0));
                    }
                }
            }
        }
    }
}

/// Reports the pairs of the primitive in slot `s` of `tp` with the primitives of the subtree
/// `root` of `tq`. `SWAP`: `tp` is the second tree of the walk (pairs are reported first tree
/// first). `qstack` is scratch.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn prim_query<const SELF: bool, const SWAP: bool, MP: Mask, MQ: Mask>(
    tp: &Bvh,
    mp: &MP,
    s: usize,
    tq: &Bvh,
    mq: &MQ,
    root: u32,
    qstack: &mut Vec<u32>,
    f: &mut impl FnMut(u32, u32),
) {
    let (plo, phi) = prim_box(&tp.prim_bounds[s]);
    let ms = mp.slot(s);
    let ip = tp.prim_indices[s];
    let nodes = &tq.nodes;
    let (rlo, rhi) = node_box(&nodes[root as usize]);
    if !overlap(plo, phi, rlo, rhi) {
        return;
    }
    qstack.clear();
    let mut cur = root as usize;
    loop {
        let node = &nodes[cur];
        if node.is_leaf() {
            for u in node.leaf_range() {
                let (ulo, uhi) = prim_box(&tq.prim_bounds[u]);
                if (ms || mq.slot(u)) && overlap(plo, phi, ulo, uhi) {
                    let iq = tq.prim_indices[u];
                    if SELF {
                        f(ip.min(iq), ip.max(iq));
                    } else if SWAP {
                        f(iq, ip);
                    } else {
                        f(ip, iq);
                    }
                }
            }
        } else {
            let (l, r) = (cur + 1, node.right() as usize);
            let (llo, lhi) = node_box(&nodes[l]);
            let (rlo, rhi) = node_box(&nodes[r]);
            let ol = (ms || mq.node(l as u32)) && overlap(plo, phi, llo, lhi);
            let or = (ms || mq.node(r as u32)) && overlap(plo, phi, rlo, rhi);
            match (ol, or) {
                (true, true) => {
                    qstack.push(r as u32);
                    cur = l;
                    continue;
                }
                (true, false) => {
                    cur = l;
                    continue;
                }
                (false, true) => {
                    cur = r;
                    continue;
                }
                (false, false) => {}
            }
        }
        match qstack.pop() {
            Some(c) => cur = c as usize,
            None => return,
        }
    }
}

/// The child entry `r` (`2 * wide index + side`) of a tree's wide array.
#[inline(always)]
fn ent(w: &[Wide], r: u32) -> &Node {
    &wide_at(w, (r >> 1) as usize).0[(r & 1) as usize]
}

/// Reports the pair of slots `s` (first tree) and `u` (second tree).
#[inline(always)]
fn report<const SELF: bool, const SWAP: bool>(ip: u32, iq: u32, f: &mut impl FnMut(u32, u32)) {
    if SELF {
        f(ip.min(iq), ip.max(iq));
    } else if SWAP {
        f(iq, ip);
    } else {
        f(ip, iq);
    }
}

/// The unmarked pair walk on the wide array (see [`Wide`]): a task is two child entries whose
/// boxes overlap (or an entry against itself in a self walk), and both children of a node are
/// tested from one cache line. A leaf of one primitive has that primitive's box, so two such
/// leaves pushed as overlapping are reported without another test.
fn wwalk<const SELF: bool>(t1: &Bvh, t2: &Bvh, start: Task, f: &mut impl FnMut(u32, u32)) {
    let (w1, w2) = (&t1.wide[..], &t2.wide[..]);
    let mut stack: Vec<Task> = Vec::with_capacity(128);
    let mut qstack: Vec<u32> = Vec::with_capacity(64);
    stack.push(start);
    while let Some((a, b)) = stack.pop() {
        let na = ent(w1, a);
        if SELF && a == b {
            if na.is_leaf() {
                leaf_pairs::<SELF>(t1, na, t2, na, f);
                continue;
            }
            let c = na.first;
            let [l, r] = &wide_at(w1, c as usize).0;
            let (lr, rr) = (2 * c, 2 * c + 1);
            // A leaf of one primitive has no pairs of its own.
            if r.count != 1 {
                stack.push((rr, rr));
            }
            if l.count != 1 {
                stack.push((lr, lr));
            }
            if nodes_overlap(l, r) {
                found::<SELF>(t1, t2, &mut stack, (l, lr), (r, rr), f);
            }
            continue;
        }
        let nb = ent(w2, b);
        match (na.is_leaf(), nb.is_leaf()) {
            (true, true) => {
                if na.count == 1 && nb.count == 1 {
                    let (ip, iq) = (
                        t1.prim_indices[na.first as usize],
                        t2.prim_indices[nb.first as usize],
                    );
                    report::<SELF, false>(ip, iq, f);
                } else {
                    leaf_pairs::<SELF>(t1, na, t2, nb, f);
                }
            }
            (true, false) if na.count == 1 => {
                wprim_query::<SELF, false>(t1, na, t2, nb.first, &mut qstack, f);
            }
            (false, true) if nb.count == 1 => {
                wprim_query::<SELF, true>(t2, nb, t1, na.first, &mut qstack, f);
            }
            (true, false) => {
                let c = nb.first;
                let (alo, ahi) = node_box(na);
                for side in [1, 0] {
                    let e = &wide_at(w2, c as usize).0[side as usize];
                    let (clo, chi) = node_box(e);
                    if overlap(alo, ahi, clo, chi) {
                        found::<SELF>(t1, t2, &mut stack, (na, a), (e, 2 * c + side), f);
                    }
                }
            }
            (false, true) => {
                let c = na.first;
                let (blo, bhi) = node_box(nb);
                for side in [1, 0] {
                    let e = &wide_at(w1, c as usize).0[side as usize];
                    let (clo, chi) = node_box(e);
                    if overlap(clo, chi, blo, bhi) {
                        found::<SELF>(t1, t2, &mut stack, (e, 2 * c + side), (nb, b), f);
                    }
                }
            }
            (false, false) => {
                let (ca, cb) = (na.first, nb.first);
                let [b0, b1] = &wide_at(w2, cb as usize).0;
                let (b0lo, b0hi) = node_box(b0);
                let (b1lo, b1hi) = node_box(b1);
                for side in [1, 0] {
                    let e = &wide_at(w1, ca as usize).0[side as usize];
                    let (clo, chi) = node_box(e);
                    let c = 2 * ca + side;
                    if overlap(clo, chi, b1lo, b1hi) {
                        found::<SELF>(t1, t2, &mut stack, (e, c), (b1, 2 * cb + 1), f);
                    }
                    if overlap(clo, chi, b0lo, b0hi) {
                        found::<SELF>(t1, t2, &mut stack, (e, c), (b0, 2 * cb), f);
                    }
                }
            }
        }
    }
}

/// `true` when the boxes of two nodes (or wide entries) overlap: one mask, one move.
#[inline(always)]
fn entries_overlap(a: &Node, b: &Node) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_and_ps, _mm_cmple_ps, _mm_movemask_ps};
        let (alo, ahi) = node_box(a);
        let (blo, bhi) = node_box(b);
        // SAFETY: SSE is part of the x86_64 baseline.
        unsafe {
            _mm_movemask_ps(_mm_and_ps(
                _mm_cmple_ps(alo.0, bhi.0),
                _mm_cmple_ps(blo.0, ahi.0),
            )) & 7
                == 7
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        nodes_overlap(a, b)
    }
}

/// A hint to start loading the line holding the children of entry `e` (a right child, whose
/// children lie away from its parent's line; left children's follow it) before its tasks are
/// popped. For a leaf the address means nothing, and a prefetch never faults.
#[inline(always)]
fn prefetch_children(w: &[Wide], e: &Node) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
        let p = w.as_ptr().wrapping_add(e.first as usize).cast::<i8>();
        // SAFETY: a prefetch is only a hint: it never faults and never changes memory, whatever
        // the address; SSE is part of the x86_64 baseline.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(p) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (w, e);
}

/// A task of the self walk: two wide entries whose boxes overlap, or one entry twice (its
/// subtree against itself).
type EntryPair<'a> = (&'a Node, &'a Node);

/// The stack of the self walk. Each expansion reserves room for all the tasks it may make,
/// then writes every candidate and keeps it only when it is a task (`len += keep`), so the
/// box tests feed no branch.
struct PairStack<'a> {
    v: Vec<EntryPair<'a>>,
}

impl<'a> PairStack<'a> {
    /// Pushes the candidates `t[i]` for which `keep[i]`.
    #[inline(always)]
    fn push_if<const N: usize>(&mut self, t: [EntryPair<'a>; N], keep: [bool; N]) {
        self.v.reserve(N);
        let mut len = self.v.len();
        let p = self.v.as_mut_ptr();
        for i in 0..N {
            // SAFETY: `reserve(N)` made room for `N` more tasks past the original length, and
            // `len` grows by at most one per write; tasks are `Copy` (nothing to drop).
            unsafe { p.add(len).write(t[i]) };
            len += keep[i] as usize;
        }
        // SAFETY: the first `len` slots are initialised (see above) and within capacity.
        unsafe { self.v.set_len(len) };
    }
}

/// The unmarked self walk of [`Bvh::par_self_pairs`] from task `start` (`(root, root)` for the
/// whole tree; see [`EntryPair`]): the tasks of [`wwalk`] for one tree, held as references to their two entries (nothing to look
/// up on a pop), and pushed without branches (see [`PairStack`]). Two one-primitive leaves
/// found overlapping are pushed like any task and reported when popped.
fn self_walk<'a>(t: &'a Bvh, start: EntryPair<'a>, f: &mut impl FnMut(u32, u32)) {
    let w = &t.wide[..];
    let mut stack = PairStack {
        v: Vec::with_capacity(256),
    };
    let mut qstack: Vec<u32> = Vec::with_capacity(64);
    stack.v.push(start);
    while let Some((a, b)) = stack.v.pop() {
        if std::ptr::eq(a, b) {
            if a.is_leaf() {
                leaf_pairs::<true>(t, a, t, a, f);
                continue;
            }
            let [l, r] = &wide_at(w, a.first as usize).0;
            prefetch_children(w, r);
            // A leaf of one primitive has no pairs of its own.
            stack.push_if(
                [(r, r), (l, l), (l, r)],
                [r.count != 1, l.count != 1, entries_overlap(l, r)],
            );
            continue;
        }
        match (a.count, b.count) {
            (0, 0) => {
                let [a0, a1] = &wide_at(w, a.first as usize).0;
                let [b0, b1] = &wide_at(w, b.first as usize).0;
                prefetch_children(w, a1);
                prefetch_children(w, b1);
                stack.push_if(
                    [(a1, b1), (a1, b0), (a0, b1), (a0, b0)],
                    [
                        entries_overlap(a1, b1),
                        entries_overlap(a1, b0),
                        entries_overlap(a0, b1),
                        entries_overlap(a0, b0),
                    ],
                );
            }
            (1, 1) => {
                // One-primitive leaves have their primitive's box, seen to overlap.
                let (ip, iq) = (
                    t.prim_indices[a.first as usize],
                    t.prim_indices[b.first as usize],
                );
                report::<true, false>(ip, iq, f);
            }
            (1, 0) => wprim_query::<true, false>(t, a, t, b.first, &mut qstack, f),
            (0, 1) => wprim_query::<true, false>(t, b, t, a.first, &mut qstack, f),
            (_, 0) => {
                let [b0, b1] = &wide_at(w, b.first as usize).0;
                stack.push_if(
                    [(a, b1), (a, b0)],
                    [entries_overlap(a, b1), entries_overlap(a, b0)],
                );
            }
            (0, _) => {
                let [a0, a1] = &wide_at(w, a.first as usize).0;
                stack.push_if(
                    [(a1, b), (a0, b)],
                    [entries_overlap(a1, b), entries_overlap(a0, b)],
                );
            }
            _ => leaf_pairs::<true>(t, a, t, b, f),
        }
    }
}

/// Two overlapping entries found by the walk: reported at once when both are leaves of one
/// primitive (whose boxes are those primitives' boxes), else pushed as a task.
#[inline(always)]
fn found<const SELF: bool>(
    t1: &Bvh,
    t2: &Bvh,
    stack: &mut Vec<Task>,
    (ea, ra): (&Node, u32),
    (eb, rb): (&Node, u32),
    f: &mut impl FnMut(u32, u32),
) {
    if ea.count == 1 && eb.count == 1 {
        let (ip, iq) = (
            t1.prim_indices[ea.first as usize],
            t2.prim_indices[eb.first as usize],
        );
        report::<SELF, false>(ip, iq, f);
    } else {
        stack.push((ra, rb));
    }
}

/// Pairs of two leaves whose boxes overlap (in a self walk, `na` and `nb` the same leaf means
/// the pairs within it).
#[inline(always)]
fn leaf_pairs<const SELF: bool>(
    t1: &Bvh,
    na: &Node,
    t2: &Bvh,
    nb: &Node,
    f: &mut impl FnMut(u32, u32),
) {
    let same = SELF && std::ptr::eq(na, nb);
    for s in na.leaf_range() {
        let (plo, phi) = prim_box(&t1.prim_bounds[s]);
        let us = if same {
            s + 1..nb.leaf_range().end
        } else {
            nb.leaf_range()
        };
        for u in us {
            let (ulo, uhi) = prim_box(&t2.prim_bounds[u]);
            if overlap(plo, phi, ulo, uhi) {
                report::<SELF, false>(t1.prim_indices[s], t2.prim_indices[u], f);
            }
        }
    }
}

/// Reports the pairs of the one-primitive leaf `leaf` of `tp` with the primitives under wide
/// node `root` of `tq` (whose parent entry the leaf overlaps). `SWAP`: `tp` is the second tree
/// of the walk. `qstack` is scratch.
#[inline(always)]
fn wprim_query<const SELF: bool, const SWAP: bool>(
    tp: &Bvh,
    leaf: &Node,
    tq: &Bvh,
    root: u32,
    qstack: &mut Vec<u32>,
    f: &mut impl FnMut(u32, u32),
) {
    let (plo, phi) = node_box(leaf);
    let ip = tp.prim_indices[leaf.first as usize];
    let wide = &tq.wide[..];
    qstack.clear();
    let mut cur = root as usize;
    loop {
        let [l, r] = &wide_at(wide, cur).0;
        let (llo, lhi) = node_box(l);
        let (rlo, rhi) = node_box(r);
        let ol = overlap(plo, phi, llo, lhi);
        let or = overlap(plo, phi, rlo, rhi);
        let mut next = None;
        for (o, c) in [(ol, l), (or, r)] {
            if !o {
                continue;
            }
            if !c.is_leaf() {
                if let Some(n) = next.replace(c.first) {
                    qstack.push(n);
                }
            } else if c.count == 1 {
                report::<SELF, SWAP>(ip, tq.prim_indices[c.first as usize], f);
            } else {
                for u in c.leaf_range() {
                    let (ulo, uhi) = prim_box(&tq.prim_bounds[u]);
                    if overlap(plo, phi, ulo, uhi) {
                        report::<SELF, SWAP>(ip, tq.prim_indices[u], f);
                    }
                }
            }
        }
        match next.or_else(|| qstack.pop()) {
            Some(c) => cur = c as usize,
            None => return,
        }
    }
}

/// The tasks of the self walk of `t` (not empty) expanded breadth first from the root until
/// there are at least `target` (fewer when the tree runs out of nodes): each task is expanded
/// as [`self_walk`] would, except that a one-primitive leaf against a subtree splits the
/// subtree like any other leaf (the same pairs). Depends only on the tree.
fn split_self_tasks(t: &Bvh, target: usize) -> Vec<EntryPair<'_>> {
    let w = &t.wide[..];
    let root = &w[0].0[0];
    let mut tasks = vec![(root, root)];
    while tasks.len() < target {
        let mut next = Vec::with_capacity(tasks.len() * 4);
        let mut grew = false;
        for &(a, b) in &tasks {
            if std::ptr::eq(a, b) {
                if a.is_leaf() {
                    next.push((a, b));
                    continue;
                }
                let [l, r] = &wide_at(w, a.first as usize).0;
                if r.count != 1 {
                    next.push((r, r));
                }
                if l.count != 1 {
                    next.push((l, l));
                }
                if entries_overlap(l, r) {
                    next.push((l, r));
                }
                grew = true;
                continue;
            }
            match (a.is_leaf(), b.is_leaf()) {
                (true, true) => next.push((a, b)),
                (false, false) => {
                    let [a0, a1] = &wide_at(w, a.first as usize).0;
                    let [b0, b1] = &wide_at(w, b.first as usize).0;
                    for (x, y) in [(a1, b1), (a1, b0), (a0, b1), (a0, b0)] {
                        if entries_overlap(x, y) {
                            next.push((x, y));
                        }
                    }
                    grew = true;
                }
                (true, false) => {
                    let [b0, b1] = &wide_at(w, b.first as usize).0;
                    for y in [b1, b0] {
                        if entries_overlap(a, y) {
                            next.push((a, y));
                        }
                    }
                    grew = true;
                }
                (false, true) => {
                    let [a0, a1] = &wide_at(w, a.first as usize).0;
                    for x in [a1, a0] {
                        if entries_overlap(x, b) {
                            next.push((x, b));
                        }
                    }
                    grew = true;
                }
            }
        }
        tasks = next;
        if !grew {
            break;
        }
    }
    tasks
}

/// [`Bvh::par_self_pairs`] of a non-empty tree: the tasks of [`split_self_tasks`], each walked
/// by [`self_walk`] (on rayon when the pool has more than one thread), results concatenated in
/// task order.
fn par_self_walk(t: &Bvh) -> Vec<(u32, u32)> {
    let tasks = split_self_tasks(t, PARALLEL_TASKS);
    if rayon::current_num_threads() == 1 {
        // Same tasks in the same order, without the cost of rayon's collection.
        let mut out = Vec::with_capacity(t.len());
        for &task in &tasks {
            self_walk(t, task, &mut |a, b| out.push((a, b)));
        }
        return out;
    }
    let parts: Vec<Vec<(u32, u32)>> = tasks
        .par_iter()
        .map(|&task| {
            let mut v = Vec::new();
            self_walk(t, task, &mut |a, b| v.push((a, b)));
            v
        })
        .collect();
    let mut out = Vec::with_capacity(parts.iter().map(Vec::len).sum());
    for p in parts {
        out.extend_from_slice(&p);
    }
    out
}

/// Breadth-first expansion of `start` into at least `target` tasks (fewer when the trees run
/// out of nodes). Depends only on the trees.
fn split_tasks<const SELF: bool, M1: Mask, M2: Mask>(
    t1: &Bvh,
    m1: &M1,
    t2: &Bvh,
    m2: &M2,
    start: Task,
    target: usize,
) -> Vec<Task> {
    let mut tasks = vec![start];
    loop {
        if tasks.len() >= target {
            return tasks;
        }
        let mut next = Vec::with_capacity(tasks.len() * 3);
        let mut grew = false;
        for &t in &tasks {
            if expand::<SELF, M1, M2>(t1, m1, t2, m2, t, |c| next.push(c)) {
                grew = true;
            } else {
                next.push(t);
            }
        }
        tasks = next;
        if !grew {
            return tasks;
        }
    }
}

fn par_walk<const SELF: bool, M1: Mask, M2: Mask>(
    t1: &Bvh,
    m1: &M1,
    t2: &Bvh,
    m2: &M2,
    start: Task,
) -> Vec<(u32, u32)> {
    let tasks = split_tasks::<SELF, M1, M2>(t1, m1, t2, m2, start, PARALLEL_TASKS);
    if rayon::current_num_threads() == 1 {
        // Same tasks in the same order, without the cost of rayon's collection.
        let mut out = Vec::new();
        for &t in &tasks {
            walk::<SELF, M1, M2>(t1, m1, t2, m2, t, &mut |a, b| out.push((a, b)));
        }
        return out;
    }
    let parts: Vec<Vec<(u32, u32)>> = tasks
        .par_iter()
        .map(|&t| {
            let mut v = Vec::new();
            walk::<SELF, M1, M2>(t1, m1, t2, m2, t, &mut |a, b| v.push((a, b)));
            v
        })
        .collect();
    let mut out = Vec::with_capacity(parts.iter().map(Vec::len).sum());
    for p in parts {
        out.extend_from_slice(&p);
    }
    out
}

impl Bvh {
    /// Calls `f(a, b)` once for every pair of primitives whose boxes overlap, with `a < b`.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let boxes: Vec<Aabb> = (0..10)
    ///     .map(|i| Aabb::from_arrays([i as f32; 3], [i as f32 + 1.0; 3]))
    ///     .collect();
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let mut pairs = Vec::new();
    /// bvh.self_pairs(|a, b| pairs.push((a, b)));
    /// pairs.sort();
    /// assert_eq!(pairs, (0..9).map(|i| (i, i + 1)).collect::<Vec<_>>());
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn self_pairs(&self, f: impl FnMut(u32, u32)) {
        if !self.nodes.is_empty() {
            super::pairs4::self_pairs4(self, f);
        }
    }

    /// The pairs of [`Bvh::self_pairs`], found in parallel on the current rayon pool. The order
    /// of the result depends only on the tree, so one thread and many give the same `Vec`.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let boxes: Vec<Aabb> = (0..1000)
    ///     .map(|i| Aabb::from_arrays([(i % 97) as f32; 3], [(i % 97) as f32 + 1.5; 3]))
    ///     .collect();
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let mut serial = Vec::new();
    /// bvh.self_pairs(|a, b| serial.push((a, b)));
    /// let mut parallel = bvh.par_self_pairs();
    /// serial.sort();
    /// parallel.sort();
    /// assert_eq!(serial, parallel);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn par_self_pairs(&self) -> Vec<(u32, u32)> {
        if self.wide.is_empty() {
            return Vec::new();
        }
        par_self_walk(self)
    }

    /// Calls `f(a, b)` for every primitive `a` of `self` and `b` of `other` whose boxes
    /// overlap.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let a = [Aabb::from_arrays([0.0; 3], [1.0; 3]), Aabb::from_arrays([5.0; 3], [6.0; 3])];
    /// let b = [Aabb::from_arrays([5.5; 3], [7.0; 3])];
    /// let (ta, tb) = (Bvh::build(&a, BuildOptions::default())?, Bvh::build(&b, BuildOptions::default())?);
    /// let mut pairs = Vec::new();
    /// ta.pairs_with(&tb, |i, j| pairs.push((i, j)));
    /// assert_eq!(pairs, [(1, 0)]);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn pairs_with(&self, other: &Bvh, mut f: impl FnMut(u32, u32)) {
        if let Some(start) = self.root_task(other) {
            wwalk::<false>(self, other, start, &mut f);
        }
    }

    /// The pairs of [`Bvh::pairs_with`] as `(self primitive, other primitive)`, found in
    /// parallel; the order depends only on the two trees.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let a: Vec<Aabb> = (0..50).map(|i| Aabb::from_arrays([i as f32; 3], [i as f32 + 0.5; 3])).collect();
    /// let b = [Aabb::from_arrays([10.2; 3], [12.2; 3])];
    /// let (ta, tb) = (Bvh::build(&a, BuildOptions::default())?, Bvh::build(&b, BuildOptions::default())?);
    /// let mut pairs = ta.par_pairs_with(&tb);
    /// pairs.sort();
    /// assert_eq!(pairs, [(10, 0), (11, 0), (12, 0)]);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn par_pairs_with(&self, other: &Bvh) -> Vec<(u32, u32)> {
        match self.root_task(other) {
            Some(start) => par_walk::<false, All, All>(self, &All, other, &All, start),
            None => Vec::new(),
        }
    }

    /// Marks primitives for the `_marked` pair queries: `marked(i)` says whether primitive `i`
    /// takes part. One pass over the primitives and one over the nodes.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let boxes: Vec<Aabb> = (0..8).map(|i| Aabb::from_arrays([i as f32; 3], [i as f32 + 1.0; 3])).collect();
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let marks = bvh.marks(|i| i == 3);
    /// let mut pairs = Vec::new();
    /// bvh.self_pairs_marked(&marks, |a, b| pairs.push((a, b)));
    /// pairs.sort();
    /// assert_eq!(pairs, [(2, 3), (3, 4)]);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn marks(&self, marked: impl Fn(u32) -> bool) -> PairMarks {
        let slots: Vec<bool> = self.prim_indices.iter().map(|&p| marked(p)).collect();
        let mut nodes = vec![false; self.nodes.len()];
        for i in (0..self.nodes.len()).rev() {
            let n = &self.nodes[i];
            nodes[i] = if n.is_leaf() {
                slots[n.leaf_range()].iter().any(|&m| m)
            } else {
                nodes[i + 1] || nodes[n.right() as usize]
            };
        }
        let any = nodes.first().copied().unwrap_or(false);
        PairMarks { nodes, slots, any }
    }

    /// `marks` when it was made for this tree, else `None` (callers then treat all as marked).
    fn checked_marks<'a>(&self, marks: &'a PairMarks) -> Option<&'a PairMarks> {
        (marks.nodes.len() == self.nodes.len() && marks.slots.len() == self.len()).then_some(marks)
    }

    /// [`Bvh::self_pairs`] restricted to pairs with at least one marked primitive.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let boxes: Vec<Aabb> = (0..20).map(|i| Aabb::from_arrays([i as f32; 3], [i as f32 + 1.0; 3])).collect();
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let marks = bvh.marks(|i| i == 0 || i == 10);
    /// let mut pairs = Vec::new();
    /// bvh.self_pairs_marked(&marks, |a, b| pairs.push((a, b)));
    /// pairs.sort();
    /// assert_eq!(pairs, [(0, 1), (9, 10), (10, 11)]);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn self_pairs_marked(&self, marks: &PairMarks, mut f: impl FnMut(u32, u32)) {
        if self.nodes.is_empty() {
            return;
        }
        match self.checked_marks(marks) {
            Some(m) if m.any => walk::<true, _, _>(self, m, self, m, (0, 0), &mut f),
            Some(_) => {}
            // All marked: the walk (and order) of the plain query before it had its own.
            None => wwalk::<true>(self, self, (0, 0), &mut f),
        }
    }

    /// [`Bvh::par_self_pairs`] restricted to pairs with at least one marked primitive; the
    /// order depends only on the tree and the marks.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let boxes: Vec<Aabb> = (0..20).map(|i| Aabb::from_arrays([i as f32; 3], [i as f32 + 1.0; 3])).collect();
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let mut pairs = bvh.par_self_pairs_marked(&bvh.marks(|i| i == 19));
    /// pairs.sort();
    /// assert_eq!(pairs, [(18, 19)]);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn par_self_pairs_marked(&self, marks: &PairMarks) -> Vec<(u32, u32)> {
        if self.nodes.is_empty() {
            return Vec::new();
        }
        match self.checked_marks(marks) {
            Some(m) if m.any => par_walk::<true, _, _>(self, m, self, m, (0, 0)),
            Some(_) => Vec::new(),
            // All marked: the walk (and order) of the plain query before it had its own.
            None => par_walk::<true, All, All>(self, &All, self, &All, (0, 0)),
        }
    }

    /// [`Bvh::pairs_with`] restricted to pairs where the primitive of `self` is marked in
    /// `marks` or the primitive of `other` is marked in `other_marks`.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let a: Vec<Aabb> = (0..10).map(|i| Aabb::from_arrays([i as f32; 3], [i as f32 + 0.5; 3])).collect();
    /// let b: Vec<Aabb> = (0..10).map(|i| Aabb::from_arrays([i as f32 + 0.25; 3], [i as f32 + 0.75; 3])).collect();
    /// let (ta, tb) = (Bvh::build(&a, BuildOptions::default())?, Bvh::build(&b, BuildOptions::default())?);
    /// let (ma, mb) = (ta.marks(|i| i == 3), tb.marks(|j| j == 7));
    /// let mut pairs = Vec::new();
    /// ta.pairs_with_marked(&ma, &tb, &mb, |i, j| pairs.push((i, j)));
    /// pairs.sort();
    /// assert_eq!(pairs, [(3, 3), (7, 7)]);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn pairs_with_marked(
        &self,
        marks: &PairMarks,
        other: &Bvh,
        other_marks: &PairMarks,
        mut f: impl FnMut(u32, u32),
    ) {
        let Some(start) = self.root_task(other) else {
            return;
        };
        match (self.checked_marks(marks), other.checked_marks(other_marks)) {
            (Some(m1), Some(m2)) if m1.any || m2.any => {
                walk::<false, _, _>(self, m1, other, m2, start, &mut f)
            }
            (Some(_), Some(_)) => {}
            _ => self.pairs_with(other, f),
        }
    }

    /// [`Bvh::pairs_with_marked`], found in parallel; the order depends only on the trees and
    /// the marks.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions};
    /// let a: Vec<Aabb> = (0..10).map(|i| Aabb::from_arrays([i as f32; 3], [i as f32 + 0.5; 3])).collect();
    /// let (ta, tb) = (Bvh::build(&a, BuildOptions::default())?, Bvh::build(&a, BuildOptions::default())?);
    /// let pairs = ta.par_pairs_with_marked(&ta.marks(|i| i == 4), &tb, &tb.marks(|_| false));
    /// assert_eq!(pairs, [(4, 4)]);
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn par_pairs_with_marked(
        &self,
        marks: &PairMarks,
        other: &Bvh,
        other_marks: &PairMarks,
    ) -> Vec<(u32, u32)> {
        let Some(start) = self.root_task(other) else {
            return Vec::new();
        };
        match (self.checked_marks(marks), other.checked_marks(other_marks)) {
            (Some(m1), Some(m2)) if m1.any || m2.any => {
                par_walk::<false, _, _>(self, m1, other, m2, start)
            }
            (Some(_), Some(_)) => Vec::new(),
            _ => self.par_pairs_with(other),
        }
    }

    fn root_task(&self, other: &Bvh) -> Option<Task> {
        let (a, b) = (self.nodes.first()?, other.nodes.first()?);
        nodes_overlap(a, b).then_some((0, 0))
    }
}
