use canopy::rapier::CanopyBroadPhase;
use canopy::scenes::{ray_batch, scene, Size, World};
use rapier3d::prelude::*;
use std::cell::Cell;
fn main() {
    let build = || scene("many_static", Size::Full).unwrap();
    let mut rapier = World::new(build(), BroadPhaseBvh::new());
    let mut canopy = World::new(build(), CanopyBroadPhase::new());
    rapier.step();
    canopy.step();
    let rays = ray_batch(rapier.colliders(), 20000, 7);
    let n = Cell::new(0usize);
    let pred = |_h: ColliderHandle, _c: &Collider| {
        n.set(n.get() + 1);
        true
    };
    let filter = QueryFilter::default().predicate(&pred);
    let q = rapier.broad_phase.as_query_pipeline(
        rapier.narrow_phase.query_dispatcher(),
        rapier.bodies(),
        rapier.colliders(),
        filter,
    );
    for r in &rays {
        q.cast_ray(r, Real::MAX, true);
    }
    println!(
        "rapier candidates per ray {}",
        n.get() as f64 / rays.len() as f64
    );
    n.set(0);
    let q = canopy.broad_phase.scene_queries(
        canopy.narrow_phase.query_dispatcher(),
        canopy.bodies(),
        canopy.colliders(),
        filter,
    );
    for r in &rays {
        q.cast_ray(r, Real::MAX, true);
    }
    println!(
        "canopy candidates per ray {}",
        n.get() as f64 / rays.len() as f64
    );
    println!("{:?}", canopy.broad_phase.stats());
}
