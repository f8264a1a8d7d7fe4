//! View-tree PBGI on the Cornell box (`graphs/vpbgi_cornell.ron` as the graph has it: 10,000
//! points, 6 × 8² maps, 8² microbuffers, view threshold 0.08 sr): every point gathering the light of the coded
//! tree, through the view tree (receiver and sender nodes paired, group buffers reused)
//! against each point traversing the tree from the root on its own: the traversal alone
//! (each point's buffer reduced to its irradiance), and the whole `ViewTree` node (one
//! bounce: gathering, reflecting, coding again) with either walk. Prints, once, the pairs
//! decided and nodes rasterised per point by each walk.

use relume_base::math::frame::Frame;
use relume_benches::{add_output, bench_graph};
use relume_core::{CancelToken, Engine, RunCtx, RunOptions, Value};
use relume_pbgi::microbuffer::Microbuffer;
use relume_pbgi::traversal::tree_extent;
use relume_pbgi::types::{CodedWavelets, PointTree};
use relume_pbgi::view_walk::{ViewWalk, WalkCounts};
use relume_pbgi::wavelet_radiance::WaveletSource;
use std::sync::OnceLock;

fn main() {
    divan::main();
}

struct Setup {
    tree: Value,
    points: Value,
    wavelets: Value,
    coded: Value,
}

fn setup() -> &'static Setup {
    static S: OnceLock<Setup> = OnceLock::new();
    S.get_or_init(|| {
        let engine = Engine::new(relume_cli::registry());
        let mut g = bench_graph("vpbgi_cornell.ron");
        for (o, port) in [("tree", "tree.tree"), ("points", "points.points"), ("wavelets", "wavelets.wavelets"), ("coded", "coded.coded")] {
            add_output(&mut g, o, port);
        }
        let outputs = ["tree", "points", "wavelets", "coded"].map(String::from).to_vec();
        let r = engine.run(&g, &RunOptions { outputs: Some(outputs), ..Default::default() }).unwrap();
        let out = |o: &str| r.output(o).unwrap().clone();
        let s = Setup { tree: out("tree"), points: out("points"), wavelets: out("wavelets"), coded: out("coded") };
        let (_, view) = walk(&s, false);
        let (_, alone) = walk(&s, true);
        let n = s.tree.get::<PointTree>().unwrap().nodes.len().div_ceil(2) as f64;
        eprintln!(
            "cornell, {n} points: view tree {:.1} pairs and {:.1} nodes rasterised per point ({} group buffers), per receiver {:.1} and {:.1}",
            view.pairs as f64 / n,
            view.rasterised as f64 / n,
            view.group_buffers,
            alone.pairs as f64 / n,
            alone.rasterised as f64 / n
        );
        s
    })
}

/// Every point's irradiance (red) through one walk, and its counts.
fn walk(s: &Setup, per_receiver: bool) -> (f64, WalkCounts) {
    let (tree, coded) = (s.tree.get::<PointTree>().unwrap(), s.coded.get::<CodedWavelets>().unwrap());
    let source = WaveletSource::new(tree, coded);
    let w = ViewWalk {
        tree,
        source: &source,
        resolution: 8,
        threshold: 1.0,
        view_omega: 0.08,
        reuse_cos: 5f32.to_radians().cos(),
        eps: 1e-5 * tree_extent(tree),
    };
    let cancel = CancelToken::new();
    let cx = RunCtx::new("bench", &cancel, None);
    let irradiance = |_: u32, mb: &Microbuffer, _: &Frame| mb.radiance().iter().map(|l| l.x as f64).sum::<f64>();
    let (out, counts) = if per_receiver { w.run_per_receiver(&cx, &irradiance) } else { w.run(&cx, &irradiance) }.unwrap();
    (out.iter().map(|(_, e)| e).sum(), counts)
}

#[divan::bench(sample_count = 5)]
fn traversal_view_tree(bencher: divan::Bencher) {
    let s = setup();
    bencher.bench_local(|| walk(s, false));
}

#[divan::bench(sample_count = 5)]
fn traversal_per_receiver(bencher: divan::Bencher) {
    let s = setup();
    bencher.bench_local(|| walk(s, true));
}

/// One bounce of the `ViewTree` node at the graph's settings, through `walk`.
fn bounce(s: &Setup, walk: &str) -> Vec<Value> {
    use relume_core::ParamValue::{Float, Ident, Int};
    let params = [("resolution", Int(8)), ("split", Int(8)), ("view_threshold", Float(0.08)), ("walk", Ident(walk.into()))];
    let inputs = [s.tree.clone(), s.points.clone(), s.wavelets.clone()];
    relume_core::run_kind(&relume_cli::registry(), "ViewTree", &params, &relume_benches::graphs_dir(), &inputs).unwrap().outputs
}

#[divan::bench(sample_count = 3)]
fn bounce_view_tree(bencher: divan::Bencher) {
    let s = setup();
    bencher.bench_local(|| bounce(s, "ViewTree"));
}

#[divan::bench(sample_count = 3)]
fn bounce_per_receiver(bencher: divan::Bencher) {
    let s = setup();
    bencher.bench_local(|| bounce(s, "PerReceiver"));
}
