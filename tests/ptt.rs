//! Pipeline 2 (precomputed transfer tensors) through its graph: each edit re-runs only what it
//! reaches, asserted from the run report.

use relume_base::types::Image;
use relume_core::{Engine, Graph, RunOptions};
use relume_tests::{load_test_graph, ran};

/// A pipeline-2 graph (`ptt_envlit.ron` or its Cook-Torrance variant) at test size.
fn small_ptt(name: &str) -> Graph {
    load_test_graph(
        name,
        &[
            ("scene.width", "24"),
            ("scene.height", "24"),
            ("reference.spp", "4"),
            ("hits.spp", "2"),
            ("vertex_reference.spp", "2"),
            ("ref_hits.spp", "2"),
        ],
    )
}

/// Runs `name` at test size, then orbits, edits the bunny's material with `material` (a
/// `node.param` and its value) and turns the sky, asserting what each edit re-runs.
fn edits_rerun_only_what_they_reach(name: &str, material: (&str, &str)) {
    let reg = relume_cli::registry();
    let e = Engine::new(relume_cli::registry());
    let mut g = small_ptt(name);
    let r = e.run(&g, &RunOptions::default()).unwrap();
    let img = r.output("image").unwrap().get::<Image>().unwrap().clone();
    assert_eq!((img.width, img.height, img.nonfinite_pixels()), (24, 24, 0));
    assert!(img.pixels.iter().any(|p| p[0] > 0.0), "the relit image is not black");
    let mut rerun = |param: &str, value: &str| {
        g.set_param_text(&reg, param, value).unwrap();
        ran(&e.run(&g, &RunOptions::default()).unwrap().report)
    };
    // Orbiting: the camera, what it sees, the shading and the rasteriser (the reference keeps
    // the scene's view).
    assert_eq!(rerun("camera.azimuth", "20"), ["camera", "error", "hits", "method_error", "raster", "relight"]);
    // The bunny's material: its projection, the incident light (the bounces carry it), the
    // shading onward, and the reference with the new material.
    let references = ["interpolation_error", "method_error", "reference", "vertex_raster", "vertex_reference"];
    let with = |nodes: &[&str]| {
        let mut v: Vec<String> = nodes.iter().chain(&references).map(|s| s.to_string()).collect();
        v.sort();
        v
    };
    assert_eq!(rerun(material.0, material.1), with(&["apply", "error", "incident", "project", "raster", "relight"]), "{name}");
    // Turning the sky: the environment's cube map and what reads it (the rasterisers read
    // the sky where the samples miss), never the transfer nor what the camera sees.
    assert_eq!(
        rerun("turn.rotation_deg", "45"),
        with(&["apply", "bounced", "direct", "env", "error", "incident", "raster", "relight", "turn"])
    );
}

#[test]
fn view_material_and_sky_edits_rerun_only_what_they_reach_never_the_transfer() {
    edits_rerun_only_what_they_reach("ptt_envlit.ron", ("project.s", "60"));
}

#[test]
fn the_cook_torrance_variant_reruns_the_same_nodes_for_a_roughness_edit() {
    edits_rerun_only_what_they_reach("ptt_envlit_ct.ron", ("project.m", "0.4"));
}

#[test]
fn the_bounce_graph_holds_the_cook_torrance_lobe_on_its_own_space_and_isolates_the_bounces() {
    let e = Engine::new(relume_cli::registry());
    let r = e.run(&small_ptt("ptt_envlit_ct_bounce.ron"), &RunOptions::default()).unwrap();
    // The material fitted on the Cook-Torrance space's basis and on the Blinn-Phong one's: the
    // first holds the microfacet lobe, the second cannot (its growth toward grazing).
    let fit = |id: &str| r.report.node(id).unwrap().metrics["fit_error_max_pct"];
    assert!(fit("project") < 0.5 * fit("project_bp"), "{} % against {} %", fit("project"), fit("project_bp"));
    // The bounce images: the light of the bounces alone, finite, not all black.
    for name in ["b_ct", "b_bp", "b_ref"] {
        let img = r.output(name).unwrap().get::<Image>().unwrap();
        assert_eq!(img.nonfinite_pixels(), 0, "{name}");
        assert!(img.pixels.iter().any(|p| p[0] > 0.0), "{name} holds some bounced light");
    }
    let m = |id: &str, k: &str| r.report.node(id).unwrap().metrics[k];
    assert!(m("bounce_error_ct", "l2_percent").is_finite() && m("bounce_error_bp", "l2_percent").is_finite());
}

#[test]
fn the_scene_scale_does_not_change_the_relit_image_from_a_thousandth_to_a_thousand() {
    // `envlit` scaled as a whole (ground, bunny, camera) under the same sky at infinity: the
    // visibility, the transfer and the camera's hits follow the scale, and the picture stays
    // (measured against the unscaled scene: relative L1 differences of 0.06 % at 10⁻³ and
    // 0.45 % at 10³).
    let dir = tempfile::tempdir().unwrap();
    // One engine: what does not depend on the scene (the BRDF tensor and basis) runs once.
    let e = Engine::new(relume_cli::registry());
    let at_scale = |s: f64| {
        let edits = [
            ("origin: (0, 1.2, 3.2), target: (0, 0.45, 0)", format!("origin: (0, {}, {}), target: (0, {}, 0)", 1.2 * s, 3.2 * s, 0.45 * s)),
            ("material: \"ground\")", format!("material: \"ground\", transform: [Scale({s})])")),
            ("transform: [Translate(", format!("transform: [Scale({s}), Translate(")),
        ];
        let path = relume_tests::edited_scene("envlit.ron", &s.to_string(), dir.path(), &edits);
        relume_tests::image_with_scene(&e, small_ptt("ptt_envlit.ron"), &path)
    };
    // The two ends against each other (each run of the precompute takes the time of the rest
    // of this file): six orders of magnitude apart, the same picture.
    let diff = relume_tests::relative_l1(&at_scale(1e3), &at_scale(1e-3));
    assert!(diff < 0.02, "10³ against 10⁻³: relative L1 difference {diff}");
}
