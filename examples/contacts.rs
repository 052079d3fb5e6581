//! A canopy-parry collision world stepped with a few lines of motion: mixed convex shapes
//! falling and swirling over a triangle-mesh floor, and a deformable cloth that crumples. Prints,
//! per update, the contacts found, the events, the cloth's self-contacts and the time spent in
//! the broad and narrow phases.
//!
//! `cargo run --release --example contacts [OBJECTS]` (default 2000).

use canopy_parry::{CollisionWorld, ContactEvent};
use nalgebra::{Isometry3, Point3, Vector3};
use parry3d::shape::SharedShape;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let n: usize = std::env::args().nth(1).map_or(Ok(2000), |a| a.parse())?;
    let side = (n as f32).sqrt().ceil() as usize;
    let mut world = CollisionWorld::new();

    // A bumpy floor: a 64 × 64 grid mesh (8192 triangles) under the objects.
    let cells = 64;
    let size = side as f32 * 1.2;
    let mut vertices = Vec::new();
    for i in 0..=cells {
        for j in 0..=cells {
            let (x, z) = (
                size * i as f32 / cells as f32,
                size * j as f32 / cells as f32,
            );
            vertices.push(Point3::new(x, 0.3 * (x * 0.7).sin() * (z * 0.5).cos(), z));
        }
    }
    let w = cells + 1;
    let indices: Vec<[u32; 3]> = (0..cells * cells)
        .flat_map(|c| {
            let a = (c / cells) * w + c % cells;
            [[a, a + 1, a + w], [a + 1, a + w + 1, a + w]]
        })
        .collect();
    world.insert(
        SharedShape::trimesh(vertices, indices)?,
        Isometry3::identity(),
        usize::MAX,
    )?;

    // Mixed convex shapes on a grid above the floor.
    let shapes = [
        SharedShape::ball(0.45),
        SharedShape::cuboid(0.4, 0.3, 0.35),
        SharedShape::capsule_y(0.3, 0.25),
        SharedShape::cylinder(0.3, 0.4),
        SharedShape::cone(0.35, 0.4),
    ];
    let mut objects = Vec::new();
    for k in 0..n {
        let base = Vector3::new(
            (k % side) as f32 * 1.2 + 0.6,
            1.0,
            (k / side) as f32 * 1.2 + 0.6,
        );
        let handle = world.insert(
            shapes[k % shapes.len()].clone(),
            Isometry3::translation(base.x, base.y, base.z),
            k,
        )?;
        objects.push((handle, base));
    }

    // A deformable cloth (16 × 16 cells) that will crumple.
    let (cn, cs) = (16u32, 4.0f32);
    let mut cloth_vertices: Vec<Point3<f32>> = (0..=cn)
        .flat_map(|i| {
            (0..=cn).map(move |j| {
                Point3::new(i as f32 * cs / cn as f32, 0.0, j as f32 * cs / cn as f32)
            })
        })
        .collect();
    let cw = cn + 1;
    let cloth_indices: Vec<[u32; 3]> = (0..cn * cn)
        .flat_map(|c| {
            let a = (c / cn) * cw + c % cn;
            [[a, a + 1, a + cw], [a + 1, a + cw + 1, a + cw]]
        })
        .collect();
    let cloth_pose = Isometry3::translation(size * 0.5, 3.0, size * 0.5);
    let cloth = world.insert_deformable(
        cloth_vertices.clone(),
        cloth_indices,
        cloth_pose,
        usize::MAX,
    )?;
    let flat = cloth_vertices.clone();

    println!("{} objects (+ floor mesh and cloth), prediction 0.02", n);
    println!("update  candidates  contacts  started  stopped  self  broad(ms)  narrow(ms)");
    for t in 0..20 {
        let time = t as f32 * 0.1;
        // The motion: each object sinks towards the floor while swirling around its base.
        for (k, (handle, base)) in objects.iter().enumerate() {
            let phase = time * 2.0 + k as f32 * 0.37;
            let p = base + Vector3::new(0.3 * phase.cos(), -0.06 * t as f32, 0.3 * phase.sin());
            world.set_pose(*handle, Isometry3::new(p, Vector3::new(0.0, phase, 0.0)))?;
        }
        // The cloth folds in half along x, a little more every update.
        let fold = (t as f32 / 19.0) * std::f32::consts::PI * 0.95;
        for (v, f) in cloth_vertices.iter_mut().zip(&flat) {
            let hinge = cs * 0.5;
            *v = if f.x <= hinge {
                *f
            } else {
                let r = f.x - hinge;
                Point3::new(hinge + r * fold.cos(), r * fold.sin(), f.z)
            };
        }
        world.set_vertices(cloth, &cloth_vertices)?;

        world.update(0.02)?;
        let s = world.stats();
        let started = world
            .events()
            .iter()
            .filter(|e| matches!(e, ContactEvent::Started(..)))
            .count();
        let stopped = world.events().len() - started;
        println!(
            "{t:>6}  {:>10}  {:>8}  {started:>7}  {stopped:>7}  {:>4}  {:>9.3}  {:>10.3}",
            s.candidate_pairs,
            s.contact_pairs,
            s.self_contacts,
            s.broad_phase.as_secs_f64() * 1e3,
            s.narrow_phase.as_secs_f64() * 1e3,
        );
    }
    if let Some(pair) = world.contact_pairs().next() {
        let (a, b) = pair.objects();
        let name = |k: usize| {
            if k == usize::MAX {
                "floor/cloth".to_string()
            } else {
                format!("object {k}")
            }
        };
        println!(
            "e.g. {} and {}:",
            name(*world.data(a)?),
            name(*world.data(b)?)
        );
        for c in pair.contacts().take(4) {
            println!(
                "  point {:?}, normal {:?}, distance {:.4}",
                c.point1.coords.as_slice(),
                c.normal1.as_slice(),
                c.dist
            );
        }
    }
    Ok(())
}
