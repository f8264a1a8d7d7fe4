//! The node-graph canvas draws every node of a shipped graph inside its panel, also when the
//! graph was edited (as `--set` does) before the first frame built the widget.

use relume_core::ParamValue;
use relume_editor::EditorApp;

mod common;
use common::*;

/// Texts the canvas drew this frame inside its own rectangle.
fn kinds_drawn_on_canvas(ctx: &egui::Context, app: &mut EditorApp) -> Vec<String> {
    let input =
        egui::RawInput { screen_rect: Some(egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(1400.0, 860.0))), ..Default::default() };
    let out = ctx.run(input, |ctx| app.ui(ctx));
    let canvas = app.view.canvas_rect.expect("the default layout shows the node graph");
    let mut v: Vec<String> = out
        .shapes
        .iter()
        .filter_map(|c| match &c.shape {
            egui::Shape::Text(t) if canvas.contains(t.pos) && c.clip_rect.intersects(canvas) => Some(t.galley.text().to_string()),
            _ => None,
        })
        .collect();
    v.sort();
    v.dedup();
    v
}

/// Each node's id (its title) and kind (the label beside it).
fn graph_names(app: &EditorApp) -> Vec<String> {
    let mut v: Vec<String> = app.doc.graph.nodes.iter().flat_map(|n| [n.id.clone(), n.kind.clone()]).collect();
    v.sort();
    v.dedup();
    v
}

#[test]
fn every_node_is_drawn_on_the_canvas_after_opening() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = app();
    open_copy(&mut app, "filters.ron", dir.path());
    let ctx = egui::Context::default();
    let drawn = kinds_drawn_on_canvas(&ctx, &mut app);
    for name in graph_names(&app) {
        assert!(drawn.contains(&name), "{name} not drawn on the canvas: {drawn:?}");
    }
}

#[test]
fn a_parameter_set_before_the_first_frame_leaves_every_node_on_the_canvas() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = open_shipped(dir.path(), "pbgi_cornell.ron", &[("scene", "width", ParamValue::Int(32))]);
    app.set_text("scene.height=32").unwrap();
    let ctx = egui::Context::default();
    let drawn = kinds_drawn_on_canvas(&ctx, &mut app);
    assert_eq!(app.view.state.graph.nodes.len(), app.doc.graph.nodes.len(), "every node is in the widget");
    for name in graph_names(&app) {
        assert!(drawn.contains(&name), "{name} not drawn on the canvas: {drawn:?}");
    }
}
