//! Ray casts: closest hit and any hit, on a four-wide copy of the tree (`Ray4`: the binary
//! tree with every other level folded into its parent, so a ray meets half as many dependent
//! cache misses on its way down). The four children of a node are slab-tested together and
//! entered near first; subtrees entered beyond the best time so far are skipped. What a visit
//! will read is prefetched as soon as it is known (in a tree larger than the caches, all interior
//! children as their node is reached). The caller's callback decides the exact primitive test;
//! the stored primitive boxes cull first.

use super::{prefetch, Stack};
use crate::build::f4::F4;
use crate::bvh::{Bvh, Node};
use crate::ray::Ray;

/// A ray hit: which primitive, at what time (`ray.origin + t * ray.dir`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Primitive index.
    pub primitive: u32,
    /// Time of impact.
    pub t: f32,
}

impl Bvh {
    /// The closest hit along `ray` within `[0, t_max]`.
    ///
    /// `hit(primitive, best_t)` is called for primitives whose box the ray enters before
    /// `best_t` (the closest time found so far, or `t_max`); it returns the exact time of impact
    /// with that primitive, or `None` for a miss. Its time must not be before the ray enters the
    /// primitive's box. Hits later than `best_t` are ignored; ties keep the first found. Nothing
    /// is hit by a ray with a NaN or infinite origin or direction, nor with a NaN or negative
    /// `t_max`.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions, Ray};
    /// use nalgebra::{Point3, Vector3};
    /// let boxes: Vec<Aabb> = (0..10)
    ///     .map(|i| Aabb::from_arrays([i as f32 * 2.0, 0.0, 0.0], [i as f32 * 2.0 + 1.0, 1.0, 1.0]))
    ///     .collect();
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let ray = Ray::new(Point3::new(-5.0, 0.5, 0.5), Vector3::x());
    /// // The exact test here is the box itself.
    /// let hit = bvh.cast_ray(&ray, 100.0, |i, t_max| ray.intersect_aabb(&boxes[i as usize], t_max));
    /// assert_eq!(hit.map(|h| (h.primitive, h.t)), Some((0, 5.0)));
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn cast_ray(
        &self,
        ray: &Ray,
        t_max: f32,
        hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<RayHit> {
        self.traverse_ray::<false>(ray, t_max, hit)
    }

    /// Any hit along `ray` within `[0, t_max]`: stops at the first primitive for which `hit`
    /// (as in [`Bvh::cast_ray`]) reports a time of impact. Use it for shadow and
    /// line-of-sight rays.
    ///
    /// ```
    /// use canopy_core::{Aabb, Bvh, BuildOptions, Ray};
    /// use nalgebra::{Point3, Vector3};
    /// let boxes = [Aabb::from_arrays([1.0; 3], [2.0; 3])];
    /// let bvh = Bvh::build(&boxes, BuildOptions::default())?;
    /// let ray = Ray::new(Point3::origin(), Vector3::new(1.0, 1.0, 1.0));
    /// let test = |i: u32, t: f32| ray.intersect_aabb(&boxes[i as usize], t);
    /// assert!(bvh.cast_ray_any(&ray, 10.0, test).is_some());
    /// assert!(bvh.cast_ray_any(&ray, 0.5, test).is_none());
    /// # Ok::<(), canopy_core::BvhError>(())
    /// ```
    pub fn cast_ray_any(
        &self,
        ray: &Ray,
        t_max: f32,
        hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<RayHit> {
        self.traverse_ray::<true>(ray, t_max, hit)
    }

    fn traverse_ray<const ANY: bool>(
        &self,
        ray: &Ray,
        t_max: f32,
        mut hit: impl FnMut(u32, f32) -> Option<f32>,
    ) -> Option<RayHit> {
        let root = self.nodes.first()?;
        if t_max.is_nan() || t_max < 0.0 || !ray.is_finite() {
            return None;
        }
        ray.slab(&root.min, &root.max, t_max)?;
        let r4 = self.four_wide();
        let slab = SignedSlab4::new(ray);
        let eager = r4.nodes.len() * std::mem::size_of::<Node4>() > EAGER_PREFETCH_BYTES;
        let mut best: Option<RayHit> = None;
        let mut best_t = t_max;
        let mut stack: Stack<Entry> = Stack::new();
        // What to visit next: the root node first.
        let mut cur = Entry {
            first: 0,
            meta: INTERIOR,
            t: 0.0,
        };
        'walk: loop {
            if cur.meta == INTERIOR {
                let n = r4.at(cur.first as usize);
                if eager {
                    r4.prefetch_children(n);
                }
                let (entries, mut bits) = slab.entries(n, best_t);
                if bits != 0 {
                    // The hit children, nearest first (insertion sort of at most four).
                    let mut hits = [cur; 4];
                    let mut len = 0;
                    while bits != 0 {
                        let lane = bits.trailing_zeros() as usize;
                        bits &= bits - 1;
                        let e = Entry {
                            first: n.first[lane],
                            meta: n.meta[lane],
                            t: entries[lane],
                        };
                        // Start loading what visiting it reads now, the nearest one included:
                        // the sort below and the pushes overlap those misses.
                        self.prefetch_entry(r4, &e);
                        let mut j = len;
                        while j > 0 && hits[j - 1].t > e.t {
                            hits[j] = hits[j - 1];
                            j -= 1;
                        }
                        hits[j] = e;
                        len += 1;
                    }
                    // The others go on the stack farthest first.
                    for e in hits[1..len].iter().rev() {
                        stack.push(*e);
                    }
                    cur = hits[0];
                    continue 'walk;
                }
            } else if cur.meta == 1 {
                // A leaf of one primitive has that primitive's box (builders and refit make
                // leaf boxes from their primitives), which the ray was just seen to enter
                // before `best_t`: no second slab test. Its lane holds the primitive index
                // itself, so the callback comes without another dependent load.
                let prim = cur.first;
                if let Some(t) = hit(prim, best_t) {
                    if take_hit(&mut best, &mut best_t, prim, t) && ANY {
                        return best;
                    }
                }
            } else {
                // Primitives in the order the ray enters their boxes, so that the nearest hit
                // comes first and the primitives behind it are skipped (the exact test is
                // usually the expensive part). Leaves larger than `SORTED_LEAF` are taken in
                // storage order.
                let range = cur.first as usize..cur.first as usize + cur.meta as usize;
                let mut order = [(0.0f32, 0u32); SORTED_LEAF];
                let mut len = 0;
                let sort = range.len() <= SORTED_LEAF;
                for slot in range {
                    let b = &self.prim_bounds[slot];
                    let Some(entry) = ray.slab(&b.min, &b.max, best_t) else {
                        continue;
                    };
                    if sort {
                        order[len] = (entry, slot as u32);
                        len += 1;
                        continue;
                    }
                    let prim = self.prim_indices[slot];
                    if let Some(t) = hit(prim, best_t) {
                        if take_hit(&mut best, &mut best_t, prim, t) && ANY {
                            return best;
                        }
                    }
                }
                let order = &mut order[..len];
                order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                for &(entry, slot) in order.iter() {
                    if entry > best_t {
                        break;
                    }
                    let prim = self.prim_indices[slot as usize];
                    if let Some(t) = hit(prim, best_t) {
                        if take_hit(&mut best, &mut best_t, prim, t) && ANY {
                            return best;
                        }
                    }
                }
            }
            // Next subtree still worth entering.
            loop {
                let Some(e) = stack.pop() else {
                    return best;
                };
                if e.t <= best_t {
                    cur = e;
                    continue 'walk;
                }
            }
        }
    }

    /// The four-wide copy of this (non-empty) tree, made on first use. Inline: every box query
    /// asks for it, and the answer is one load and one check once it is made.
    #[inline]
    pub(crate) fn four_wide(&self) -> &Ray4 {
        self.ray4
            .get_or_init(|| Ray4::new(&self.nodes, &self.prim_indices))
    }

    /// Starts loading the first lines that visiting `e` reads: its [`Node4`] for an interior
    /// node, its first primitive's box for a leaf of several (a leaf of one reads nothing of
    /// the tree).
    #[inline(always)]
    fn prefetch_entry(&self, r4: &Ray4, e: &Entry) {
        let i = e.first as usize;
        if e.meta == INTERIOR {
            let p = r4.nodes.as_ptr().wrapping_add(i).cast::<u8>();
            prefetch(p);
            prefetch(p.wrapping_add(64));
        } else if e.meta > 1 {
            prefetch(self.prim_bounds.as_ptr().wrapping_add(i));
        }
    }
}

/// Size of the four-wide tree beyond which a visit starts loading all its interior children
/// before the slab test says which ones the ray enters: in a tree larger than a core's caches
/// the walk waits on memory, and the lines of the children it then enters are on their way
/// sooner (the others cost bandwidth, which a single ray leaves spare). In a smaller tree the
/// extra instructions cost more than they save.
const EAGER_PREFETCH_BYTES: usize = 1 << 20;

/// Records `t` as the best hit (with `prim`) when it is within `best_t` and, ties keeping
/// the first found, strictly earlier than the current best; `true` when it did.
#[inline(always)]
fn take_hit(best: &mut Option<RayHit>, best_t: &mut f32, prim: u32, t: f32) -> bool {
    if t <= *best_t && (best.is_none() || t < *best_t) {
        *best_t = t;
        *best = Some(RayHit { primitive: prim, t });
        true
    } else {
        false
    }
}

/// Largest leaf whose primitives are tested in ray-entry order.
const SORTED_LEAF: usize = 8;

/// [`Node4::meta`] of an interior child.
pub(crate) const INTERIOR: u32 = u32::MAX;

/// A child to visit: `first` and `meta` as in [`Node4`], `t` the time the ray enters its box.
#[derive(Clone, Copy, Debug)]
struct Entry {
    first: u32,
    meta: u32,
    t: f32,
}

/// Up to four children of one node, boxes stored by coordinate (lane `i` is child `i`), in two
/// cache lines. `b[a]` holds the smallest and `b[3 + a]` the largest coordinate along axis
/// `a`. A child is either
///
/// * interior: `meta == INTERIOR`, `first` the index of its own `Node4`;
/// * a leaf of one primitive: `meta == 1`, `first` that primitive's index (not its slot);
/// * a larger leaf: `meta` its number of primitives, `first` its first slot (as in [`Node`]);
/// * empty (nodes with fewer than four children): an inverted box (`+inf` smallest, `-inf`
///   largest corner), which no slab test enters, and `meta == 0`, a leaf of no primitive,
///   should it ever be visited.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(128))]
pub(crate) struct Node4 {
    pub(crate) b: [[f32; 4]; 6],
    pub(crate) first: [u32; 4],
    pub(crate) meta: [u32; 4],
}

const _: () = assert!(std::mem::size_of::<Node4>() == 128);

impl Node4 {
    pub(crate) const EMPTY: Node4 = Node4 {
        b: [
            [f32::INFINITY; 4],
            [f32::INFINITY; 4],
            [f32::INFINITY; 4],
            [f32::NEG_INFINITY; 4],
            [f32::NEG_INFINITY; 4],
            [f32::NEG_INFINITY; 4],
        ],
        first: [0; 4],
        meta: [0; 4],
    };

    /// Makes lane `lane` the leaf `n` (see [`Node4`]).
    #[inline]
    fn set_leaf(&mut self, lane: usize, n: &Node, prim_indices: &[u32]) {
        self.first[lane] = if n.count == 1 {
            prim_indices[n.first as usize]
        } else {
            n.first
        };
        self.meta[lane] = n.count;
    }

    #[inline]
    fn set_box(&mut self, lane: usize, n: &Node) {
        for a in 0..3 {
            self.b[a][lane] = n.min[a];
            self.b[3 + a][lane] = n.max[a];
        }
    }
}

/// The four-wide tree of the ray casts (and of the self-pair walk, `pairs4.rs`), made from the
/// binary one: each `Node4` takes the
/// children of one binary interior node, then repeatedly replaces its interior child of largest
/// surface area by that child's two children, up to four (a binary leaf root gives one node
/// with that leaf as its only child). Node 0 is the root; the children of a node are stored
/// next to each other. A leaf lane of one primitive holds the primitive's index, which no refit
/// changes. `src[k][lane]` is the binary node whose box lane `lane` of node `k`
/// copies (`u32::MAX` for an empty lane), for refit; `lane_of[i]` is the inverse, `k * 4 +
/// lane` for binary node `i` (`u32::MAX` for a node opened in place, which no lane copies),
/// for the partial refit.
#[derive(Clone, Debug, Default)]
pub(crate) struct Ray4 {
    pub(crate) nodes: Vec<Node4>,
    src: Vec<[u32; 4]>,
    lane_of: Vec<u32>,
}

impl Ray4 {
    /// The four-wide tree of the depth-first binary `nodes` (not empty), whose leaves index
    /// `prim_indices` (slot to primitive index).
    pub(crate) fn new(nodes: &[Node], prim_indices: &[u32]) -> Self {
        let mut r4 = Self::lanes(nodes, prim_indices);
        r4.lane_of = vec![u32::MAX; nodes.len()];
        for (k, src) in r4.src.iter().enumerate() {
            for (lane, &s) in src.iter().enumerate() {
                if s != u32::MAX {
                    r4.lane_of[s as usize] = (k * 4 + lane) as u32;
                }
            }
        }
        r4
    }

    /// [`Ray4::new`] without `lane_of`.
    fn lanes(nodes: &[Node], prim_indices: &[u32]) -> Self {
        let mut r4 = Ray4 {
            nodes: Vec::with_capacity(nodes.len() / 3 + 1),
            src: Vec::with_capacity(nodes.len() / 3 + 1),
            lane_of: Vec::new(),
        };
        if nodes.is_empty() {
            return r4;
        }
        let half_area = |n: &Node| {
            let e = [0, 1, 2].map(|a| n.max[a] - n.min[a]);
            e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
        };
        // (binary node, its Node4): binary interior nodes whose Node4 is still to fill.
        let mut todo: Vec<(u32, u32)> = Vec::new();
        r4.nodes.push(Node4::EMPTY);
        r4.src.push([u32::MAX; 4]);
        if nodes[0].is_leaf() {
            let (n, s) = (&mut r4.nodes[0], &mut r4.src[0]);
            n.set_box(0, &nodes[0]);
            n.set_leaf(0, &nodes[0], prim_indices);
            s[0] = 0;
            return r4;
        }
        todo.push((0, 0));
        while let Some((bin, k)) = todo.pop() {
            let b = &nodes[bin as usize];
            let mut kids = [bin + 1, b.right(), 0, 0];
            let mut len = 2;
            while len < 4 {
                // The interior child of largest area, opened in place (keeps the order).
                let mut pick = None;
                let mut area = f32::NEG_INFINITY;
                for (j, &c) in kids[..len].iter().enumerate() {
                    let cn = &nodes[c as usize];
                    if !cn.is_leaf() && half_area(cn) > area {
                        area = half_area(cn);
                        pick = Some(j);
                    }
                }
                let Some(j) = pick else { break };
                let c = kids[j];
                kids.copy_within(j + 1..len, j + 2);
                kids[j] = c + 1;
                kids[j + 1] = nodes[c as usize].right();
                len += 1;
            }
            // The interior children's Node4s, side by side.
            let base = r4.nodes.len() as u32;
            let mut next = base;
            let mut n4 = Node4::EMPTY;
            let mut src = [u32::MAX; 4];
            for (lane, &c) in kids[..len].iter().enumerate() {
                let cn = &nodes[c as usize];
                n4.set_box(lane, cn);
                src[lane] = c;
                if cn.is_leaf() {
                    n4.set_leaf(lane, cn, prim_indices);
                } else {
                    n4.first[lane] = next;
                    n4.meta[lane] = INTERIOR;
                    next += 1;
                }
            }
            r4.nodes[k as usize] = n4;
            r4.src[k as usize] = src;
            r4.nodes
                .resize((next - base) as usize + r4.nodes.len(), Node4::EMPTY);
            r4.src
                .resize((next - base) as usize + r4.src.len(), [u32::MAX; 4]);
            // Depth first, first child first: push in reverse.
            for lane in (0..len).rev() {
                if n4.meta[lane] == INTERIOR {
                    todo.push((src[lane], n4.first[lane]));
                }
            }
        }
        r4
    }

    /// Copies the boxes of the binary `nodes` (same topology as when made) into the lanes.
    pub(crate) fn refresh(&mut self, nodes: &[Node]) {
        for (n4, src) in self.nodes.iter_mut().zip(&self.src) {
            for (lane, &s) in src.iter().enumerate() {
                if s != u32::MAX {
                    n4.set_box(lane, &nodes[s as usize]);
                }
            }
        }
    }

    /// Copies the box of binary node `i` (`n`) into the lane that holds it, if any: the
    /// partial refit's update, node by node.
    #[inline(always)]
    pub(crate) fn refresh_node(&mut self, i: usize, n: &Node) {
        let l = self.lane_of[i];
        if l != u32::MAX {
            self.nodes[l as usize / 4].set_box(l as usize % 4, n);
        }
    }

    /// Starts loading the `Node4`s of the interior children of `n`.
    #[inline(always)]
    fn prefetch_children(&self, n: &Node4) {
        for lane in 0..4 {
            if n.meta[lane] == INTERIOR {
                let p = self.nodes.as_ptr().wrapping_add(n.first[lane] as usize);
                let p = p.cast::<u8>();
                prefetch(p);
                prefetch(p.wrapping_add(64));
            }
        }
    }

    /// Node `i` without a bounds check, for the traversal loop.
    ///
    /// Every interior reference in a `Node4` is made by [`Ray4::new`] and indexes `nodes`; the
    /// traversal only follows such references or starts at the root, 0, of a tree made from a
    /// non-empty binary tree (which always has one node).
    #[inline(always)]
    pub(crate) fn at(&self, i: usize) -> &Node4 {
        debug_assert!(i < self.nodes.len());
        // SAFETY: see above.
        unsafe { self.nodes.get_unchecked(i) }
    }
}

/// The slab test of four boxes at once, with the near and far plane of each axis chosen once
/// per ray by the sign of the direction.
struct SignedSlab4 {
    origin: [F4; 3],
    inv: [F4; 3],
    near: [usize; 3],
    far: [usize; 3],
}

impl SignedSlab4 {
    #[inline(always)]
    fn new(ray: &Ray) -> Self {
        let inv = [ray.inv_dir.x, ray.inv_dir.y, ray.inv_dir.z];
        let neg = inv.map(f32::is_sign_negative);
        Self {
            origin: [ray.origin.x, ray.origin.y, ray.origin.z].map(F4::splat),
            inv: inv.map(F4::splat),
            near: [0, 1, 2].map(|a| if neg[a] { 3 + a } else { a }),
            far: [0, 1, 2].map(|a| if neg[a] { a } else { 3 + a }),
        }
    }

    /// Entry times of the ray into the four boxes of `n` within `[0, t_max]`, and the bit mask
    /// of the boxes it enters. Same result per box as `Ray::slab`: a NaN plane time (from
    /// `0 * inf`) is dropped, since it is always the first operand of the SSE-rule min/max.
    /// Except that an infinite entry time counts as an entry here when `t_max` is infinite:
    /// that only costs a visit, as the primitives' `Ray::slab` test drops it.
    #[inline(always)]
    fn entries(&self, n: &Node4, t_max: f32) -> ([f32; 4], u32) {
        let mut t0 = F4::splat(0.0);
        let mut t1 = F4::splat(t_max);
        for a in 0..3 {
            let near = F4::load4(&n.b[self.near[a]]);
            let far = F4::load4(&n.b[self.far[a]]);
            t0 = near.sub(self.origin[a]).mul(self.inv[a]).max(t0);
            t1 = far.sub(self.origin[a]).mul(self.inv[a]).min(t1);
        }
        (t0.to_array(), t0.le_bits(t1))
    }
}

#[cfg(test)]
mod tests {
    use crate::testing::rng;
    use crate::{Aabb, BuildOptions, Builder, Bvh, Ray};
    use nalgebra::{Point3, Vector3};

    fn boxes(n: usize, r: &mut impl FnMut(f32, f32) -> f32) -> Vec<Aabb> {
        (0..n)
            .map(|_| {
                let c = Point3::new(r(0.0, 10.0), r(0.0, 10.0), r(0.0, 10.0));
                let h = Vector3::new(r(0.05, 1.0), r(0.05, 1.0), r(0.05, 1.0));
                Aabb::from_center_half_extents(c, h)
            })
            .collect()
    }

    /// Closest and any hit against brute force, for rays from around the scene.
    fn check(bvh: &Bvh, boxes: &[Aabb], r: &mut impl FnMut(f32, f32) -> f32) {
        for _ in 0..200 {
            let o = Point3::new(r(-2.0, 12.0), r(-2.0, 12.0), r(-2.0, 12.0));
            let d = Vector3::new(r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0));
            let ray = Ray::new(o, d);
            let t_max = r(0.0, 30.0);
            let test = |i: u32, t: f32| ray.intersect_aabb(&boxes[i as usize], t);
            let brute = (0..boxes.len() as u32)
                .filter_map(|i| test(i, t_max))
                .min_by(f32::total_cmp);
            let got = bvh.cast_ray(&ray, t_max, test);
            assert_eq!(got.map(|h| h.t), brute);
            if let Some(h) = got {
                assert_eq!(test(h.primitive, t_max), Some(h.t));
            }
            assert_eq!(
                bvh.cast_ray_any(&ray, t_max, test).is_some(),
                brute.is_some()
            );
        }
    }

    /// A ray with a NaN or infinite origin or direction hits nothing, even with a callback
    /// that would report a hit (it was asked, and a NaN ray entered every box at `t = 0`); a
    /// ray with a zero direction hits only what it starts in.
    #[test]
    fn rays_that_are_not_numbers_hit_nothing() {
        let boxes = [
            Aabb::from_arrays([0.0; 3], [1.0; 3]),
            Aabb::from_arrays([3.0; 3], [4.0; 3]),
        ];
        let bvh = Bvh::build(&boxes, BuildOptions::default()).unwrap();
        for bad in [f32::NAN, f32::INFINITY, -f32::INFINITY] {
            for ray in [
                Ray::new(Point3::new(bad, 0.5, 0.5), Vector3::x()),
                Ray::new(Point3::new(-1.0, 0.5, 0.5), Vector3::new(1.0, bad, 0.0)),
            ] {
                assert_eq!(bvh.cast_ray(&ray, f32::INFINITY, |_, _| Some(0.0)), None);
                assert_eq!(
                    bvh.cast_ray_any(&ray, f32::INFINITY, |_, _| Some(0.0)),
                    None
                );
            }
        }
        let test = |ray: Ray| {
            bvh.cast_ray(&ray, f32::INFINITY, |i, t| {
                ray.intersect_aabb(&boxes[i as usize], t)
            })
            .map(|h| (h.primitive, h.t))
        };
        assert_eq!(
            test(Ray::new(Point3::new(-1.0, -1.0, -1.0), Vector3::zeros())),
            None
        );
        assert_eq!(
            test(Ray::new(Point3::new(3.5, 3.5, 3.5), Vector3::zeros())),
            Some((1, 0.0))
        );
    }

    #[test]
    fn four_wide_tree_is_exact_and_follows_refits() {
        let mut r = rng(7);
        for builder in [Builder::BinnedSah, Builder::Lbvh] {
            for leaf in [1, 4] {
                for n in [1, 3, 5, 200] {
                    let options = BuildOptions {
                        builder,
                        max_leaf_size: leaf,
                        ..Default::default()
                    };
                    let mut b = boxes(n, &mut r);
                    let mut bvh = Bvh::build(&b, options).unwrap();
                    check(&bvh, &b, &mut r);
                    b = boxes(n, &mut r);
                    bvh.refit(&b).unwrap();
                    check(&bvh, &b, &mut r);
                    b[n / 2] = Aabb::from_arrays([20.0; 3], [21.0; 3]);
                    bvh.refit_primitives(&[(n as u32 / 2, b[n / 2])]).unwrap();
                    check(&bvh, &b, &mut r);
                    // A clone keeps its own copy.
                    check(&bvh.clone(), &b, &mut r);
                }
            }
        }
    }
}
