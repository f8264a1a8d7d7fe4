//! The bidirectional path tracer against the unidirectional one on cornell, ring and glass at
//! 128 × 128, max_depth −1, two threads: samples per second of each (pixels × spp / time).
//! Before the timed cases (under `cargo bench`) it prints, from one run of each at 16 samples per pixel, the mean
//! per-pixel variance of the mean and the time, and their product's ratio (the path tracer's
//! over the bidirectional one's): how many times sooner the bidirectional tracer reaches the
//! same error, both being unbiased.

use divan::counter::ItemsCount;
use relume_base::reference::bidir_path_trace;
use relume_base::reference::path_trace::{self, PathTrace};
use relume_base::render::bidir::BidirSettings;
use relume_base::types::accel::{Accel, BuildQuality};
use relume_base::types::{Image, Scene};
use relume_benches::scene;
use std::time::Instant;

const SIZE: usize = 128;
const SPP: u32 = 16;
const SCENES: [&str; 3] = ["cornell", "ring", "glass"];

fn main() {
    // `cargo bench` passes --bench; the test run only checks that the cases run.
    if std::env::args().any(|a| a == "--bench") {
        compare();
    }
    divan::main();
}

fn compare() {
    for name in SCENES {
        let (s, accel) = setup(name);
        let pool = pool();
        let t0 = Instant::now();
        let (_, bv) = pool.install(|| bidir(&s, &accel));
        let tb = t0.elapsed().as_secs_f64();
        let t0 = Instant::now();
        let (_, pv) = pool.install(|| path(&s, &accel));
        let tp = t0.elapsed().as_secs_f64();
        let (vb, vp) = (mean_variance(&bv), mean_variance(&pv));
        eprintln!(
            "{name}: bidirectional variance {vb:.4e} in {tb:.3} s, path tracer {vp:.4e} in {tp:.3} s; time to equal error, path tracer / bidirectional: {:.2}",
            vp * tp / (vb * tb)
        );
    }
}

fn setup(name: &str) -> (Scene, Accel) {
    let s = scene(name, Some(SIZE));
    let accel = Accel::build(&s, BuildQuality::Medium);
    (s, accel)
}

fn pool() -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new().num_threads(2).build().unwrap()
}

fn bidir(s: &Scene, accel: &Accel) -> (Image, Image) {
    let settings = BidirSettings { max_depth: -1, min_depth: 1, rr_depth: 5, seed: 0, only: None, fresnel_reflection: true };
    let (m, v, _) = bidir_path_trace::render(s, accel, settings, SPP, None).unwrap();
    (m, v)
}

fn path(s: &Scene, accel: &Accel) -> (Image, Image) {
    let (m, v, _, _) = path_trace::render(
        s,
        accel,
        &PathTrace { spp: SPP, max_depth: -1, min_depth: 1, rr_depth: 5, seed: 0, fresnel_reflection: true },
        None,
    )
    .unwrap();
    (m, v)
}

/// The per-pixel variance of the mean, averaged over pixels and channels.
fn mean_variance(v: &Image) -> f64 {
    v.as_floats().iter().map(|&x| x as f64).sum::<f64>() / v.as_floats().len() as f64
}

#[divan::bench(args = SCENES, sample_count = 5)]
fn bidirectional(bencher: divan::Bencher, name: &str) {
    let (s, accel) = setup(name);
    let pool = pool();
    bencher.counter(ItemsCount::new(SIZE * SIZE * SPP as usize)).bench_local(|| pool.install(|| bidir(&s, &accel)));
}

#[divan::bench(args = SCENES, sample_count = 5)]
fn path_tracer(bencher: divan::Bencher, name: &str) {
    let (s, accel) = setup(name);
    let pool = pool();
    bencher.counter(ItemsCount::new(SIZE * SIZE * SPP as usize)).bench_local(|| pool.install(|| path(&s, &accel)));
}
