//! Determinism: the same inputs give the same pairs, manifolds (bit for bit), events and
//! self-contacts in the same order, whatever the rayon thread count.

mod common;

use canopy_parry::{CollisionWorld, ContactEvent, ObjectHandle};
use common::*;

/// Everything an update reports, with floats as bits.
type Record = (
    Vec<(ObjectHandle, ObjectHandle, Vec<u32>)>,
    Vec<ContactEvent>,
    Vec<(u32, u32, Vec<u32>)>,
);

fn run(seed: u64) -> Vec<Record> {
    let mut rng = SeedRng::new(seed);
    let n = 150;
    let extent = 2.0 * (n as f32).cbrt();
    let mut world = CollisionWorld::new();
    for _ in 0..n {
        let pose = random_pose(&mut rng, extent);
        world.insert(random_shape(&mut rng, 0.7), pose, ()).unwrap();
    }
    let (v, i) = grid_mesh(&mut rng, 6, 3.0, 0.3);
    let cloth = world
        .insert_deformable(v, i, random_pose(&mut rng, extent), ())
        .unwrap();
    let mut out = Vec::new();
    for _ in 0..6 {
        for h in world.handles().collect::<Vec<_>>() {
            let pose = *world.pose(h).unwrap();
            world.set_pose(h, jitter(&mut rng, &pose, 0.1)).unwrap();
        }
        let mut v = world.vertices(cloth).unwrap().to_vec();
        for p in &mut v {
            p.coords += rng.vec3(-0.3, 0.3);
        }
        world.set_vertices(cloth, &v).unwrap();
        world.update(0.02).unwrap();
        let pairs = world
            .candidate_pairs()
            .iter()
            .map(|p| {
                let bits = p
                    .manifolds()
                    .iter()
                    .flat_map(|m| {
                        let mut b = vec![m.subshape1, m.subshape2];
                        b.extend(m.points.iter().flat_map(|c| {
                            [
                                c.dist.to_bits(),
                                c.local_p1.x.to_bits(),
                                c.local_p2.z.to_bits(),
                            ]
                        }));
                        b
                    })
                    .collect();
                (p.objects().0, p.objects().1, bits)
            })
            .collect();
        let selfs = world
            .self_contacts()
            .iter()
            .map(|c| {
                let bits = c.manifold.points.iter().map(|p| p.dist.to_bits()).collect();
                (c.triangle1, c.triangle2, bits)
            })
            .collect();
        out.push((pairs, world.events().to_vec(), selfs));
    }
    out
}

#[test]
fn same_results_with_one_and_many_threads() {
    let pool = |n| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .unwrap()
    };
    let one = pool(1).install(|| run(3));
    let many = pool(4).install(|| run(3));
    assert!(
        one.iter().any(|r| !r.1.is_empty()),
        "no events: scene too sparse"
    );
    assert!(one == many, "results depend on the thread count");
}
