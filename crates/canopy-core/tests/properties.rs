//! Property tests: both builders and every query against brute force over all primitives, on
//! random inputs drawn from several distributions (uniform, clustered, identical, zero-size,
//! far from the origin), including empty and single-box inputs. Every tree is validated.

use canopy_core::{Aabb, BuildOptions, Builder, Bvh, BvhError, Node, Ray};
use nalgebra::{Point3, Vector3};
use proptest::prelude::*;

const FAR: f32 = 1.0e6;

fn uniform_box(lo: f32, hi: f32, max_half: f32) -> impl Strategy<Value = Aabb> {
    (
        prop::array::uniform3(lo..hi),
        prop::array::uniform3(0.0f32..max_half),
    )
        .prop_map(|(c, h)| Aabb::from_center_half_extents(Point3::from(c), Vector3::from(h)))
}

/// Box sets from every distribution the issue names.
fn box_set(max_len: usize) -> impl Strategy<Value = Vec<Aabb>> {
    prop_oneof![
        // uniform
        prop::collection::vec(uniform_box(-50.0, 50.0, 6.0), 0..max_len),
        // clustered: a few tight clusters
        (
            prop::collection::vec(prop::array::uniform3(-100.0f32..100.0), 1..4),
            prop::collection::vec(
                (
                    0usize..4,
                    prop::array::uniform3(-1.0f32..1.0),
                    prop::array::uniform3(0.0f32..0.5)
                ),
                0..max_len
            ),
        )
            .prop_map(|(centres, items)| {
                items
                    .into_iter()
                    .map(|(k, o, h)| {
                        let c = centres[k % centres.len()];
                        let c = Point3::new(c[0] + o[0], c[1] + o[1], c[2] + o[2]);
                        Aabb::from_center_half_extents(c, Vector3::from(h))
                    })
                    .collect()
            }),
        // all identical
        (uniform_box(-10.0, 10.0, 2.0), 0..max_len).prop_map(|(b, n)| vec![b; n]),
        // zero-size boxes (points), some repeated
        prop::collection::vec(prop::array::uniform3(-5.0f32..5.0), 0..max_len).prop_map(|ps| {
            ps.into_iter()
                .map(|p| Aabb::from_point(Point3::from(p.map(|c| c.round()))))
                .collect()
        }),
        // far from the origin
        prop::collection::vec(uniform_box(FAR - 100.0, FAR + 100.0, 8.0), 0..max_len),
    ]
}

/// A box coordinate: small, often a whole number (so that faces meet), or NaN or infinite.
fn coordinate() -> impl Strategy<Value = f32> {
    prop_oneof![
        -4.0f32..4.0,
        (-4i32..4).prop_map(|i| i as f32),
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(f32::NEG_INFINITY),
    ]
}

fn options() -> impl Strategy<Value = BuildOptions> {
    (prop::bool::ANY, 1u32..9, 2u32..33, prop::bool::ANY).prop_map(|(lbvh, leaf, bins, par)| {
        BuildOptions {
            builder: if lbvh {
                Builder::Lbvh
            } else {
                Builder::BinnedSah
            },
            max_leaf_size: leaf,
            bins,
            parallel: par,
            ..Default::default()
        }
    })
}

fn build_checked(boxes: &[Aabb], opts: BuildOptions) -> Bvh {
    let bvh = Bvh::build(boxes, opts).expect("valid input builds");
    bvh.validate_with_primitives(boxes)
        .expect("built tree is valid");
    assert_eq!(bvh.len(), boxes.len());
    assert!(bvh.stats().max_leaf_size <= opts.max_leaf_size as usize);
    bvh
}

fn is_unknown_primitive(e: &Option<BvhError>) -> bool {
    matches!(e, Some(BvhError::UnknownPrimitive { .. }))
}

fn brute_self_pairs(boxes: &[Aabb]) -> Vec<(u32, u32)> {
    let mut v = Vec::new();
    for i in 0..boxes.len() {
        for j in i + 1..boxes.len() {
            if boxes[i].intersects(&boxes[j]) {
                v.push((i as u32, j as u32));
            }
        }
    }
    v
}

fn sorted(mut v: Vec<(u32, u32)>) -> Vec<(u32, u32)> {
    v.sort_unstable();
    v
}

/// A query box or point near the data, so queries actually hit something.
fn query_near(boxes: &[Aabb], pick: usize, offset: [f32; 3], half: [f32; 3]) -> Aabb {
    let c = boxes
        .get(pick % boxes.len().max(1))
        .map(|b| b.center())
        .unwrap_or_else(Point3::origin);
    Aabb::from_center_half_extents(c + Vector3::from(offset), Vector3::from(half))
}

/// Every field of every node, floats as bits (so that `-0.0 != 0.0`).
fn node_bits(nodes: &[Node]) -> Vec<[u32; 8]> {
    nodes
        .iter()
        .map(|n| {
            let [a, b, c] = n.min.map(f32::to_bits);
            let [d, e, f] = n.max.map(f32::to_bits);
            [a, b, c, n.first, d, e, f, n.count]
        })
        .collect()
}

/// One primitive's new box: (which, offset of its centre, new half extents, how). How: 0,
/// a jump twenty times as far; 1, a point at whole (often zero, of either sign) coordinates
/// near the origin; else a small move.
type Change = (usize, [f32; 3], [f32; 3], u8);

fn change() -> impl Strategy<Value = Change> {
    (
        any::<usize>(),
        prop::array::uniform3(-2.0f32..2.0),
        prop::array::uniform3(0.0f32..3.0),
        0u8..10,
    )
}

/// One round of `refit_primitives`: (kind, changes). Kind 0: one change; 1: a few; 2: all the
/// listed ones (up to a few hundred, duplicates likely); 3: every primitive, and the listed
/// ones again after.
fn refit_round() -> impl Strategy<Value = (u8, Vec<Change>)> {
    (0u8..4, prop::collection::vec(change(), 1..400))
}

/// The changes of one round on `cur` (updated, the last change of a primitive counting).
fn round_changes(cur: &mut [Aabb], kind: u8, list: &[Change]) -> Vec<(u32, Aabb)> {
    let n = cur.len();
    let list = match kind {
        0 => &list[..1],
        1 => &list[..list.len().min(8)],
        _ => list,
    };
    let mut order: Vec<(usize, &Change)> = Vec::new();
    if kind == 3 {
        order.extend((0..n).map(|i| (i, &list[i % list.len()])));
    }
    order.extend(list.iter().map(|c| (c.0 % n, c)));
    order
        .into_iter()
        .map(|(i, &(_, o, h, how))| {
            let b = match how {
                0 => Aabb::from_center_half_extents(
                    cur[i].center() + Vector3::from(o.map(|c| c * 20.0)),
                    Vector3::from(h),
                ),
                1 => Aabb::from_point(Point3::from(o.map(|c| (c * 0.4).round()))),
                _ => Aabb::from_center_half_extents(
                    cur[i].center() + Vector3::from(o),
                    Vector3::from(h),
                ),
            };
            cur[i] = b;
            (i as u32, b)
        })
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// The branch-free box tests answer as the short-circuit ones, touching boxes, zero-size
    /// boxes and NaN or infinite coordinates included (the second box often reuses the first
    /// box's coordinates, so that faces meet).
    #[test]
    fn branchless_box_tests_match(
        a in prop::array::uniform6(coordinate()),
        b in prop::array::uniform6(coordinate()),
        reuse in prop::array::uniform6(0usize..9),
        sorted in prop::bool::ANY,
    ) {
        let b: [f32; 6] = std::array::from_fn(|k| if reuse[k] < 6 { a[reuse[k]] } else { b[k] });
        // Half the cases have min <= max on every axis (NaN aside), so that overlapping and
        // nested boxes, where the answer is `true`, are common.
        let make = |v: [f32; 6]| {
            let (mut min, mut max) = ([v[0], v[1], v[2]], [v[3], v[4], v[5]]);
            if sorted {
                for i in 0..3 {
                    if min[i] > max[i] {
                        std::mem::swap(&mut min[i], &mut max[i]);
                    }
                }
            }
            Aabb::from_arrays(min, max)
        };
        let (x, y) = (make(a), make(b));
        prop_assert_eq!(x.intersects_branchless(&y), x.intersects(&y));
        prop_assert_eq!(y.intersects_branchless(&x), y.intersects(&x));
        prop_assert_eq!(x.contains_branchless(&y), x.contains(&y));
        prop_assert_eq!(y.contains_branchless(&x), y.contains(&x));
    }

    #[test]
    fn partial_refit_rounds_match_the_full_refit(
        boxes in box_set(300),
        opts in options(),
        rounds in prop::collection::vec(refit_round(), 1..6),
        queries in prop::collection::vec((0usize..1000, prop::array::uniform3(-3.0f32..3.0), prop::array::uniform3(0.0f32..4.0)), 1..4),
        four_wide in prop::bool::ANY,
    ) {
        prop_assume!(!boxes.is_empty());
        let fresh = build_checked(&boxes, opts);
        let mut normalized = fresh.clone();
        normalized.refit(&boxes).expect("valid boxes refit");
        for (fresh_tree, mut bvh) in [(true, fresh), (false, normalized)] {
            let mut cur = boxes.clone();
            // Make the wide array (and, sometimes, the four-wide copy) before the refits.
            let q = query_near(&cur, queries[0].0, queries[0].1, queries[0].2);
            bvh.for_each_overlap(&q, |_| {});
            if four_wide {
                bvh.self_pairs(|_, _| {});
            }
            for (kind, list) in &rounds {
                let changes = round_changes(&mut cur, *kind, list);
                let mut full = bvh.clone();
                full.refit(&cur).expect("valid boxes refit");
                bvh.refit_primitives(&changes).expect("valid changes refit");
                if fresh_tree {
                    prop_assert_eq!(bvh.nodes(), full.nodes());
                } else {
                    prop_assert_eq!(node_bits(bvh.nodes()), node_bits(full.nodes()));
                }
                // Also checks the wide array against the nodes.
                bvh.validate_with_primitives(&cur).expect("refit tree is valid");
                for &(pick, offset, half) in &queries {
                    let q = query_near(&cur, pick, offset, half);
                    let expect: Vec<u32> = (0..cur.len() as u32).filter(|&i| cur[i as usize].intersects(&q)).collect();
                    let mut cb = Vec::new();
                    bvh.for_each_overlap(&q, |i| cb.push(i));
                    cb.sort_unstable();
                    prop_assert_eq!(&cb, &expect);
                    let mut got: Vec<u32> = bvh.overlaps(&q).collect();
                    got.sort_unstable();
                    prop_assert_eq!(&got, &expect);
                }
                if four_wide {
                    let mut got = Vec::new();
                    bvh.self_pairs(|a, b| got.push((a, b)));
                    prop_assert_eq!(sorted(got), brute_self_pairs(&cur));
                }
            }
        }
    }

    #[test]
    fn self_pairs_match_brute_force(boxes in box_set(200), opts in options()) {
        let bvh = build_checked(&boxes, opts);
        let expect = brute_self_pairs(&boxes);
        let mut serial = Vec::new();
        bvh.self_pairs(|a, b| serial.push((a, b)));
        prop_assert!(serial.iter().all(|&(a, b)| a < b));
        let serial = sorted(serial);
        prop_assert_eq!(&serial, &expect, "serial self pairs");
        prop_assert_eq!(sorted(bvh.par_self_pairs()), expect, "parallel self pairs");
    }

    #[test]
    fn tree_pairs_match_brute_force(a in box_set(150), b in box_set(150), oa in options(), ob in options()) {
        let (ta, tb) = (build_checked(&a, oa), build_checked(&b, ob));
        let mut expect = Vec::new();
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                if x.intersects(y) {
                    expect.push((i as u32, j as u32));
                }
            }
        }
        let mut got = Vec::new();
        ta.pairs_with(&tb, |i, j| got.push((i, j)));
        prop_assert_eq!(sorted(got), expect.clone());
        prop_assert_eq!(sorted(ta.par_pairs_with(&tb)), expect);
    }

    #[test]
    fn marked_pairs_match_brute_force(
        a in box_set(150),
        b in box_set(150),
        oa in options(),
        ob in options(),
        seed_a in any::<u64>(),
        seed_b in any::<u64>(),
        density in 0u64..4,
    ) {
        // Mark about density/4 of the primitives (0: none, 3: three in four).
        let mark = |seed: u64, i: u32| (seed ^ (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)).rotate_left(17) % 4 < density;
        let (ta, tb) = (build_checked(&a, oa), build_checked(&b, ob));
        let (ma, mb) = (ta.marks(|i| mark(seed_a, i)), tb.marks(|i| mark(seed_b, i)));
        let expect_self: Vec<(u32, u32)> = brute_self_pairs(&a)
            .into_iter()
            .filter(|&(x, y)| mark(seed_a, x) || mark(seed_a, y))
            .collect();
        let mut got = Vec::new();
        ta.self_pairs_marked(&ma, |x, y| got.push((x, y)));
        prop_assert_eq!(sorted(got), expect_self.clone());
        prop_assert_eq!(sorted(ta.par_self_pairs_marked(&ma)), expect_self);

        let mut expect = Vec::new();
        for (i, x) in a.iter().enumerate() {
            for (j, y) in b.iter().enumerate() {
                if x.intersects(y) && (mark(seed_a, i as u32) || mark(seed_b, j as u32)) {
                    expect.push((i as u32, j as u32));
                }
            }
        }
        let mut got = Vec::new();
        ta.pairs_with_marked(&ma, &tb, &mb, |x, y| got.push((x, y)));
        prop_assert_eq!(sorted(got), expect.clone());
        prop_assert_eq!(sorted(ta.par_pairs_with_marked(&ma, &tb, &mb)), expect);

        // Marks of another tree count as "all marked": never a missed pair. Also for a tree
        // of the same size, even the same boxes built again (marks used to be checked by size
        // only, and then missed every pair here); a clone shares its tree's marks.
        let all = sorted(ta.par_self_pairs());
        let none_of_b = tb.marks(|_| false);
        prop_assert_eq!(sorted(ta.par_self_pairs_marked(&none_of_b)), all.clone());
        let again = build_checked(&a, oa);
        let none_of_again = again.marks(|_| false);
        prop_assert_eq!(sorted(ta.par_self_pairs_marked(&none_of_again)), all.clone());
        let mut got = Vec::new();
        ta.self_pairs_marked(&none_of_again, |x, y| got.push((x, y)));
        prop_assert_eq!(sorted(got), all);
        prop_assert_eq!(sorted(ta.clone().par_self_pairs_marked(&ta.marks(|_| false))), vec![]);
    }

    #[test]
    fn overlap_and_point_queries_match_brute_force(
        boxes in box_set(200),
        opts in options(),
        pick in 0usize..1000,
        offset in prop::array::uniform3(-3.0f32..3.0),
        half in prop::array::uniform3(0.0f32..4.0),
    ) {
        let bvh = build_checked(&boxes, opts);
        let q = query_near(&boxes, pick, offset, half);
        let mut got: Vec<u32> = bvh.overlaps(&q).collect();
        // The callback form walks another array (the four-wide copy), in its own order, which
        // is the same on every call.
        let mut cb = Vec::new();
        bvh.for_each_overlap(&q, |i| cb.push(i));
        let mut again = Vec::new();
        bvh.for_each_overlap(&q, |i| again.push(i));
        prop_assert_eq!(&cb, &again);
        got.sort_unstable();
        let expect: Vec<u32> = (0..boxes.len() as u32).filter(|&i| boxes[i as usize].intersects(&q)).collect();
        prop_assert_eq!(&got, &expect);
        cb.sort_unstable();
        prop_assert_eq!(cb, expect);

        let p = q.center();
        let mut got: Vec<u32> = bvh.containing_point(&p).collect();
        got.sort_unstable();
        let expect: Vec<u32> = (0..boxes.len() as u32).filter(|&i| boxes[i as usize].contains_point(&p)).collect();
        prop_assert_eq!(got, expect);
    }

    #[test]
    fn ray_casts_match_brute_force(
        boxes in box_set(200),
        opts in options(),
        pick in 0usize..1000,
        offset in prop::array::uniform3(-30.0f32..30.0),
        dir in prop::array::uniform3(-1.0f32..1.0),
        axis_aligned in 0usize..4,
        t_max in prop_oneof![Just(f32::INFINITY), 0.0f32..100.0],
    ) {
        let bvh = build_checked(&boxes, opts);
        let origin = query_near(&boxes, pick, offset, [0.0; 3]).min;
        let mut d = Vector3::from(dir);
        if axis_aligned < 3 {
            // Rays parallel to two axes exercise the infinite inverse direction.
            d = Vector3::zeros();
            d[axis_aligned] = if dir[0] < 0.0 { -1.0 } else { 1.0 };
        }
        prop_assume!(d.norm() > 1e-3);
        // Aim at a box half the time.
        let ray = Ray::new(origin, d);
        let test = |i: u32, t: f32| ray.intersect_aabb(&boxes[i as usize], t);
        let brute = (0..boxes.len() as u32)
            .filter_map(|i| test(i, t_max).map(|t| (t, i)))
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let got = bvh.cast_ray(&ray, t_max, test);
        match (got, brute) {
            (None, None) => {}
            (Some(h), Some((t, _))) => {
                prop_assert_eq!(h.t, t);
                prop_assert_eq!(test(h.primitive, t_max), Some(t), "reported primitive is hit at t");
            }
            (g, b) => prop_assert!(false, "tree {:?} vs brute force {:?}", g, b),
        }
        let any = bvh.cast_ray_any(&ray, t_max, test);
        prop_assert_eq!(any.is_some(), brute.is_some());
        if let Some(h) = any {
            prop_assert_eq!(test(h.primitive, t_max), Some(h.t));
        }
    }

    #[test]
    fn nearest_matches_brute_force(
        boxes in box_set(200),
        opts in options(),
        pick in 0usize..1000,
        offset in prop::array::uniform3(-20.0f32..20.0),
        max_d in prop_oneof![Just(f32::INFINITY), 0.0f32..10.0],
    ) {
        let bvh = build_checked(&boxes, opts);
        let p = query_near(&boxes, pick, offset, [0.0; 3]).min;
        let dist = |i: u32, _best: f32| Some(boxes[i as usize].distance_to_point(&p));
        let brute = (0..boxes.len() as u32)
            .map(|i| (boxes[i as usize].distance_to_point(&p), i))
            .filter(|&(d, _)| d <= max_d)
            .min_by(|a, b| a.0.total_cmp(&b.0));
        let got = bvh.nearest(&p, max_d, dist);
        match (got, brute) {
            (None, None) => {}
            (Some(h), Some((d, _))) => {
                prop_assert_eq!(h.distance, d);
                prop_assert_eq!(boxes[h.primitive as usize].distance_to_point(&p), d);
            }
            (g, b) => prop_assert!(false, "tree {:?} vs brute force {:?}", g, b),
        }
    }

    #[test]
    fn refit_keeps_queries_exact(
        boxes in box_set(150),
        opts in options(),
        moves in prop::collection::vec((prop::array::uniform3(-20.0f32..20.0), prop::array::uniform3(0.0f32..3.0)), 150),
    ) {
        let mut bvh = build_checked(&boxes, opts);
        let moved: Vec<Aabb> = boxes
            .iter()
            .zip(moves.iter().cycle())
            .map(|(b, (o, h))| Aabb::from_center_half_extents(b.center() + Vector3::from(*o), Vector3::from(*h)))
            .collect();
        bvh.refit(&moved).expect("valid boxes refit");
        bvh.validate_with_primitives(&moved).expect("refit tree is valid");
        let mut got = Vec::new();
        bvh.self_pairs(|a, b| got.push((a, b)));
        prop_assert_eq!(sorted(got), brute_self_pairs(&moved));
    }

    #[test]
    fn partial_refit_keeps_queries_exact(
        boxes in box_set(150),
        opts in options(),
        moves in prop::collection::vec((0usize..150, prop::array::uniform3(-20.0f32..20.0), prop::array::uniform3(0.0f32..3.0)), 0..60),
        bad in prop::option::of(0usize..60),
    ) {
        let mut bvh = build_checked(&boxes, opts);
        let mut moved = boxes.clone();
        let mut changes = Vec::new();
        for &(i, o, h) in &moves {
            if boxes.is_empty() {
                break;
            }
            let i = i % boxes.len();
            let b = Aabb::from_center_half_extents(boxes[i].center() + Vector3::from(o), Vector3::from(h));
            moved[i] = b;
            changes.push((i as u32, b));
        }
        // A bad entry anywhere leaves the tree unchanged.
        if let Some(k) = bad.filter(|&k| k < changes.len()) {
            let mut broken = changes.clone();
            broken[k].1.max.x = f32::NAN;
            let before = bvh.clone();
            prop_assert_eq!(bvh.refit_primitives(&broken), Err(BvhError::InvalidAabb { index: k }));
            prop_assert_eq!(bvh.nodes(), before.nodes());
            prop_assert_eq!(bvh.primitive_bounds(), before.primitive_bounds());
            let unknown = [(boxes.len() as u32, Aabb::from_point(Point3::origin()))];
            let unknown_err = bvh.refit_primitives(&unknown).err();
            prop_assert!(is_unknown_primitive(&unknown_err));
        }
        bvh.refit_primitives(&changes).expect("valid changes refit");
        bvh.validate_with_primitives(&moved).expect("refit tree is valid");
        let mut got = Vec::new();
        bvh.self_pairs(|a, b| got.push((a, b)));
        prop_assert_eq!(sorted(got), brute_self_pairs(&moved));
    }

    #[test]
    fn invalid_boxes_are_errors_naming_the_first(
        boxes in prop::collection::vec(uniform_box(-10.0, 10.0, 2.0), 1..100),
        at in 0usize..100,
        kind in 0usize..5,
        lbvh in prop::bool::ANY,
    ) {
        let at = at % boxes.len();
        let mut bad = boxes.clone();
        let b = &mut bad[at];
        match kind {
            0 => b.min.x = f32::NAN,
            1 => b.max.y = f32::NAN,
            2 => b.max.z = f32::INFINITY,
            3 => b.min.x = f32::NEG_INFINITY,
            _ => b.min.y = b.max.y + 1.0, // inverted
        }
        let opts = BuildOptions::default().with_builder(if lbvh { Builder::Lbvh } else { Builder::BinnedSah });
        prop_assert_eq!(Bvh::build(&bad, opts).err(), Some(BvhError::InvalidAabb { index: at }));

        // Refit with a bad box fails and leaves the tree as it was.
        let mut bvh = build_checked(&boxes, opts);
        let before = bvh.clone();
        prop_assert_eq!(bvh.refit(&bad).err(), Some(BvhError::InvalidAabb { index: at }));
        prop_assert_eq!(bvh.nodes(), before.nodes());
        prop_assert_eq!(bvh.primitive_bounds(), before.primitive_bounds());
    }
}

#[test]
fn empty_input_is_an_empty_tree() {
    for builder in [Builder::BinnedSah, Builder::Lbvh] {
        let bvh = Bvh::build(&[], BuildOptions::default().with_builder(builder)).unwrap();
        bvh.validate().unwrap();
        assert!(bvh.is_empty() && bvh.root_aabb().is_none());
        assert_eq!(
            bvh.overlaps(&Aabb::from_arrays([-1e9; 3], [1e9; 3]))
                .count(),
            0
        );
        let ray = Ray::new(Point3::origin(), Vector3::x());
        assert!(bvh
            .cast_ray(&ray, f32::INFINITY, |_, _| Some(0.0))
            .is_none());
        assert!(bvh
            .nearest(&Point3::origin(), f32::INFINITY, |_, _| Some(0.0))
            .is_none());
        assert!(bvh.par_self_pairs().is_empty());
        assert_eq!(bvh.stats().sah_cost, 0.0);
    }
}

#[test]
fn bad_options_and_lengths_are_errors() {
    let boxes = [Aabb::from_arrays([0.0; 3], [1.0; 3])];
    let bad_leaf = BuildOptions {
        max_leaf_size: 0,
        ..Default::default()
    };
    assert!(matches!(
        Bvh::build(&boxes, bad_leaf),
        Err(BvhError::InvalidOptions(_))
    ));
    let bad_bins = BuildOptions {
        bins: 1,
        ..Default::default()
    };
    assert!(matches!(
        Bvh::build(&boxes, bad_bins),
        Err(BvhError::InvalidOptions(_))
    ));
    let bad_cost = BuildOptions {
        traversal_cost: f32::NAN,
        ..Default::default()
    };
    assert!(matches!(
        Bvh::build(&boxes, bad_cost),
        Err(BvhError::InvalidOptions(_))
    ));
    let mut bvh = Bvh::build(&boxes, BuildOptions::default()).unwrap();
    assert_eq!(
        bvh.refit(&[]),
        Err(BvhError::LengthMismatch {
            expected: 1,
            got: 0
        })
    );
}

#[test]
fn huge_coordinates_build_and_query() {
    let m = f32::MAX;
    let boxes = vec![
        Aabb::from_arrays([-m; 3], [m; 3]),
        Aabb::from_arrays([m / 2.0; 3], [m; 3]),
        Aabb::from_arrays([-m; 3], [-m / 2.0; 3]),
        Aabb::from_arrays([0.0; 3], [0.0; 3]),
    ];
    for builder in [Builder::BinnedSah, Builder::Lbvh] {
        let bvh = build_checked(
            &boxes,
            BuildOptions::default()
                .with_builder(builder)
                .with_max_leaf_size(1),
        );
        assert!(bvh.stats().sah_cost.is_finite());
        assert_eq!(sorted(bvh.par_self_pairs()), brute_self_pairs(&boxes));
    }
}

/// Deterministic pseudo-random boxes for the larger tests below.
fn lcg_boxes(n: usize, seed: u64) -> Vec<Aabb> {
    let mut s = seed;
    let mut next = move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 40) as f32) / (1u64 << 24) as f32
    };
    let side = (n as f32).cbrt() * 2.0;
    (0..n)
        .map(|_| {
            let c = Point3::new(next() * side, next() * side, next() * side);
            let h = Vector3::new(
                0.05 + next() * 0.45,
                0.05 + next() * 0.45,
                0.05 + next() * 0.45,
            );
            Aabb::from_center_half_extents(c, h)
        })
        .collect()
}

#[test]
fn builds_and_pairs_do_not_depend_on_thread_count() {
    let boxes = lcg_boxes(50_000, 42);
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    for builder in [Builder::BinnedSah, Builder::Lbvh] {
        let opts = BuildOptions::default().with_builder(builder);
        let one = pool(1).install(|| Bvh::build(&boxes, opts).unwrap());
        let two = pool(2).install(|| Bvh::build(&boxes, opts).unwrap());
        let serial = Bvh::build(&boxes, opts.with_parallel(false)).unwrap();
        one.validate_with_primitives(&boxes).unwrap();
        assert_eq!(one.nodes(), two.nodes());
        assert_eq!(one.nodes(), serial.nodes());
        assert_eq!(one.primitive_indices(), two.primitive_indices());
        let p1 = pool(1).install(|| one.par_self_pairs());
        let p2 = pool(2).install(|| one.par_self_pairs());
        let p3 = pool(3).install(|| one.par_self_pairs());
        assert_eq!(p1, p2);
        assert_eq!(p1, p3);
        let mut serial_pairs = Vec::new();
        one.self_pairs(|a, b| serial_pairs.push((a, b)));
        assert_eq!(sorted(p1), sorted(serial_pairs));
    }
}

#[test]
fn sah_tree_is_no_worse_than_lbvh() {
    let boxes = lcg_boxes(20_000, 7);
    let sah = Bvh::build(&boxes, BuildOptions::default()).unwrap().stats();
    let lbvh = Bvh::build(&boxes, BuildOptions::default().with_builder(Builder::Lbvh))
        .unwrap()
        .stats();
    assert!(
        sah.sah_cost <= lbvh.sah_cost,
        "SAH {} vs LBVH {}",
        sah.sah_cost,
        lbvh.sah_cost
    );
    assert!(sah.depth < 64 && lbvh.depth < 64);
}

/// The distance from `p` to the box, by an independent route: the nearest point of the box
/// (`p` clamped to it, in `f64`), then the length of the difference, scaled so that no square
/// overflows even in `f64`.
fn reference_distance(b: &Aabb, p: &Point3<f32>) -> f64 {
    let d: Vec<f64> = (0..3)
        .map(|i| {
            let q = (p[i] as f64).clamp(b.min[i] as f64, b.max[i] as f64);
            (p[i] as f64 - q).abs()
        })
        .collect();
    let scale = d.iter().cloned().fold(0.0, f64::max);
    if scale == 0.0 {
        return 0.0;
    }
    scale * d.iter().map(|x| (x / scale).powi(2)).sum::<f64>().sqrt()
}

/// A coordinate anywhere in `f32`'s range, small or huge.
fn any_scale() -> impl Strategy<Value = f32> {
    prop_oneof![
        -10.0f32..10.0,
        -1.0e20f32..1.0e20,
        -1.0e30f32..1.0e30,
        -f32::MAX..f32::MAX,
    ]
}

proptest! {
    /// `distance_to_point` is the exact distance rounded to `f32`, for boxes and points at any
    /// scale (squares of `f32` distances past 1.8e19 overflow; the distance must not).
    #[test]
    fn box_distance_is_exact_at_any_scale(
        a in prop::array::uniform3(any_scale()),
        b in prop::array::uniform3(any_scale()),
        p in prop::array::uniform3(any_scale()),
    ) {
        let lo = [a[0].min(b[0]), a[1].min(b[1]), a[2].min(b[2])];
        let hi = [a[0].max(b[0]), a[1].max(b[1]), a[2].max(b[2])];
        let aabb = Aabb::from_arrays(lo, hi);
        let p = Point3::from(p);
        let want = reference_distance(&aabb, &p);
        let got = aabb.distance_to_point(&p) as f64;
        if want > f32::MAX as f64 {
            prop_assert!(got >= f32::MAX as f64, "{} for {}", got, want);
        } else {
            prop_assert!((got - want).abs() <= want * 1.0e-6, "{} for {}", got, want);
        }
    }

    /// `nearest` finds the nearest box (by the independent distance) on boxes spread over
    /// huge ranges, where the squared distances overflow `f32`.
    #[test]
    fn nearest_matches_brute_force_at_huge_distances(
        boxes in prop::collection::vec(
            (prop::array::uniform3(-1.0e30f32..1.0e30), prop::array::uniform3(0.0f32..1.0e28)),
            1..120,
        ),
        opts in options(),
        p in prop::array::uniform3(-1.0e30f32..1.0e30),
        limit in prop_oneof![Just(f32::INFINITY), 0.0f32..2.0e30],
    ) {
        let boxes: Vec<Aabb> = boxes
            .into_iter()
            .map(|(c, h)| Aabb::from_center_half_extents(Point3::from(c), Vector3::from(h)))
            .collect();
        let bvh = build_checked(&boxes, opts);
        let p = Point3::from(p);
        let exact = |i: u32| reference_distance(&boxes[i as usize], &p) as f32;
        let got = bvh.nearest(&p, limit, |i, _| Some(exact(i)));
        let brute = (0..boxes.len() as u32)
            .map(|i| (exact(i), i))
            .filter(|&(d, _)| d <= limit)
            .min_by(|a, b| a.0.total_cmp(&b.0));
        match (got, brute) {
            (None, None) => {}
            (Some(h), Some((d, _))) => prop_assert_eq!(h.distance, d),
            (g, b) => prop_assert!(false, "tree {:?} vs brute force {:?}", g, b),
        }
    }
}

#[test]
fn nearest_at_distances_whose_squares_overflow() {
    // Two points on the x axis, 3e19 and 2e19 from the query point: the second is nearer,
    // and within a limit of 2.5e19.
    let boxes = [
        Aabb::from_arrays([3.0e19, 0.0, 0.0], [3.0e19, 0.0, 0.0]),
        Aabb::from_arrays([2.0e19, 0.0, 0.0], [2.0e19, 0.0, 0.0]),
    ];
    let p = Point3::origin();
    assert_eq!(boxes[1].distance_to_point(&p), 2.0e19);
    for builder in [Builder::BinnedSah, Builder::Lbvh] {
        let bvh = Bvh::build(&boxes, BuildOptions::default().with_builder(builder)).unwrap();
        for limit in [f32::INFINITY, 2.5e19] {
            let hit = bvh.nearest(&p, limit, |i, _| {
                Some(boxes[i as usize].distance_to_point(&p))
            });
            assert_eq!(
                hit.map(|h| (h.primitive, h.distance)),
                Some((1, 2.0e19)),
                "{builder:?}, {limit}"
            );
        }
    }
}
