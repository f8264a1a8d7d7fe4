//! What two small graphs of graphs/ compute is sensible. (That every graph runs with finite
//! outputs is checked by `determinism.rs`, in the same pass that compares thread counts.)

use relume_base::types::{Image, Metrics};
use relume_core::{Graph, RunOptions};
use relume_tests::{engine, graphs_dir};

#[test]
fn the_median_filter_lowers_the_error_of_the_noisy_render_in_image_error_ron() {
    let g = Graph::load(&graphs_dir().join("image_error.ron"), &relume_cli::registry()).unwrap();
    let r = engine().run(&g, &RunOptions::default()).unwrap();
    let m = |name: &str| r.output(name).unwrap().get::<Metrics>().unwrap().clone();
    let (raw, denoised) = (m("metrics"), m("metrics_denoised"));
    // Uniform noise of amplitude 0.3 has variance 0.3²/12 = 0.0075 per channel.
    assert!((raw.get("mse").unwrap() - 0.0075).abs() < 0.0005, "{raw:?}");
    assert!(denoised.get("mse").unwrap() < 0.5 * raw.get("mse").unwrap(), "{denoised:?}");
    assert!(denoised.get("psnr_db").unwrap() > raw.get("psnr_db").unwrap() + 3.0);
    assert_eq!(r.report.node("error").unwrap().metrics["mse"], raw.get("mse").unwrap(), "the report carries the metrics");
}

#[test]
fn the_filters_graph_denoises_its_checkerboard() {
    let g = Graph::load(&graphs_dir().join("filters.ron"), &relume_cli::registry()).unwrap();
    let r = engine().run(&g, &RunOptions::default()).unwrap();
    let m = r.output("metrics").unwrap().get::<Metrics>().unwrap();
    // Noise of amplitude 0.4 alone has MSE 0.4²/12 ≈ 0.0133; the filters must not make it worse
    // by more than the edge blur costs, and the error must be finite and positive.
    let mse = m.get("mse").unwrap();
    assert!(mse > 0.0 && mse < 0.03, "{mse}");
    let img = r.output("image").unwrap().get::<Image>().unwrap();
    assert!(img.as_floats().iter().all(|x| (0.0..=1.0).contains(x)), "tone-mapped values lie in [0, 1]");
}
