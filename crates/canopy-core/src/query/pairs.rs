//! Overlapping pairs: every pair of primitives whose boxes overlap within one tree (each pair
//! once), or between two trees; serial with a callback, and rayon-parallel into a `Vec` whose
//! order depends only on the trees, never on the thread count.
//!
//! Both walk the bounding volume test tree with an explicit stack of node pairs: a node against
//! itself expands to its two children against themselves and against each other; two different
//! nodes, when their boxes overlap, expand the larger one. The parallel versions first expand
//! the root task breadth-first into a fixed number of independent tasks, run those on rayon, and
//! concatenate the results in task order.

use crate::aabb::overlaps;
use crate::bvh::{Bvh, Node};
use rayon::prelude::*;

/// The parallel pair queries split the work into at least this many tasks (a fixed number, so
/// the output order does not depend on the thread count).
const PARALLEL_TASKS: usize = 256;

#[inline(always)]
fn nodes_overlap(a: &Node, b: &Node) -> bool {
    overlaps(&a.min, &a.max, &b.min, &b.max)
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

/// A pair-walk task: node `a` of the first tree against node `b` of the second. In a self walk
/// (`SELF = true`, both trees the same) `a == b` means "the subtree against itself".
type Task = (u32, u32);

/// Expands one task into the tasks it generates, or returns `false` when it is a leaf task
/// (`a` and `b` leaves, or a leaf against itself) to be handled by `leaf_task`.
#[inline(always)]
fn expand<const SELF: bool>(t1: &Bvh, t2: &Bvh, (a, b): Task, mut push: impl FnMut(Task)) -> bool {
    let na = &t1.nodes[a as usize];
    if SELF && a == b {
        if na.is_leaf() {
            return false;
        }
        let (l, r) = (a + 1, na.right());
        if nodes_overlap(&t1.nodes[l as usize], &t1.nodes[r as usize]) {
            push((l, r));
        }
        push((r, r));
        push((l, l));
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
        for c in [na.right(), a + 1] {
            if nodes_overlap(&t1.nodes[c as usize], nb) {
                push((c, b));
            }
        }
    } else {
        for c in [nb.right(), b + 1] {
            if nodes_overlap(na, &t2.nodes[c as usize]) {
                push((a, c));
            }
        }
    }
    true
}

/// Reports the overlapping primitive pairs of a leaf task.
#[inline(always)]
fn leaf_task<const SELF: bool>(t1: &Bvh, t2: &Bvh, (a, b): Task, f: &mut impl FnMut(u32, u32)) {
    let na = &t1.nodes[a as usize];
    if SELF && a == b {
        let r = na.leaf_range();
        for s in r.clone() {
            let ps = &t1.prim_bounds[s];
            for u in s + 1..r.end {
                let pu = &t1.prim_bounds[u];
                if overlaps(&ps.min, &ps.max, &pu.min, &pu.max) {
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
        for u in nb.leaf_range() {
            let pu = &t2.prim_bounds[u];
            if overlaps(&ps.min, &ps.max, &pu.min, &pu.max) {
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

fn walk<const SELF: bool>(t1: &Bvh, t2: &Bvh, start: Task, f: &mut impl FnMut(u32, u32)) {
    let mut stack: Vec<Task> = Vec::with_capacity(128);
    stack.push(start);
    while let Some(t) = stack.pop() {
        if !expand::<SELF>(t1, t2, t, |c| stack.push(c)) {
            leaf_task::<SELF>(t1, t2, t, f);
        }
    }
}

/// Breadth-first expansion of `start` into at least `target` tasks (fewer when the trees run
/// out of nodes). Depends only on the trees.
fn split_tasks<const SELF: bool>(t1: &Bvh, t2: &Bvh, start: Task, target: usize) -> Vec<Task> {
    let mut tasks = vec![start];
    loop {
        if tasks.len() >= target {
            return tasks;
        }
        let mut next = Vec::with_capacity(tasks.len() * 3);
        let mut grew = false;
        for &t in &tasks {
            if expand::<SELF>(t1, t2, t, |c| next.push(c)) {
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

fn par_walk<const SELF: bool>(t1: &Bvh, t2: &Bvh, start: Task) -> Vec<(u32, u32)> {
    let tasks = split_tasks::<SELF>(t1, t2, start, PARALLEL_TASKS);
    let parts: Vec<Vec<(u32, u32)>> = tasks
        .par_iter()
        .map(|&t| {
            let mut v = Vec::new();
            walk::<SELF>(t1, t2, t, &mut |a, b| v.push((a, b)));
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
    pub fn self_pairs(&self, mut f: impl FnMut(u32, u32)) {
        if !self.nodes.is_empty() {
            walk::<true>(self, self, (0, 0), &mut f);
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
        par_walk::<true>(self, self, (0, 0))
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
            walk::<false>(self, other, start, &mut f);
        }
    }

    /// The pairs of [`Bvh::pairs_with`] as `(self primitive, other primitive)`, found in
    /// parallel; the order depends only on the two trees.
    pub fn par_pairs_with(&self, other: &Bvh) -> Vec<(u32, u32)> {
        match self.root_task(other) {
            Some(start) => par_walk::<false>(self, other, start),
            None => Vec::new(),
        }
    }

    fn root_task(&self, other: &Bvh) -> Option<Task> {
        let (a, b) = (self.nodes.first()?, other.nodes.first()?);
        nodes_overlap(a, b).then_some((0, 0))
    }
}
