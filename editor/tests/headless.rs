//! The editor driven headlessly through `egui::Context::run` (no window): file round trips,
//! refused connections, which nodes an edit makes stale, undo, and the incremental re-runs
//! on `graphs/pbgi_cornell.ron` read from the run report.

use egui_node_graph2 as eng;
use relume_core::{Graph, ParamValue};
use relume_editor::runner::NodeState;
use relume_editor::view::NodeResponse;
use relume_editor::EditorApp;
use std::time::{Duration, Instant};

mod common;
use common::*;

/// `filters.ron` open in a fresh editor (in a temporary folder), one frame drawn.
fn filters() -> (tempfile::TempDir, EditorApp, egui::Context) {
    let dir = tempfile::tempdir().unwrap();
    let mut app = app();
    open_copy(&mut app, "filters.ron", dir.path());
    let ctx = egui::Context::default();
    frame(&ctx, &mut app);
    (dir, app, ctx)
}

fn states(app: &EditorApp) -> Vec<(String, NodeState)> {
    let mut v: Vec<_> = app.view.user.states.iter().map(|(k, s)| (k.clone(), s.clone())).collect();
    v.sort_by(|a, b| a.0.cmp(&b.0));
    v
}

fn stale(app: &EditorApp) -> Vec<String> {
    states(app).into_iter().filter(|(_, s)| *s == NodeState::Stale).map(|(k, _)| k).collect()
}

#[test]
fn a_relume_saved_file_round_trips_byte_identical_through_the_editor() {
    let dir = tempfile::tempdir().unwrap();
    let reg = relume_editor::registry();
    for name in ["pbgi_cornell.ron", "filters.ron", "pbgi_vs_reference.ron"] {
        let g = Graph::load(&graphs().join(name), &reg).unwrap();
        let path = dir.path().join(name);
        g.save(&path).unwrap();
        let before = std::fs::read(&path).unwrap();
        let mut app = app();
        app.open(&path).unwrap();
        let ctx = egui::Context::default();
        for _ in 0..3 {
            frame(&ctx, &mut app);
        }
        assert_eq!(app.view.state.graph.nodes.len(), g.nodes.len(), "{name}: every node is in the widget");
        assert_eq!(app.view.connection_count(), g.edges.len(), "{name}: every edge is in the widget");
        assert!(!app.doc.is_dirty(), "{name}: showing a graph does not change it");
        app.save();
        assert_eq!(std::fs::read(&path).unwrap(), before, "{name}: saved bytes differ");
    }
}

#[test]
fn connecting_incompatible_ports_is_refused_and_compatible_ones_are_undoable() {
    let (_dir, mut app, ctx) = filters();
    let before = app.doc.graph.to_ron();
    let port = |app: &EditorApp, node: &str, name: &str, output: bool| -> (eng::NodeId, Option<eng::OutputId>, Option<eng::InputId>) {
        let id = app.view.ids[node];
        let n = &app.view.state.graph[id];
        (id, output.then(|| n.get_output(name).unwrap()), (!output).then(|| n.get_input(name).unwrap()))
    };
    // error.metrics (Metrics) into tonemap.image (Image): the widget would draw it; the editor refuses.
    let (_, out, _) = port(&app, "error", "metrics", true);
    let (_, _, inp) = port(&app, "tonemap", "image", false);
    let (out, inp) = (out.unwrap(), inp.unwrap());
    app.view.inject.push(NodeResponse::ConnectEventEnded { output: out, input: inp, input_hook: 0 });
    frame(&ctx, &mut app);
    frame(&ctx, &mut app);
    assert_eq!(app.doc.graph.to_ron(), before, "the document is unchanged");
    assert!(app.status.contains("port types differ"), "status: {}", app.status);
    assert_eq!(app.view.connection_count(), app.doc.graph.edges.len(), "the widget shows the document again");
    assert!(!app.doc.can_undo(), "a refused connection is not an undo step");

    // A cycle is refused too: blur.image back into median.image.
    let (_, out, _) = port(&app, "blur", "image", true);
    let (_, _, inp) = port(&app, "median", "image", false);
    app.view.inject.push(NodeResponse::ConnectEventEnded { output: out.unwrap(), input: inp.unwrap(), input_hook: 0 });
    frame(&ctx, &mut app);
    assert!(app.status.contains("cycle"), "status: {}", app.status);
    assert_eq!(app.doc.graph.to_ron(), before);

    // sum.image into tonemap.image: accepted, replaces blur → tonemap, and undo restores it.
    let (_, out, _) = port(&app, "sum", "image", true);
    let (_, _, inp) = port(&app, "tonemap", "image", false);
    app.view.inject.push(NodeResponse::ConnectEventEnded { output: out.unwrap(), input: inp.unwrap(), input_hook: 0 });
    frame(&ctx, &mut app);
    assert!(app.doc.graph.edges.iter().any(|e| e.from.to_string() == "sum.image" && e.to.to_string() == "tonemap.image"));
    assert_eq!(app.doc.graph.edges.len(), 7, "the input keeps one edge");
    app.undo();
    frame(&ctx, &mut app);
    assert_eq!(app.doc.graph.to_ron(), before, "undo restores the previous graph");
    assert_eq!(app.view.connection_count(), 7);
    app.redo();
    frame(&ctx, &mut app);
    assert!(app.doc.graph.edges.iter().any(|e| e.from.to_string() == "sum.image"));
}

#[test]
fn a_parameter_edit_marks_exactly_the_downstream_nodes_stale_and_undo_restores() {
    let (_dir, mut app, ctx) = filters();
    assert_eq!(stale(&app).len(), 7, "nothing has run: every node is stale");
    app.run();
    app.wait_for_run();
    frame(&ctx, &mut app);
    assert!(stale(&app).is_empty(), "after a run nothing is stale: {:?}", states(&app));
    assert!(app.viewer.has_image(), "the viewer shows the image output");
    let before = app.doc.graph.to_ron();

    // Without re-runs on edit: a live re-run of this small graph may be under way or done by
    // the next frame, and the marks under test are those of the edit itself.
    app.auto_run = false;
    app.set_param("median", "radius", ParamValue::Int(2)).unwrap();
    frame(&ctx, &mut app);
    assert_eq!(stale(&app), ["blur", "error", "median", "tonemap"]);
    assert_eq!(relume_editor::edit::downstream(&app.doc.graph, "median"), stale(&app));
    let cached: Vec<String> = states(&app).into_iter().filter(|(_, s)| *s == NodeState::Cached).map(|(k, _)| k).collect();
    assert_eq!(cached, ["clean", "noisy", "sum"]);
    assert!(app.doc.is_dirty());

    app.undo();
    frame(&ctx, &mut app);
    assert_eq!(app.doc.graph.to_ron(), before, "undo restores the previous graph");
    assert!(stale(&app).is_empty(), "the previous parameters' results are still cached: {:?}", states(&app));
    assert!(!app.doc.is_dirty());

    // Structural edits undo too: a node from the palette, then its removal.
    app.add_from_palette("GaussianBlur", [0.0, 300.0]);
    frame(&ctx, &mut app);
    assert!(app.doc.graph.node("gaussian_blur").is_some());
    assert_eq!(app.view.state.graph.nodes.len(), 8);
    app.delete_selected();
    frame(&ctx, &mut app);
    assert!(app.doc.graph.node("gaussian_blur").is_none());
    app.undo();
    app.undo();
    frame(&ctx, &mut app);
    assert_eq!(app.doc.graph.to_ron(), before);
}

/// Each edit (node, parameter, value, the nodes it must re-run): the viewed image comes first,
/// from exactly those nodes, and differs from the one before; then the rest runs.
fn edits_update_the_image(ctx: &egui::Context, app: &mut EditorApp, edits: Vec<(&str, &str, ParamValue, &[&str])>) {
    let mut img = app.viewer.image().expect("the image is shown").clone();
    for (node, param, value, reran) in edits {
        app.set_param(node, param, value).unwrap();
        frames_until_refreshed(ctx, app);
        let mut ran = app.report.as_ref().unwrap().ran_ids();
        ran.sort();
        assert_eq!(ran, reran, "{node}.{param}");
        let now = app.viewer.image().unwrap().clone();
        assert!(!std::sync::Arc::ptr_eq(&img, &now) && img.pixels != now.pixels, "{node}.{param}: the viewer shows the edit");
        img = now;
        until_idle(ctx, app);
    }
}

#[test]
fn pbgi_cornell_edits_rerun_only_what_they_reach() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = open_shipped(
        dir.path(),
        "pbgi_cornell.ron",
        &[
            ("scene", "width", ParamValue::Int(64)),
            ("scene", "height", ParamValue::Int(64)),
            ("points", "count", ParamValue::Int(4000)),
            ("direct", "pixel_samples", ParamValue::Int(2)),
        ],
    );
    let ctx = egui::Context::default();
    frame(&ctx, &mut app);
    app.run();
    app.wait_for_run();
    frame(&ctx, &mut app);
    // The viewed image first, then the other outputs: the last report is the second run's,
    // which found the image's nodes cached by the first.
    let report = app.report.clone().expect("a report");
    assert!(app.is_idle() && report.cached > 0 && report.node("combine").is_some_and(|n| n.status == "cached"), "{}", app.status);
    let img = app.viewer.image().expect("the image is shown").clone();
    assert_eq!((img.width, img.height), (64, 64));
    assert!(stale(&app).is_empty());

    // Move the light: the surface points and the loaded scene are reused.
    app.set_param("move", "translation", ParamValue::Tuple(vec![ParamValue::Float(0.0), ParamValue::Float(-0.05), ParamValue::Float(0.0)]))
        .unwrap();
    frame(&ctx, &mut app);
    assert!(stale(&app).contains(&"shade".to_string()) && !stale(&app).contains(&"points".to_string()));
    frames_until_refreshed(&ctx, &mut app);
    let r = app.report.clone().unwrap();
    let ran = r.ran_ids();
    assert!(!ran.contains(&"points") && !ran.contains(&"scene"), "ran: {ran:?}");
    for id in ["move", "shade", "tree", "gather", "direct", "combine"] {
        assert!(ran.contains(&id), "{id} should re-run after the light moved: {ran:?}");
    }
    assert!(!std::sync::Arc::ptr_eq(&img, app.viewer.image().unwrap()), "the viewer shows the new image");

    // The microbuffer resolution reaches only the gather and what adds it to the direct light.
    // At test size the gather can fit the frame budget and start at once (then it is running,
    // not stale); it is priced as the shipped graph's is, so the edit waits for a pause.
    app.costs.set("gather", 10.0 * relume_editor::live::FRAME_BUDGET_MS);
    app.set_param("gather", "resolution", ParamValue::Int(8)).unwrap();
    frame(&ctx, &mut app);
    assert_eq!(stale(&app), ["combine", "gather"]);
    frames_until_refreshed(&ctx, &mut app);
    assert_eq!(app.report.as_ref().unwrap().ran_ids(), ["combine", "gather"]);
    assert!(app.edit_to_image_ms.unwrap() > 0.0);
}

/// One frame in which the window's close button was pressed; returns the viewport commands.
fn close_frame(ctx: &egui::Context, app: &mut EditorApp) -> Vec<egui::ViewportCommand> {
    let mut input =
        egui::RawInput { screen_rect: Some(egui::Rect::from_min_size(egui::Pos2::ZERO, egui::vec2(1400.0, 860.0))), ..Default::default() };
    input.viewports.entry(egui::ViewportId::ROOT).or_default().events.push(egui::ViewportEvent::Close);
    let out = ctx.run(input, |ctx| app.ui(ctx));
    out.viewport_output.get(&egui::ViewportId::ROOT).map(|v| v.commands.clone()).unwrap_or_default()
}

#[test]
fn closing_with_unsaved_changes_asks_first_and_keeps_a_recovery_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = app();
    let path = open_copy(&mut app, "filters.ron", dir.path());
    let ctx = egui::Context::default();
    frame(&ctx, &mut app);
    let cmds = close_frame(&ctx, &mut app);
    assert!(!cmds.contains(&egui::ViewportCommand::CancelClose), "a clean graph closes at once");

    app.set_param("blur", "sigma", ParamValue::Float(1.5)).unwrap();
    let cmds = close_frame(&ctx, &mut app);
    assert!(cmds.contains(&egui::ViewportCommand::CancelClose), "unsaved changes stop the close");
    assert!(app.quit_prompt);
    let rec = app.doc.write_recovery().unwrap();

    // Opening the file again offers the unsaved work back.
    let mut again = self::app();
    again.open(&path).unwrap();
    frame(&ctx, &mut again);
    assert!(again.status.contains("opened"));
    assert!(again.doc.pending_recovery().is_some());
    assert!(rec.exists());
    app.save_and_close(&ctx);
    assert!(!app.doc.is_dirty() && !rec.exists(), "saving clears the recovery file");
}

#[test]
fn unsaved_work_is_kept_each_frame_it_is_due_and_not_after_a_discard() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = app();
    open_copy(&mut app, "filters.ron", dir.path());
    app.recovery_every = std::time::Duration::ZERO;
    let ctx = egui::Context::default();
    app.set_param("blur", "sigma", ParamValue::Float(1.5)).unwrap();
    frame(&ctx, &mut app);
    let rec = relume_editor::document::recovery_path(app.doc.path.as_deref());
    assert!(rec.exists(), "the edit is kept");
    // Discarding (as a measured drive does on its way out) removes it, and the frames before
    // the window closes do not write it again.
    app.set_param("blur", "sigma", ParamValue::Float(1.7)).unwrap();
    app.discard_and_close(&ctx);
    frame(&ctx, &mut app);
    assert!(!rec.exists());
}

#[test]
fn deleting_a_node_in_the_widget_is_one_undo_step() {
    let (_dir, mut app, ctx) = filters();
    let before = app.doc.graph.to_ron();
    let blur = app.view.ids["blur"];
    app.view.inject.push(NodeResponse::DeleteNodeUi(blur));
    frame(&ctx, &mut app);
    assert!(app.doc.graph.node("blur").is_none());
    assert!(!app.doc.graph.edges.iter().any(|e| e.from.node == "blur" || e.to.node == "blur"));
    assert_eq!(app.view.connection_count(), app.doc.graph.edges.len());
    app.undo();
    frame(&ctx, &mut app);
    assert_eq!(app.doc.graph.to_ron(), before, "one undo brings the node and its edges back");
    assert_eq!(app.view.connection_count(), 7);
}

#[test]
fn save_image_layers_writes_every_image_output_of_the_last_run_beside_the_graph() {
    let (dir, mut app, ctx) = filters();
    assert!(app.save_exr_layers().is_none(), "nothing to save before a run");
    app.run();
    app.wait_for_run();
    frame(&ctx, &mut app);
    let path = app.save_exr_layers().unwrap_or_else(|| panic!("{}", app.status));
    assert_eq!(path, dir.path().join("filters.layers.exr"));
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(&bytes[..4], &[0x76, 0x2f, 0x31, 0x01], "an OpenEXR file");
    let header = String::from_utf8_lossy(&bytes[..bytes.len().min(8192)]).into_owned();
    for name in ["image.R", "image.G", "image.B", "relume.layers", "filters.ron"] {
        assert!(header.contains(name), "{name} in the header");
    }
    assert!(app.status.contains("filters.layers.exr"), "{}", app.status);
}

#[test]
fn a_material_edit_on_relight_cornell_bunny_shows_the_relit_image_first_with_its_time() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = open_shipped(
        dir.path(),
        "relight_cornell_bunny.ron",
        &[
            ("scene", "width", ParamValue::Int(24)),
            ("scene", "height", ParamValue::Int(24)),
            ("space", "n_theta_i", ParamValue::Int(12)),
            ("space", "n_theta_o", ParamValue::Int(12)),
            ("space", "n_phi", ParamValue::Int(24)),
            ("space", "samples", ParamValue::Int(41)),
            ("transfer", "spp", ParamValue::Int(2)),
            ("transfer", "bounce_rays", ParamValue::Int(2)),
            ("reference", "spp", ParamValue::Int(4)),
        ],
    );
    assert_eq!(app.view_target.as_deref(), Some("image"));
    let ctx = egui::Context::default();
    first_run(&ctx, &mut app);
    assert!(app.report.as_ref().unwrap().ran_ids().contains(&"z_test"), "the whole graph ran");
    let img = app.viewer.image().expect("the relit image is shown").clone();

    app.set_param("project", "object", ParamValue::Text("bunny".into())).unwrap();
    app.set_param("project", "kd", ParamValue::Tuple(vec![ParamValue::Float(0.7), ParamValue::Float(0.1), ParamValue::Float(0.1)]))
        .unwrap();
    frames_until_refreshed(&ctx, &mut app);
    // The image came alone: the projection and the combine, nothing else.
    assert_eq!(app.report.as_ref().unwrap().ran_ids(), ["project", "relight"]);
    assert!(!std::sync::Arc::ptr_eq(&img, app.viewer.image().unwrap()), "the viewer shows the edit");
    let ms = app.edit_to_image_ms.unwrap();
    assert!(ms > 0.0);
    // Then the comparisons that need it, while the status bar keeps the edit-to-image time.
    until_idle(&ctx, &mut app);
    let mut rest = app.report.as_ref().unwrap().ran_ids();
    rest.sort();
    assert_eq!(rest, ["applied", "basis_error", "error", "paths_z_test", "reference", "same_seed", "z_test"]);
    assert_eq!(app.edit_to_image_ms, Some(ms));
}

#[test]
fn orbiting_moving_the_light_and_painting_on_refract_glass_update_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = refract_glass_small(dir.path());
    assert_eq!(app.view_target.as_deref(), Some("image"));
    let ctx = egui::Context::default();
    first_run(&ctx, &mut app);
    let vec3 = |x: f64, y: f64, z: f64| ParamValue::Tuple(vec![ParamValue::Float(x), ParamValue::Float(y), ParamValue::Float(z)]);
    // Each edit: the image first, from exactly the nodes the edit reaches on its way there.
    let edits: Vec<(&str, &str, ParamValue, &[&str])> = vec![
        ("camera", "azimuth", ParamValue::Float(25.0), &["camera", "paths", "render"]),
        ("light", "translation", vec3(0.3, 0.0, 0.0), &["bvh", "emit", "light", "march", "render"]),
        ("paint", "weight", ParamValue::Float(0.3), &["emit", "march", "octree", "paint", "paths", "render"]),
    ];
    edits_update_the_image(&ctx, &mut app, edits);
}

#[test]
fn turning_the_sky_changing_the_material_and_orbiting_on_ptt_envlit_update_the_image() {
    let dir = tempfile::tempdir().unwrap();
    let i = ParamValue::Int;
    let mut app = open_shipped(
        dir.path(),
        "ptt_envlit.ron",
        &[
            // The Spot-and-teapot scene: fewer vertices than the bunny's for the same edits.
            ("scene", "path", ParamValue::Text(graphs().join("scenes/envlit-pair.ron").display().to_string())),
            ("project", "object", ParamValue::Text("spot".into())),
            ("scene", "width", i(24)),
            ("scene", "height", i(24)),
            ("env", "side", i(8)),
            ("env", "supersample", i(2)),
            ("visibility", "side", i(8)),
            ("visibility", "coarse", i(2)),
            ("tensor", "disk", i(6)),
            ("tensor", "samples", i(12)),
            ("space", "n_theta_i", i(8)),
            ("space", "n_theta_o", i(8)),
            ("space", "n_phi", i(16)),
            ("space", "samples", i(21)),
            ("plan", "clusters", i(64)),
            ("plan", "eigenvectors", i(8)),
            ("plan", "lighting", i(8)),
            ("plan", "cpca_iterations", i(2)),
            ("t0", "terms", i(16)),
            ("t0", "lobe_side", i(2)),
            ("t1", "rays_side", i(2)),
            ("t2", "side", i(1)),
            ("t2", "rays_side", i(2)),
            ("reference", "spp", i(4)),
            ("hits", "spp", i(2)),
            ("vertex_reference", "spp", i(2)),
            ("ref_hits", "spp", i(2)),
        ],
    );
    assert_eq!(app.view_target.as_deref(), Some("image"));
    let ctx = egui::Context::default();
    first_run(&ctx, &mut app);
    // Each edit: the image first, from exactly the nodes the edit reaches on its way there.
    let edits: Vec<(&str, &str, ParamValue, &[&str])> = vec![
        ("turn", "rotation_deg", ParamValue::Float(60.0), &["bounced", "direct", "env", "incident", "raster", "relight", "turn"]),
        ("project", "s", ParamValue::Float(80.0), &["incident", "project", "raster", "relight"]),
        ("camera", "azimuth", ParamValue::Float(25.0), &["camera", "hits", "raster", "relight"]),
    ];
    edits_update_the_image(&ctx, &mut app, edits);
}

#[test]
fn vpbgi_cornell_shows_the_preview_splat_before_the_gathered_image() {
    let dir = tempfile::tempdir().unwrap();
    let i = ParamValue::Int;
    let mut app = open_shipped(
        dir.path(),
        "vpbgi_cornell.ron",
        &[
            ("scene", "width", i(32)),
            ("scene", "height", i(32)),
            ("points", "count", i(1500)),
            ("direct", "pixel_samples", i(2)),
            ("reference", "spp", i(4)),
            ("pt", "spp", i(1)),
            ("preview", "level", i(8)),
        ],
    );
    assert_eq!(app.view_target.as_deref(), Some("image"));
    let ctx = egui::Context::default();
    first_run(&ctx, &mut app);
    assert!(!app.preview_shown, "after a whole run the viewer shows the image");
    let img = app.viewer.image().expect("the image is shown").clone();

    // A second bounce reaches the view tree: its preview comes first, from the view tree and
    // the splat alone, while the gather is still to run. At test size the gather takes a few
    // milliseconds and an edit that fits the frame budget runs its image alone, live; the
    // gather is priced as the shipped graph's is (well over the budget), so the edit waits for
    // a pause and then shows its preview first.
    app.costs.set("gather", 10.0 * relume_editor::live::FRAME_BUDGET_MS);
    app.set_param("views", "bounces", i(2)).unwrap();
    app.edit_to_image_ms = None;
    let t0 = Instant::now();
    while !app.preview_shown {
        assert!(t0.elapsed() < Duration::from_secs(600), "no preview: {}", app.status);
        assert!(app.edit_to_image_ms.is_none(), "the image came before its preview");
        frame(&ctx, &mut app);
        std::thread::sleep(Duration::from_millis(5));
    }
    let mut ran = app.report.as_ref().unwrap().ran_ids();
    ran.sort();
    assert_eq!(ran, ["preview", "views"]);
    let preview = app.viewer.image().unwrap().clone();
    assert!(!std::sync::Arc::ptr_eq(&img, &preview) && preview.pixels != img.pixels);
    assert!(app.status.starts_with("preview in"), "{}", app.status);

    // Then the gathered image replaces it, then the error figures.
    frames_until_refreshed(&ctx, &mut app);
    assert!(!app.preview_shown);
    let mut ran = app.report.as_ref().unwrap().ran_ids();
    ran.sort();
    assert_eq!(ran, ["gather", "vpbgi_image"]);
    assert!(!std::sync::Arc::ptr_eq(&preview, app.viewer.image().unwrap()));
    until_idle(&ctx, &mut app);
    assert!(app.report.as_ref().unwrap().ran_ids().contains(&"vpbgi_error"));
}
