//! Path-tracer throughput on `cornell` at 256 × 256, max_depth −1, on 1 and 2 threads
//! (samples per second = pixels × spp / time). Compare with Mitsuba 3's scalar_rgb on the same
//! machine with `benches/scripts/mitsuba_cornell.py`.

use divan::counter::ItemsCount;
use relume_base::reference::path_trace::{render, PathTrace};
use relume_base::types::accel::{Accel, BuildQuality};
use relume_benches::scene;

fn main() {
    divan::main();
}

const SPP: u32 = 8;

#[divan::bench(args = [1, 2], sample_count = 5)]
fn cornell_256(bencher: divan::Bencher, threads: usize) {
    let s = scene("cornell", Some(256));
    let accel = Accel::build(&s, BuildQuality::Medium);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
    let p = PathTrace { spp: SPP, max_depth: -1, min_depth: 1, rr_depth: 5, seed: 0, fresnel_reflection: true };
    bencher.counter(ItemsCount::new(256 * 256 * SPP as usize)).bench_local(|| pool.install(|| render(&s, &accel, &p, None).unwrap().2));
}
