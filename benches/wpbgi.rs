//! Wavelet PBGI on the ring (`graphs/wpbgi_ring.ron` at 256 × 256, 30,000 points, cube maps of
//! 6 × 16² as the graph has them): the gather from the coded tree (split level 8) against the same gather from the
//! uncoded tree (split 20: every node keeps its average; this tree is 15 levels deep) and
//! against classic PBGI on the same points, receivers and microbuffer. Prints, once, the
//! coded and uncoded bytes and the nodes rasterised per receiver; receivers/s is the
//! receiver count over a gather's time.

use relume_base::types::Metrics;
use relume_benches::{add_output, bench_graph, run_kind};
use relume_core::{Engine, RunOptions, Value};
use relume_pbgi::types::{CodedWavelets, Receivers};
use std::sync::OnceLock;

fn main() {
    divan::main();
}

struct Setup {
    tree: Value,
    receivers: Value,
    /// Coded at split 8, and at split 20 (uncoded at this depth).
    coded: Value,
    uncoded: Value,
}

fn setup() -> &'static Setup {
    static S: OnceLock<Setup> = OnceLock::new();
    S.get_or_init(|| {
        let reg = relume_cli::registry();
        let engine = Engine::new(relume_cli::registry());
        let mut g = bench_graph("wpbgi_ring.ron");
        for (o, port) in [("tree", "tree.tree"), ("receivers", "gbuffer.receivers"), ("coded", "coded.coded"), ("wavelets", "wavelets.wavelets")] {
            add_output(&mut g, o, port);
        }
        let outputs = ["tree", "receivers", "coded", "wavelets", "stats"].map(String::from).to_vec();
        let r = engine.run(&g, &RunOptions { outputs: Some(outputs), ..Default::default() }).unwrap();
        let out = |o: &str| r.output(o).unwrap().clone();
        g.set_param_text(&reg, "coded.split", "20").unwrap();
        let u = engine.run(&g, &RunOptions { outputs: Some(vec!["coded".into()]), ..Default::default() }).unwrap();
        let s = Setup { tree: out("tree"), receivers: out("receivers"), coded: out("coded"), uncoded: u.output("coded").unwrap().clone() };
        let bytes = |v: &Value| v.get::<CodedWavelets>().unwrap().tree.bytes();
        let stats = out("stats");
        let plain = run_kind("PbgiGather", &[s.tree.clone(), s.receivers.clone()]);
        eprintln!(
            "ring: {} receivers; coded tree {} B (split 8) against {} B (split 20, uncoded); rasterised per receiver: wavelet {:.1}, classic {:.1}",
            s.receivers.get::<Receivers>().unwrap().len(),
            bytes(&s.coded),
            bytes(&s.uncoded),
            stats.get::<Metrics>().unwrap().get("nodes_rasterised_per_receiver").unwrap(),
            plain[1].get::<Metrics>().unwrap().get("nodes_rasterised_per_receiver").unwrap(),
        );
        s
    })
}

#[divan::bench(sample_count = 3)]
fn wavelet_gather_coded(bencher: divan::Bencher) {
    let s = setup();
    bencher.bench_local(|| run_kind("WaveletGather", &[s.tree.clone(), s.coded.clone(), s.receivers.clone()]));
}

#[divan::bench(sample_count = 3)]
fn wavelet_gather_uncoded(bencher: divan::Bencher) {
    let s = setup();
    bencher.bench_local(|| run_kind("WaveletGather", &[s.tree.clone(), s.uncoded.clone(), s.receivers.clone()]));
}

#[divan::bench(sample_count = 3)]
fn classic_pbgi_gather(bencher: divan::Bencher) {
    let s = setup();
    bencher.bench_local(|| run_kind("PbgiGather", &[s.tree.clone(), s.receivers.clone()]));
}
