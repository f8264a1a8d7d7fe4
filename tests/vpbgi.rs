//! View-tree PBGI on the Cornell box (`graphs/vpbgi_cornell.ron`): a second bounce brings the
//! image closer to the path tracer at max_depth 4, and which nodes an edit of `bounces`
//! re-runs; through the glass sphere (`graphs/vpbgi_glass.ron`): the caustic and the floor
//! seen through it.

use relume_base::types::{Image, Metrics};
use relume_tests::{engine, load_graph, ran, region_sum, run, run_outputs};

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
fn the_floor_of_two_bounces_keeps_to_the_path_tracers_within_one_percent() {
    // `vpbgi_cornell.ron` as it ships (10,000 points, 8² buffers, the gathers' nodes smaller
    // than a pixel whole in the pixel that holds them, every fourth pixel of every fourth row
    // gathered where the surface is smooth) at its own 256², against the path
    // tracer at max_depth 4 (256 spp: the floor's mean over its ten thousand pixels moves by
    // less than 0.1 % from 1,024). Measured: the floor (object 0, whole pixels) 0.990 / 1.009 /
    // 1.003 of the path tracer's, gathering at every pixel or not; with the gathers' bilinear
    // spread (`splat: Bilinear`) red is 0.982, 1.8 % under, and this test fails.
    use relume_pbgi::types::Receivers;
    let mut g = load_graph("vpbgi_cornell.ron", &[("reference.spp", "256")]);
    relume_tests::add_output(&mut g, "receivers", "gbuffer.receivers");
    let r = run_outputs(&engine(), &g, &["image", "reference", "receivers"]);
    let img = |n: &str| r.output(n).unwrap().get::<Image>().unwrap().clone();
    let receivers = r.output("receivers").unwrap().get::<Receivers>().unwrap().clone();
    // Each whole pixel's object: its receiver's, or for a pixel filled from others theirs.
    let mut object = vec![u32::MAX; receivers.width * receivers.height];
    for k in (0..receivers.len()).filter(|&k| receivers.weight[k] == 1.0) {
        object[receivers.pixel[k] as usize] = receivers.object[k];
    }
    for f in &receivers.fill {
        object[f.pixel as usize] = object[f.from[0] as usize];
    }
    let floor = |i: &Image| {
        let pixels: Vec<usize> = (0..object.len()).filter(|&p| object[p] == 0).collect();
        assert!(pixels.len() > 5000, "the floor holds {} pixels", pixels.len());
        [0, 1, 2].map(|c| pixels.iter().map(|&p| i.pixels[p][c] as f64).sum::<f64>() / pixels.len() as f64)
    };
    let (ours, theirs) = (floor(&img("image")), floor(&img("reference")));
    for c in 0..3 {
        let ratio = ours[c] / theirs[c];
        assert!((ratio - 1.0).abs() < 0.01, "channel {c}: the floor at {ratio} × the path tracer's");
    }
}

#[test]
fn a_strided_gbuffer_gathers_a_third_of_the_receivers_at_the_same_error() {
    // `vpbgi_cornell.ron` at 128² (8,000 points), the gather at every pixel against every
    // fourth pixel of every fourth row where the surface is smooth (the rest filled from
    // cells around them). Measured: 17,007 receivers and rel. MSE 1.8208e-3 against 5,898 and
    // 1.8267e-3; at the graph's 256², 1.494e-3 against 1.458e-3 with 22 % of the receivers.
    let at = |stride: &str| {
        let mut g = load_graph(
            "vpbgi_cornell.ron",
            &[
                ("scene.width", "128"),
                ("scene.height", "128"),
                ("points.count", "8000"),
                ("reference.spp", "256"),
                ("gbuffer.stride", stride),
            ],
        );
        relume_tests::add_output(&mut g, "stats", "gather.stats");
        let r = run_outputs(&engine(), &g, &["vpbgi_error", "stats"]);
        let m = |n: &str, k: &str| r.output(n).unwrap().get::<Metrics>().unwrap().get(k).unwrap();
        (m("vpbgi_error", "rel_mse"), m("stats", "receivers"))
    };
    let ((e1, n1), (e4, n4)) = (at("1"), at("4"));
    assert!(n4 < 0.4 * n1, "{n4} receivers against {n1}");
    assert!(e4 < 1.02 * e1, "rel. MSE {e4} against {e1}");
}

#[test]
fn changing_bounces_reruns_the_view_tree_onward_only() {
    let reg = relume_cli::registry();
    let mut g = vpbgi_graph(16, 2000, 4);
    let e = engine();
    run(&e, &g);
    g.set_param_text(&reg, "views.bounces", "2").unwrap();
    let onward = ["gather", "preview", "preview_error", "views", "vpbgi_error", "vpbgi_image"];
    assert_eq!(ran(&run(&e, &g)), onward);
    g.set_param_text(&reg, "views.view_threshold", "0.01").unwrap();
    assert_eq!(ran(&run(&e, &g)), onward);
}

#[test]
fn through_the_glass_sphere_the_points_carry_the_lamps_caustic_and_the_floor_behind() {
    // `vpbgi_glass.ron` at 64²: the caustic lies on the floor under the sphere, toward the
    // camera (x 0.23–0.40, y 0.54–0.67 of the image). Its energy there comes only through the
    // glass: none with the direct light alone (bounces 0), and with two bounces within a
    // stated tolerance of the path tracer's at max_depth 5.
    let g = |bounces: &str| {
        load_graph(
            "vpbgi_glass.ron",
            &[
                ("scene.width", "64"),
                ("scene.height", "64"),
                ("direct.pixel_samples", "4"),
                ("views.bounces", bounces),
                ("reference.spp", "1024"),
            ],
        )
    };
    let e = engine();
    let two = run_outputs(&e, &g("2"), &["image", "reference"]);
    let zero = run_outputs(&e, &g("0"), &["image"]);
    let img = |r: &relume_core::RunResult, n: &str| r.output(n).unwrap().get::<Image>().unwrap().clone();
    let (with, without, reference) = (img(&two, "image"), img(&zero, "image"), img(&two, "reference"));
    assert!(with.as_floats().iter().all(|x| x.is_finite() && *x >= 0.0));
    let caustic = |i: &Image| region_sum(i, [0.23, 0.40], [0.54, 0.67]);
    let glass = |i: &Image| region_sum(i, [0.3, 0.7], [0.25, 0.5]);
    let (c2, c0, cr) = (caustic(&with), caustic(&without), caustic(&reference));
    // Measured: 156.7 with two bounces, 0.1 with the direct light alone (the region lies in
    // the sphere's shadow), 182.9 for the path tracer at 1,024 spp: 0.86 of it (0.86 against
    // 4,096 spp too, which costs the test 9 s more). (Before the inner twins
    // had their own subtree, their light leaked out of the glass: 105.6 without a bounce and
    // 257.1, 1.40x, with two.)
    assert!(c0 < 0.01 * cr, "caustic region: direct light alone {c0}, the path tracer {cr}");
    assert!(c2 > 0.75 * cr && c2 < 1.25 * cr, "caustic region: two bounces {c2}, the path tracer {cr}");
    // The sphere's upper half shows the floor behind it only through the bounces: measured
    // 104.2 against 1.3 without, and 101.9 for the path tracer (0.62 of it before the twins'
    // subtree, the coverage-normalised Dirac reads and their gap filling).
    let (g2, g0, gr) = (glass(&with), glass(&without), glass(&reference));
    assert!(g2 > 20.0 * g0 && (g2 / gr - 1.0).abs() < 0.2, "glass: two bounces {g2}, none {g0}, the path tracer {gr}");
}
