//! What the editor's headless tests share: a fresh editor, a frame on a headless context,
//! opening a shipped graph at test size, waiting for runs through frames.
#![allow(dead_code)]

use relume_core::{Engine, ParamValue};
use relume_editor::EditorApp;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

pub fn graphs() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../graphs")
}

pub fn app() -> EditorApp {
    let reg = relume_editor::registry();
    EditorApp::new(reg.clone(), Engine::new(reg))
}

/// Draws one frame of the editor on a headless context.
pub fn frame(ctx: &egui::Context, app: &mut EditorApp) {
    let input =
        egui::RawInput { screen_rect: Some(egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(1400.0, 860.0))), ..Default::default() };
    let _ = ctx.run(input, |ctx| app.ui(ctx));
}

/// Copies a graph into a temporary folder (with the assets it names) and opens it.
pub fn open_copy(app: &mut EditorApp, name: &str, dir: &Path) -> PathBuf {
    let dst = dir.join(name);
    std::fs::copy(graphs().join(name), &dst).unwrap();
    app.open(&dst).unwrap();
    dst
}

/// A first run of the whole graph, waited for, shown.
pub fn first_run(ctx: &egui::Context, app: &mut EditorApp) {
    frame(ctx, app);
    app.run();
    app.wait_for_run();
    frame(ctx, app);
    assert!(app.is_idle());
}

/// Frames until the run in flight (the outputs after the viewed image) is done.
pub fn until_idle(ctx: &egui::Context, app: &mut EditorApp) {
    let t0 = Instant::now();
    while !app.is_idle() {
        assert!(t0.elapsed() < Duration::from_secs(600), "{}", app.status);
        frame(ctx, app);
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Frames until the automatic re-run after an edit has refreshed the image.
pub fn frames_until_refreshed(ctx: &egui::Context, app: &mut EditorApp) {
    app.edit_to_image_ms = None;
    let t0 = Instant::now();
    while app.edit_to_image_ms.is_none() {
        assert!(t0.elapsed() < Duration::from_secs(600), "no refreshed image: {}", app.status);
        frame(ctx, app);
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Opens a shipped graph in a fresh editor, copied into `dir` with its scenes reached from
/// `graphs/`, at a smaller size than shipped (`params`: node, parameter, value) so the test is
/// quick; the wiring is the file's.
pub fn open_shipped(dir: &Path, name: &str, params: &[(&str, &str, ParamValue)]) -> EditorApp {
    let mut app = app();
    let path = dir.join(name);
    let text = std::fs::read_to_string(graphs().join(name)).unwrap();
    std::fs::write(&path, text.replace("\"scenes/", &format!("\"{}/scenes/", graphs().display()))).unwrap();
    app.open(&path).unwrap();
    for (id, param, v) in params {
        app.set_param(id, param, v.clone()).unwrap();
    }
    app
}
