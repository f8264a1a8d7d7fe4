//! A long render shown as it goes: the path tracer sends each band of rows pass by pass and
//! each finished chunk; the runner composes them into the image so far, which the viewer shows
//! (marked partial) until the run ends; composed from every chunk, it is the final image.

use relume_editor::EditorApp;
use std::time::{Duration, Instant};

mod common;
use common::*;

/// The cornell box path-traced at 128 × 96: three chunks of 32 rows.
fn graph(spp: u32) -> String {
    format!(
        r#"Graph(
    version: 1,
    nodes: {{
        "scene": (kind: "LoadScene", params: (path: "{}/scenes/cornell.ron", width: 128, height: 96)),
        "bvh": (kind: "BuildBvh", params: ()),
        "pt": (kind: "PathTrace", params: (spp: {spp}, max_depth: 4, seed: 3)),
    }},
    edges: [("scene.scene", "bvh.scene"), ("scene.scene", "pt.scene"), ("bvh.accel", "pt.accel")],
    outputs: {{"image": "pt.image", "variance": "pt.variance"}},
)
"#,
        graphs().display()
    )
}

fn open(dir: &std::path::Path, spp: u32) -> EditorApp {
    let path = dir.join("pt.ron");
    std::fs::write(&path, graph(spp)).unwrap();
    let mut app = app();
    app.open(&path).unwrap();
    app
}

#[test]
fn every_band_and_pass_reaches_the_runner_and_the_composed_image_is_the_final_one() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = open(dir.path(), 16);
    app.view_target = None;
    app.run();
    app.wait_for_run();
    let p = app.runner.last_partial().expect("the path tracer sent partial results");
    assert_eq!(p.node, "pt");
    // Three chunks, each after its passes of 1, 2 and 4 samples (the fourth is its last) and
    // once done: five partials each.
    assert_eq!(p.updates, 15);
    let outputs: Vec<_> = ["image", "variance"].iter().map(|n| app.last_output_image(n).expect("an image output")).collect();
    assert_eq!(p.layers[0].pixels, outputs[0].pixels, "the bands composed are the mean");
    assert_eq!(p.layers[1].pixels, outputs[1].pixels, "and the variance");
}

#[test]
fn the_viewer_shows_the_render_as_far_as_it_got_until_it_ends() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = open(dir.path(), 256);
    let ctx = egui::Context::default();
    frame(&ctx, &mut app);
    app.run();
    let (mut partials, t0) = (Vec::new(), Instant::now());
    while !app.is_idle() {
        assert!(t0.elapsed() < Duration::from_secs(300), "{}", app.status);
        frame(&ctx, &mut app);
        if app.partial_shown {
            let img = app.viewer.image().unwrap().clone();
            if partials.last().is_none_or(|p: &std::sync::Arc<relume_base::types::Image>| !std::sync::Arc::ptr_eq(p, &img)) {
                partials.push(img);
            }
        }
        std::thread::sleep(Duration::from_millis(3));
    }
    frame(&ctx, &mut app);
    assert!(!partials.is_empty(), "no partial image was shown while the render ran");
    assert!(!app.partial_shown, "the final image replaces the partial one");
    let last = app.viewer.image().unwrap();
    assert!(partials.iter().all(|p| (p.width, p.height) == (128, 96)));
    // Every partial but the last lacks something of the final image; the last may be the bands
    // of every chunk composed, which is the final image bit for bit, shown in a frame between
    // the last chunk and the run's end.
    let (before, _) = partials.split_at(partials.len() - 1);
    assert!(before.iter().all(|p| p.pixels != last.pixels), "a partial before the last was already the final image");
    assert!(partials.len() > 1 || partials[0].pixels != last.pixels, "the only partial shown was the final image");
    // The first partial shown lacks rows the final image has.
    let dark_rows =
        |img: &relume_base::types::Image| (0..img.height).filter(|&y| (0..img.width).all(|x| img.get(x, y) == [0.0; 3])).count();
    assert!(dark_rows(&partials[0]) > dark_rows(last), "{} dark rows", dark_rows(&partials[0]));
}
