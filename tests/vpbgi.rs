//! View-tree PBGI on the Cornell box (`graphs/vpbgi_cornell.ron`): a second bounce brings the
//! image closer to the path tracer at max_depth 4, and which nodes an edit of `bounces`
//! re-runs.

use relume_nodes::types::{Image, Metrics};
use relume_tests::{engine, load_graph, ran, run, run_outputs};

/// `vpbgi_cornell.ron` at `size`² with `count` points.
fn vpbgi_graph(size: usize, count: usize, spp: usize) -> relume_core::Graph {
    let (size, count, spp) = (size.to_string(), count.to_string(), spp.to_string());
    load_graph(
        "vpbgi_cornell.ron",
        &[
            ("scene.width", &size),
            ("scene.height", &size),
            ("points.count", &count),
            ("direct.pixel_samples", "4"),
            ("reference.spp", &spp),
            ("pt.spp", "4"),
        ],
    )
}

#[test]
fn the_second_bounce_brings_the_image_toward_the_path_tracer_at_max_depth_4() {
    let g = vpbgi_graph(32, 8000, 256);
    let r = run_outputs(&engine(), &g, &["image", "one_bounce", "reference", "vpbgi_error", "wpbgi_error", "views"]);
    let img = |n: &str| r.output(n).unwrap().get::<Image>().unwrap().clone();
    let m = |n: &str, k: &str| r.output(n).unwrap().get::<Metrics>().unwrap().get(k).unwrap();
    let mean = |i: &Image| i.pixels.iter().map(|p| (p[0] + p[1] + p[2]) as f64).sum::<f64>() / i.pixels.len() as f64;
    let (two, one, reference) = (mean(&img("image")), mean(&img("one_bounce")), mean(&img("reference")));
    assert!(img("image").as_floats().iter().all(|x| x.is_finite() && *x >= 0.0));
    // The second bounce adds light, and the image's mean lies within 5 % of the reference's.
    assert!(two > one, "two bounces {two}, one {one}");
    assert!(((two - reference) / reference).abs() < 0.05, "two bounces {two}, the path tracer {reference}");
    assert!(m("vpbgi_error", "mse") < m("wpbgi_error", "mse"), "the second bounce lowers the error");
    assert!(m("views", "pairs_per_point") > 0.0);
}

#[test]
fn changing_bounces_reruns_the_view_tree_onward_only() {
    let reg = relume_nodes::registry();
    let mut g = vpbgi_graph(16, 2000, 4);
    let e = engine();
    run(&e, &g);
    g.set_param_text(&reg, "views.bounces", "2").unwrap();
    let onward = ["gather", "preview", "preview_error", "views", "vpbgi_error", "vpbgi_image"];
    assert_eq!(ran(&run(&e, &g)), onward);
    g.set_param_text(&reg, "views.view_threshold", "0.01").unwrap();
    assert_eq!(ran(&run(&e, &g)), onward);
}
