//! Build benchmarks: canopy's binned-SAH and LBVH builders against parry3d 0.22's `Bvh`
//! (binned and PLOC strategies) on 10k, 100k and 1M random boxes at constant density (see
//! `common/mod.rs`).
//!
//! Benchmarks, per size `n`: `build/{n}/parry_binned`, `build/{n}/parry_ploc` (parry builds on
//! one thread), `build/{n}/canopy_sah`, `build/{n}/canopy_lbvh` (canopy with `parallel: false`
//! on a one-thread rayon pool), and `build/{n}/canopy_sah_par`, `build/{n}/canopy_lbvh_par`
//! (canopy's parallel build on the default rayon pool).
//!
//! Before the timings it prints a quality table: SAH cost (canopy's formula, unit costs), node
//! and leaf counts, mean and largest leaf size and depth of every tree, and checks that canopy's
//! trees are valid and the same with and without `parallel`.

mod common;

use canopy::core::{Aabb, BuildOptions, Builder, Bvh};
use common::{
    configure_group, in_one_thread, one_thread_pool, parry_sah_cost, parry_shape, random_boxes,
    size_label, to_parry, SIZES,
};
use criterion::{black_box, criterion_group, criterion_main, Criterion, Throughput};
use parry3d::partitioning::{Bvh as ParryBvh, BvhBuildStrategy};

/// Seed of the box sets (the same boxes as in `core_queries`).
const SEED: u64 = 0x5eed_0001;

fn serial(builder: Builder) -> BuildOptions {
    BuildOptions::default()
        .with_builder(builder)
        .with_parallel(false)
}

fn parallel(builder: Builder) -> BuildOptions {
    BuildOptions::default()
        .with_builder(builder)
        .with_parallel(true)
}

/// Builds a canopy tree serially and in parallel, checks both, and returns the serial one.
fn checked_canopy_build(boxes: &[Aabb], builder: Builder) -> Bvh {
    let ser = in_one_thread(|| Bvh::build(boxes, serial(builder))).expect("canopy build");
    let par = Bvh::build(boxes, parallel(builder)).expect("canopy parallel build");
    ser.validate_with_primitives(boxes)
        .expect("canopy serial tree is valid");
    par.validate_with_primitives(boxes)
        .expect("canopy parallel tree is valid");
    let same = ser.nodes() == par.nodes()
        && ser.primitive_indices() == par.primitive_indices()
        && ser.primitive_bounds() == par.primitive_bounds();
    if !same {
        println!(
            "WARNING: canopy {builder:?} trees differ between parallel and serial builds (n = {})",
            boxes.len()
        );
    }
    ser
}

/// Prints the quality table of every tree at every size.
fn quality_table() {
    println!();
    println!("Tree quality (SAH cost: unit traversal and intersection costs, canopy's formula;");
    println!("parry leaves hold 1 primitive, canopy leaves up to 4)");
    println!(
        "{:>6}  {:<14} {:>10} {:>10} {:>10} {:>9} {:>6} {:>9}",
        "n", "tree", "SAH cost", "nodes", "leaves", "avg leaf", "depth", "max leaf"
    );
    for n in SIZES {
        let boxes = random_boxes(n, SEED);
        let pboxes = to_parry(&boxes);
        let label = size_label(n);
        for (name, strategy) in [
            ("parry binned", BvhBuildStrategy::Binned),
            ("parry ploc", BvhBuildStrategy::Ploc),
        ] {
            let t = ParryBvh::from_leaves(strategy, &pboxes);
            assert_eq!(t.leaf_count() as usize, n);
            let (nodes, depth) = parry_shape(&t);
            println!(
                "{label:>6}  {name:<14} {:>10.2} {nodes:>10} {n:>10} {:>9.2} {depth:>6} {:>9}",
                parry_sah_cost(&t),
                1.0,
                1
            );
        }
        for (name, builder) in [
            ("canopy sah", Builder::BinnedSah),
            ("canopy lbvh", Builder::Lbvh),
        ] {
            let s = checked_canopy_build(&boxes, builder).stats();
            println!(
                "{label:>6}  {name:<14} {:>10.2} {:>10} {:>10} {:>9.2} {:>6} {:>9}",
                s.sah_cost,
                s.nodes,
                s.leaves,
                n as f64 / s.leaves as f64,
                s.depth,
                s.max_leaf_size
            );
        }
    }
    println!();
}

fn bench_build(c: &mut Criterion) {
    quality_table();
    let pool = one_thread_pool();
    for n in SIZES {
        let boxes = random_boxes(n, SEED);
        let pboxes = to_parry(&boxes);
        let mut g = c.benchmark_group(format!("build/{n}"));
        g.throughput(Throughput::Elements(n as u64));
        configure_group(&mut g, n);

        g.bench_function("parry_binned", |b| {
            b.iter(|| ParryBvh::from_leaves(BvhBuildStrategy::Binned, black_box(&pboxes)))
        });
        g.bench_function("parry_ploc", |b| {
            b.iter(|| ParryBvh::from_leaves(BvhBuildStrategy::Ploc, black_box(&pboxes)))
        });
        for (name, builder) in [
            ("canopy_sah", Builder::BinnedSah),
            ("canopy_lbvh", Builder::Lbvh),
        ] {
            let opts = serial(builder);
            g.bench_function(name, |b| {
                pool.install(|| b.iter(|| Bvh::build(black_box(&boxes), opts).unwrap()))
            });
        }
        for (name, builder) in [
            ("canopy_sah_par", Builder::BinnedSah),
            ("canopy_lbvh_par", Builder::Lbvh),
        ] {
            let opts = parallel(builder);
            g.bench_function(name, |b| {
                b.iter(|| Bvh::build(black_box(&boxes), opts).unwrap())
            });
        }
        g.finish();
    }
}

criterion_group!(benches, bench_build);
criterion_main!(benches);
