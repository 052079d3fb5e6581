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
//! The self queries, plain and marked ([`Bvh::self_pairs`], [`Bvh::par_self_pairs`],
//! [`Bvh::self_pairs_marked`], [`Bvh::par_self_pairs_marked`]), walk the four-wide copy of the
//! tree instead (see `pairs4.rs`; the parallel ones cut the nodes into a fixed number of
//! ranges). The serial unmarked tree-vs-tree walk (also taken by the marked self query when its
//! marks were made for another tree) runs on the tree's wide array (both children of a node in
//! one cache line); the others on the nodes.
//!
//! The `_marked` variants report only pairs with at least one *marked* primitive (a broadphase
//! marks the proxies that moved). [`PairMarks`] summarises the marks per node (and per lane of
//! the four-wide copy), so whole subtrees without a marked primitive are skipped: one pass finds
//! every new pair of every moved proxy, cheaper than one query per proxy once many moved.

use super::pairs4::{AllMarked, Marked};
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
/// [`Bvh::marks`] for one tree, valid for that tree and its clones until it is rebuilt (refit
/// keeps it valid). Marks made for another tree, even one of the same size, are treated as
/// "everything marked": never a missed pair.
#[derive(Clone, Debug, Default)]
pub struct PairMarks {
    /// The stamp of the build they were made for (`Bvh::stamp`).
    stamp: u64,
    nodes: Vec<bool>,
    slots: Vec<bool>,
    /// Per node of the tree's four-wide copy, the lanes with a marked primitive under them.
    lanes: Vec<u8>,
    any: bool,
}

impl PairMarks {
    /// `true` when at least one primitive is marked.
    pub fn any(&self) -> bool {
        self.any
    }

    /// The marks as the four-wide walk reads them (valid for the tree they were made for).
    pub(crate) fn lane_view(&self) -> Marked<'_> {
        Marked {
            lanes: &self.lanes,
            slots: &self.slots,
        }
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
    let (w1, w2) = (t1.wide(), t2.wide());
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
    let wide = tq.wide();
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
    /// The walk runs on the tree's four-wide copy, which the first such query (or ray cast)
    /// after a build makes and keeps (refits update it): that first call costs one to two
    /// walks more.
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
            super::pairs4::self_pairs4(self, &AllMarked, f);
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
        if self.nodes.is_empty() {
            return Vec::new();
        }
        super::pairs4::par_self_pairs4(self, &AllMarked, PARALLEL_TASKS)
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
        let lanes = if self.nodes.is_empty() {
            Vec::new()
        } else {
            super::pairs4::lane_marks(self, &slots, marked)
        };
        PairMarks {
            stamp: self.stamp,
            nodes,
            slots,
            lanes,
            any,
        }
    }

    /// `marks` when it was made for this tree, else `None` (callers then treat all as marked).
    /// Marks made for a tree also made its four-wide copy, so a tree without one gets `None`
    /// rather than a copy built only for this check.
    fn checked_marks<'a>(&self, marks: &'a PairMarks) -> Option<&'a PairMarks> {
        (marks.stamp == self.stamp
            && marks.nodes.len() == self.nodes.len()
            && marks.slots.len() == self.len()
            && (self.nodes.is_empty()
                || self
                    .ray4
                    .get()
                    .is_some_and(|r4| r4.nodes.len() == marks.lanes.len())))
        .then_some(marks)
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
            Some(m) if m.any => super::pairs4::self_pairs4(self, &m.lane_view(), f),
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
            Some(m) if m.any => {
                super::pairs4::par_self_pairs4(self, &m.lane_view(), PARALLEL_TASKS)
            }
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
