//! Ray throughput on cornell-bunny (69k-triangle bunny in the box): closest-hit camera rays,
//! and shadow rays from their hit points to the light's centre (stopping at the first hit).
//! The same rays through obvhs' compressed-wide BVH over the same triangles (its own
//! Möller–Trumbore test) are timed beside relume's eight-wide BVH, so that the ratio of the two
//! comes from one run.

use divan::counter::ItemsCount;
use glam::Vec3;
use glam::Vec3A;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::cwbvh::CwBvh;
use obvhs::ray::{Ray, RayHit};
use obvhs::triangle::Triangle;
use obvhs::BvhBuildParams;
use relume_base::render::camera::CameraRays;
use relume_base::types::accel::{Accel, BuildQuality};
use relume_benches::scene;

fn main() {
    divan::main();
}

struct Setup {
    accel: Accel,
    cwbvh: CwBvh,
    tris: Vec<Triangle>,
    rays: Vec<(Vec3, Vec3)>,
    shadow: Vec<(Vec3, Vec3, f32)>,
}

fn setup() -> Setup {
    let s = scene("cornell-bunny", Some(256));
    let accel = Accel::build(&s, BuildQuality::Medium);
    let tris: Vec<Triangle> = (0..s.triangles.len())
        .map(|t| {
            let [a, b, c] = s.corners(t).map(Vec3A::from);
            Triangle { v0: a, v1: b, v2: c }
        })
        .collect();
    let cwbvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Default::default());
    let cam = CameraRays::new(&s.camera);
    let rays: Vec<(Vec3, Vec3)> = (0..256 * 256).map(|i| cam.ray((i % 256) as f32 + 0.5, (i / 256) as f32 + 0.5)).collect();
    let light = Vec3::new(0.0, 0.98, 0.01);
    let shadow = rays
        .iter()
        .filter_map(|&(o, d)| accel.intersect(o, d, 0.0, f32::INFINITY).map(|h| o + d * h.t * 0.9999))
        .map(|p| {
            let to = light - p;
            (p, to.normalize(), to.length())
        })
        .collect();
    Setup { accel, cwbvh, tris, rays, shadow }
}

#[divan::bench(sample_count = 20)]
fn closest_hit_single_thread(bencher: divan::Bencher) {
    let s = setup();
    bencher
        .counter(ItemsCount::new(s.rays.len()))
        .bench_local(|| s.rays.iter().filter(|(o, d)| s.accel.intersect(*o, *d, 0.0, f32::INFINITY).is_some()).count());
}

#[divan::bench(sample_count = 20)]
fn shadow_single_thread(bencher: divan::Bencher) {
    let s = setup();
    bencher
        .counter(ItemsCount::new(s.shadow.len()))
        .bench_local(|| s.shadow.iter().filter(|(o, d, t)| s.accel.occluded(*o, *d, 1e-4, *t)).count());
}

#[divan::bench(sample_count = 20)]
fn closest_hit_single_thread_obvhs(bencher: divan::Bencher) {
    let s = setup();
    bencher.counter(ItemsCount::new(s.rays.len())).bench_local(|| {
        s.rays
            .iter()
            .filter(|(o, d)| {
                let mut hit = RayHit::none();
                s.cwbvh.ray_traverse(Ray::new((*o).into(), (*d).into(), 0.0, f32::INFINITY), &mut hit, |r, id| {
                    s.tris[s.cwbvh.primitive_indices[id] as usize].intersect(r)
                })
            })
            .count()
    });
}

#[divan::bench(sample_count = 20)]
fn shadow_single_thread_obvhs(bencher: divan::Bencher) {
    let s = setup();
    bencher.counter(ItemsCount::new(s.shadow.len())).bench_local(|| {
        s.shadow
            .iter()
            .filter(|(o, d, t)| {
                !s.cwbvh.ray_traverse_miss(Ray::new((*o).into(), (*d).into(), 1e-4, *t), |r, id| {
                    s.tris[s.cwbvh.primitive_indices[id] as usize].intersect(r)
                })
            })
            .count()
    });
}
