//! PbgiGather against FactorizedGather at equal microbuffer resolution and threshold, on
//! `cornell` and `cornell-bunny` at 256 × 256 with 100,000 points. Prints the MSE between the
//! two indirect images and the nodes rasterised per receiver of each (once, at start-up).

use relume_benches::scene;
use relume_nodes::geometry::accel::{Accel, BuildQuality};
use relume_nodes::geometry::sample_surface::{sample_surface, Method, SampleSurfaceParams};
use relume_nodes::image::image_error::error_metrics;
use relume_nodes::pbgi::cluster_receivers::{cluster_receivers, ClusterReceiversParams, Clusters};
use relume_nodes::pbgi::factorized_gather::{factorized_gather, FactorizedGatherParams};
use relume_nodes::pbgi::gbuffer::gbuffer;
use relume_nodes::pbgi::pbgi_gather::{gather, PbgiGatherParams};
use relume_nodes::pbgi::point_tree::PointTree;
use relume_nodes::pbgi::shade_direct::{shade_direct, ShadeDirectParams};
use relume_nodes::types::Receivers;
use std::sync::OnceLock;

fn main() {
    divan::main();
}

const RES: usize = 16;

struct Setup {
    tree: PointTree,
    receivers: Receivers,
    clusters: Clusters,
    extent: f32,
}

fn setup(name: &str) -> &'static Setup {
    static CACHE: OnceLock<Vec<(String, &'static Setup)>> = OnceLock::new();
    let all = CACHE.get_or_init(|| {
        ["cornell", "cornell-bunny"]
            .iter()
            .map(|&name| {
                let s = scene(name, Some(256));
                let accel = Accel::build(&s, BuildQuality::Medium);
                let pts =
                    sample_surface(&s, &SampleSurfaceParams { method: Method::AreaCdf, count: 100_000, seed: 7, emitters: false }).unwrap();
                let (b, _) = shade_direct(&s, &accel, &pts, &ShadeDirectParams { samples: 16, seed: 1 });
                let tree = PointTree::build(&pts, &b);
                let receivers = gbuffer(&s, &accel);
                let clusters =
                    cluster_receivers(&receivers, &ClusterReceiversParams { tile: 32, k: 100, iterations: 10, seed: 3 }, None).unwrap().0;
                let setup: &'static Setup = Box::leak(Box::new(Setup { tree, receivers, clusters, extent: s.extent() }));
                let (a, ca) = gather(&setup.tree, &setup.receivers, &PbgiGatherParams { resolution: RES, threshold: 1.0 }, setup.extent);
                let (f, cf) = factorized_gather(
                    &setup.tree,
                    &setup.receivers,
                    &setup.clusters,
                    &FactorizedGatherParams { resolution: RES, threshold: 1.0, epsilon: 1.0 },
                    setup.extent,
                );
                let m = error_metrics(&f, &a, 1.0, 0.01);
                let n = setup.receivers.len() as f64;
                eprintln!(
                    "{name}: MSE(FPBGI, PBGI) = {:.3e}, rasterised per receiver: PBGI {:.1}, FPBGI {:.1}",
                    m.get("mse").unwrap(),
                    ca.rasterised as f64 / n,
                    cf.rasterised as f64 / n
                );
                (name.to_string(), setup)
            })
            .collect()
    });
    all.iter().find(|(n, _)| n == name).map(|(_, s)| *s).expect("a scene set up above")
}

#[divan::bench(args = ["cornell", "cornell-bunny"], sample_count = 3)]
fn pbgi_gather(bencher: divan::Bencher, name: &str) {
    let s = setup(name);
    bencher.bench_local(|| gather(&s.tree, &s.receivers, &PbgiGatherParams { resolution: RES, threshold: 1.0 }, s.extent).1.rasterised);
}

#[divan::bench(args = ["cornell", "cornell-bunny"], sample_count = 3)]
fn factorized_gather_(bencher: divan::Bencher, name: &str) {
    let s = setup(name);
    bencher.bench_local(|| {
        factorized_gather(
            &s.tree,
            &s.receivers,
            &s.clusters,
            &FactorizedGatherParams { resolution: RES, threshold: 1.0, epsilon: 1.0 },
            s.extent,
        )
        .1
        .rasterised
    });
}
