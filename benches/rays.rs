//! Ray throughput on cornell-bunny (69k-triangle bunny in the box): closest-hit camera rays,
//! and shadow rays from their hit points to the light's centre (stopping at the first hit).

use divan::counter::ItemsCount;
use glam::Vec3;
use relume_base::render::camera::CameraRays;
use relume_base::types::accel::{Accel, BuildQuality};
use relume_benches::scene;

fn main() {
    divan::main();
}

struct Setup {
    accel: Accel,
    rays: Vec<(Vec3, Vec3)>,
    shadow: Vec<(Vec3, Vec3, f32)>,
}

fn setup() -> Setup {
    let s = scene("cornell-bunny", Some(256));
    let accel = Accel::build(&s, BuildQuality::Medium);
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
    Setup { accel, rays, shadow }
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
