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
    frame_with(ctx, app, Vec::new(), egui::Modifiers::NONE);
}

/// Draws one frame with these input events.
pub fn frame_with(ctx: &egui::Context, app: &mut EditorApp, events: Vec<egui::Event>, modifiers: egui::Modifiers) {
    let input = egui::RawInput {
        screen_rect: Some(egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(1400.0, 860.0))),
        events,
        modifiers,
        ..Default::default()
    };
    let _ = ctx.run(input, |ctx| app.ui(ctx));
}

/// The screen point at a fraction (x, y) of the viewer's image (where the last frame drew it:
/// the helpers below draw a frame first, so a layout change shows before they aim).
pub fn on_image(app: &EditorApp, f: (f32, f32)) -> egui::Pos2 {
    let r = app.viewer.image_rect.expect("the viewer shows an image");
    egui::pos2(r.min.x + f.0 * r.width(), r.min.y + f.1 * r.height())
}

fn button(pos: egui::Pos2, button: egui::PointerButton, pressed: bool, modifiers: egui::Modifiers) -> egui::Event {
    egui::Event::PointerButton { pos, button, pressed, modifiers }
}

/// A drag on the viewer's image from one fraction of it to another, in `steps` moves.
pub fn drag_on_image(ctx: &egui::Context, app: &mut EditorApp, from: (f32, f32), to: (f32, f32), steps: usize, alternate: bool) {
    frame(ctx, app);
    let (b, m) = if alternate {
        (egui::PointerButton::Secondary, egui::Modifiers::NONE)
    } else {
        (egui::PointerButton::Primary, egui::Modifiers::NONE)
    };
    let (a, z) = (on_image(app, from), on_image(app, to));
    frame_with(ctx, app, vec![egui::Event::PointerMoved(a)], m);
    frame_with(ctx, app, vec![button(a, b, true, m)], m);
    for i in 1..=steps {
        let p = a + (z - a) * (i as f32 / steps as f32);
        frame_with(ctx, app, vec![egui::Event::PointerMoved(p)], m);
    }
    frame_with(ctx, app, vec![button(z, b, false, m)], m);
    frame_with(ctx, app, Vec::new(), m);
}

/// A click on the viewer's image at a fraction of it.
pub fn click_on_image(ctx: &egui::Context, app: &mut EditorApp, at: (f32, f32)) {
    frame(ctx, app);
    let p = on_image(app, at);
    let m = egui::Modifiers::NONE;
    frame_with(ctx, app, vec![egui::Event::PointerMoved(p)], m);
    frame_with(ctx, app, vec![button(p, egui::PointerButton::Primary, true, m)], m);
    frame_with(ctx, app, vec![button(p, egui::PointerButton::Primary, false, m)], m);
    frame_with(ctx, app, Vec::new(), m);
}

/// The wheel turned over the viewer's image at its centre.
pub fn wheel_on_image(ctx: &egui::Context, app: &mut EditorApp, points: f32) {
    frame(ctx, app);
    let p = on_image(app, (0.5, 0.5));
    let m = egui::Modifiers::NONE;
    frame_with(ctx, app, vec![egui::Event::PointerMoved(p)], m);
    let wheel = egui::Event::MouseWheel { unit: egui::MouseWheelUnit::Point, delta: egui::vec2(0.0, points), modifiers: m };
    frame_with(ctx, app, vec![wheel], m);
    frame_with(ctx, app, Vec::new(), m);
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
    let text = text.replace("\"scenes/", &format!("\"{}/scenes/", graphs().display()));
    std::fs::write(&path, text.replace("\"assets/", &format!("\"{}/assets/", graphs().display()))).unwrap();
    app.open(&path).unwrap();
    for (id, param, v) in params {
        app.set_param(id, param, v.clone()).unwrap();
    }
    app
}

/// `refract_glass.ron` at test size (32², a 32³ volume, few photons).
pub fn refract_glass_small(dir: &Path) -> EditorApp {
    let i = ParamValue::Int;
    let params = [
        ("scene", "width", i(32)),
        ("scene", "height", i(32)),
        ("voxelize", "resolution", i(32)),
        ("emit", "resolution", i(64)),
        ("reference", "spp", i(4)),
        ("pt", "spp", i(1)),
    ];
    open_shipped(dir, "refract_glass.ron", &params)
}
