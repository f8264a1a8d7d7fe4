//! Spatially varying relighting's interactive step ([S] 4.2.3): `SvRelight` on cornell-spot at
//! 512 × 512 with 32 × 32 = 1024 sub-regions (the thesis' setting: 7 groups, 128 PCA
//! components each, 13.3 % of the Haar coefficients of every basis image), against the
//! thesis' 2.41 frames/s. The transfer is precomputed once at start-up with few paths (4
//! camera samples × 8 hemisphere rays: the combine's cost is set by the kept coefficients, a
//! fixed fraction, not by the paths). Also the plain relight's image combine alone, without
//! the bounce (`direct_only`), to say where the time goes.

use relume_base::types::{BrdfBasis, ObjectMaterials};
use relume_benches::{add_output, bench_graph, sized};
use relume_core::{Engine, RunOptions};
use relume_relight::sv_relight::sv_relight;
use relume_relight::types::SvTransfer;
use std::sync::OnceLock;

fn main() {
    divan::main();
}

fn setup() -> &'static (SvTransfer, BrdfBasis, ObjectMaterials) {
    static S: OnceLock<(SvTransfer, BrdfBasis, ObjectMaterials)> = OnceLock::new();
    S.get_or_init(|| {
        let reg = relume_cli::registry();
        let mut g = bench_graph("relight_sv_spot.ron");
        for (k, v) in [
            ("scene.width", sized("512", "64")),
            ("scene.height", sized("512", "64")),
            ("transfer.spp", "4"),
            ("transfer.bounce_rays", "8"),
        ] {
            g.set_param_text(&reg, k, v).unwrap();
        }
        add_output(&mut g, "transfer", "transfer.transfer");
        add_output(&mut g, "basis", "pca.basis");
        let outputs = ["transfer", "basis", "materials"].map(String::from).to_vec();
        let r = Engine::new(reg).run(&g, &RunOptions { outputs: Some(outputs), ..Default::default() }).unwrap();
        let t = r.output("transfer").unwrap().get::<SvTransfer>().unwrap().clone();
        let b = r.output("basis").unwrap().get::<BrdfBasis>().unwrap().clone();
        let m = r.output("materials").unwrap().get::<ObjectMaterials>().unwrap().clone();
        let kept: usize = t.blocks.iter().flat_map(|b| &b.images).map(|p| p.index.len()).sum();
        eprintln!(
            "SV transfer: {} groups × {} components, {kept} Haar coefficients kept, {:.1} MiB",
            t.blocks.len(),
            t.blocks.first().map_or(0, |b| b.components),
            t.bytes() as f64 / (1 << 20) as f64
        );
        (t, b, m)
    })
}

#[divan::bench(sample_count = 10)]
fn sv_relight_512_1024_sub_regions(bencher: divan::Bencher) {
    let (t, b, m) = setup();
    bencher.bench(|| sv_relight(t, b, m, None).unwrap());
}

#[divan::bench(sample_count = 10)]
fn direct_only(bencher: divan::Bencher) {
    let (t, b, m) = setup();
    let mut direct = t.clone();
    direct.blocks.clear();
    bencher.bench(|| sv_relight(&direct, b, m, None).unwrap());
}
