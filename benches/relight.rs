//! Pixel relighting's interactive step: `Relight` on the cornell-bunny transfer at 512 × 512
//! (two dynamic objects, N_b = 6: 55 grey + 29 RGB images, 144 floats a pixel with padding,
//! 144 MiB) against a plain parallel memory copy of the same bytes on the same threads — the
//! combine reads every stored float once, so memory bandwidth bounds it. The transfer is
//! precomputed once at start-up with few paths (its values do not change the combine's cost).
//! The book's table of it (recorded by `benches/scripts/record_bench.py relight relight`) divides
//! each median by the copy's, both from one run.

use rayon::prelude::*;
use relume_base::types::ObjectMaterials;
use relume_benches::{add_output, bench_graph, sized};
use relume_core::{Engine, RunOptions};
use relume_relight::relight_pixels::relight;
use relume_relight::types::Transfer;
use std::sync::OnceLock;

fn main() {
    divan::main();
}

fn setup() -> &'static (Transfer, ObjectMaterials) {
    static S: OnceLock<(Transfer, ObjectMaterials)> = OnceLock::new();
    S.get_or_init(|| {
        let reg = relume_cli::registry();
        let mut g = bench_graph("relight_cornell_bunny.ron");
        for (k, v) in [
            ("scene.width", sized("512", "32")),
            ("scene.height", sized("512", "32")),
            ("transfer.spp", "1"),
            ("transfer.bounce_rays", "1"),
        ] {
            g.set_param_text(&reg, k, v).unwrap();
        }
        add_output(&mut g, "transfer", "transfer.transfer");
        let outputs = ["transfer", "materials"].map(String::from).to_vec();
        let r = Engine::new(reg).run(&g, &RunOptions { outputs: Some(outputs), ..Default::default() }).unwrap();
        let t = r.output("transfer").unwrap().get::<Transfer>().unwrap().clone();
        let m = r.output("materials").unwrap().get::<ObjectMaterials>().unwrap().clone();
        eprintln!(
            "transfer: {} images, {} floats a pixel, {:.1} MiB",
            t.terms.len(),
            t.stride,
            t.data.len() as f64 * 4.0 / (1 << 20) as f64
        );
        (t, m)
    })
}

#[divan::bench(sample_count = 20)]
fn relight_512(bencher: divan::Bencher) {
    let (t, m) = setup();
    bencher.bench(|| relight(t, m, None).unwrap());
}

#[divan::bench(sample_count = 20)]
fn memcpy_same_bytes(bencher: divan::Bencher) {
    let (t, _) = setup();
    let mut dst = vec![0.0f32; t.data.len()];
    let row = t.width as usize * t.stride as usize;
    bencher.bench_local(|| {
        dst.par_chunks_mut(row).zip(t.data.par_chunks(row)).for_each(|(d, s)| d.copy_from_slice(s));
        divan::black_box(&dst);
    });
}
