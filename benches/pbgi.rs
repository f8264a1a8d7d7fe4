//! PbgiGather against FactorizedGather at equal microbuffer resolution and threshold, on
//! `cornell` and `cornell-bunny` at 256 × 256 with 100,000 points. The set-up is
//! `graphs/pbgi_vs_reference.ron` (points, shading, tree, G-buffer, clusters); the benchmark
//! times the two gather nodes on its outputs. Prints the MSE between the two indirect images
//! and the nodes rasterised per receiver of each (once, at start-up).

use relume_base::types::{Image, Metrics};
use relume_benches::{add_output, bench_graph, run_kind};
use relume_core::{Engine, RunOptions, Value};
use std::sync::OnceLock;

fn main() {
    divan::main();
}

/// The gathers' inputs for one scene: tree, receivers, clusters.
struct Setup {
    tree: Value,
    receivers: Value,
    clusters: Value,
}

fn setup(name: &str) -> &'static Setup {
    static CACHE: OnceLock<Vec<(String, &'static Setup)>> = OnceLock::new();
    let all = CACHE.get_or_init(|| {
        let reg = relume_cli::registry();
        let engine = Engine::new(relume_cli::registry());
        ["cornell", "cornell-bunny"]
            .iter()
            .map(|&name| {
                let mut g = bench_graph("pbgi_vs_reference.ron");
                g.set_param_text(&reg, "scene.path", &format!("scenes/{name}.ron")).unwrap();
                for (o, port) in [("tree", "tree.tree"), ("receivers", "gbuffer.receivers"), ("clusters", "clusters.clusters")] {
                    add_output(&mut g, o, port);
                }
                let outputs = ["tree", "receivers", "clusters", "pbgi_stats", "fpbgi_stats"].map(String::from).to_vec();
                let r = engine.run(&g, &RunOptions { outputs: Some(outputs), ..Default::default() }).unwrap();
                let out = |o: &str| r.output(o).unwrap().clone();
                let setup = Setup { tree: out("tree"), receivers: out("receivers"), clusters: out("clusters") };
                let stat = |o: &str| out(o).get::<Metrics>().unwrap().get("nodes_rasterised_per_receiver").unwrap();
                let plain = run_kind("PbgiGather", &[setup.tree.clone(), setup.receivers.clone()]);
                let fact = run_kind("FactorizedGather", &[setup.tree.clone(), setup.receivers.clone(), setup.clusters.clone()]);
                let (a, b) = (plain[0].get::<Image>().unwrap(), fact[0].get::<Image>().unwrap());
                let mse = a.as_floats().iter().zip(b.as_floats()).map(|(x, y)| ((x - y) as f64).powi(2)).sum::<f64>()
                    / a.as_floats().len() as f64;
                eprintln!(
                    "{name}: MSE(FPBGI, PBGI) = {mse:.3e}, rasterised per receiver: PBGI {:.1}, FPBGI {:.1}",
                    stat("pbgi_stats"),
                    stat("fpbgi_stats")
                );
                (name.to_string(), &*Box::leak(Box::new(setup)))
            })
            .collect()
    });
    all.iter().find(|(n, _)| n == name).map(|(_, s)| *s).expect("a scene set up above")
}

#[divan::bench(args = ["cornell", "cornell-bunny"], sample_count = 3)]
fn pbgi_gather(bencher: divan::Bencher, name: &str) {
    let s = setup(name);
    bencher.bench_local(|| run_kind("PbgiGather", &[s.tree.clone(), s.receivers.clone()]));
}

#[divan::bench(args = ["cornell", "cornell-bunny"], sample_count = 3)]
fn factorized_gather(bencher: divan::Bencher, name: &str) {
    let s = setup(name);
    bencher.bench_local(|| run_kind("FactorizedGather", &[s.tree.clone(), s.receivers.clone(), s.clusters.clone()]));
}
