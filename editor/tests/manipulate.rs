//! The viewer's manipulators driven headlessly through pointer events on the shown image: each
//! edits its node's parameters as one undo step; a pick selects (and binds) the material node
//! of the object under the pointer; a brush stroke adds chained dab nodes that paint, and is
//! saved and read back byte-identically.

use relume_core::ParamValue;
use relume_editor::tool::Tool;
use relume_editor::EditorApp;

mod common;
use common::*;

fn float(app: &EditorApp, node: &str, name: &str) -> f64 {
    match app.doc.graph.node(node).and_then(|n| n.param(name)) {
        Some(ParamValue::Float(x)) => *x,
        None => 0.0,
        other => panic!("{node}.{name} is {other:?}"),
    }
}

fn floats(app: &EditorApp, node: &str, name: &str) -> Vec<f64> {
    match app.doc.graph.node(node).and_then(|n| n.param(name)) {
        Some(ParamValue::Tuple(t)) => t.iter().map(|v| if let ParamValue::Float(x) = v { *x } else { panic!() }).collect(),
        other => panic!("{node}.{name} is {other:?}"),
    }
}

/// Writes a test graph into `dir` (scene paths reaching `graphs/scenes`), opens and runs it.
fn open_graph(dir: &std::path::Path, text: &str) -> (EditorApp, egui::Context) {
    let path = dir.join("g.ron");
    std::fs::write(&path, text.replace("SCENES", &graphs().join("scenes").display().to_string())).unwrap();
    let mut app = app();
    app.open(&path).unwrap();
    let ctx = egui::Context::default();
    first_run(&ctx, &mut app);
    frame(&ctx, &mut app);
    (app, ctx)
}

#[test]
fn orbit_pan_zoom_and_move_on_refract_glass_edit_their_nodes_one_undo_step_each() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = refract_glass_small(dir.path());
    let ctx = egui::Context::default();
    first_run(&ctx, &mut app);
    frame(&ctx, &mut app);
    assert_eq!(app.tools(), [Tool::Orbit, Tool::Move, Tool::Pick, Tool::PaintVolume]);
    app.doc.seal();
    let before = app.doc.graph.to_ron();

    // A quarter of the image to the right in eight moves: −45° of azimuth, one undo step.
    app.tool = Some(Tool::Orbit);
    drag_on_image(&ctx, &mut app, (0.5, 0.5), (0.75, 0.5), 8, false);
    assert!((float(&app, "camera", "azimuth") + 45.0).abs() < 0.5, "{}", float(&app, "camera", "azimuth"));
    assert_eq!(float(&app, "camera", "elevation"), 0.0);
    // Up by a tenth of the image: +9° of elevation, a second step.
    drag_on_image(&ctx, &mut app, (0.5, 0.5), (0.5, 0.4), 4, false);
    assert!((float(&app, "camera", "elevation") - 9.0).abs() < 0.5, "{}", float(&app, "camera", "elevation"));
    // The secondary button pans: left by a fifth of the image moves the view right by 0.2.
    drag_on_image(&ctx, &mut app, (0.6, 0.5), (0.4, 0.5), 4, true);
    assert!((float(&app, "camera", "pan_right") - 0.2).abs() < 0.01, "{}", float(&app, "camera", "pan_right"));
    // The wheel zooms in.
    wheel_on_image(&ctx, &mut app, 100.0);
    let d = float(&app, "camera", "distance");
    assert!((d - (-0.2f64).exp()).abs() < 1e-3, "{d}");
    for _ in 0..4 {
        app.undo();
    }
    assert_eq!(app.doc.graph.to_ron(), before, "orbit, tilt, pan and zoom were one undo step each");

    // The move tool drags the light in the view's plane: right on the image is +x here.
    app.tool = Some(Tool::Move);
    drag_on_image(&ctx, &mut app, (0.5, 0.5), (0.7, 0.5), 5, false);
    let t = floats(&app, "light", "translation");
    assert!(t[0] > 0.1 && t[1].abs() < 1e-4 && t[2].abs() < 1e-4, "{t:?}");
    app.undo();
    assert_eq!(app.doc.graph.to_ron(), before);

    // A stroke across the glass adds chained volume brush nodes inside it, one undo step.
    app.tool = Some(Tool::PaintVolume);
    drag_on_image(&ctx, &mut app, (0.45, 0.55), (0.55, 0.55), 6, false);
    let dabs: Vec<String> =
        app.doc.graph.nodes.iter().filter(|n| n.kind == "VolumePaint" && n.id != "paint").map(|n| n.id.clone()).collect();
    assert!(!dabs.is_empty(), "{}", app.status);
    assert!(app.doc.graph.edges.iter().any(|e| e.from.to_string() == "paint.medium" && e.to.to_string() == format!("{}.medium", dabs[0])));
    assert!(!app.doc.graph.edges.iter().any(|e| e.from.node == "paint" && e.to.node == "octree"), "the octree reads the last dab");
    app.undo();
    assert_eq!(app.doc.graph.to_ron(), before, "the stroke was one undo step");
}

const ENVLIT: &str = r#"Graph(
    version: 1,
    nodes: {
        "scene": (kind: "LoadScene", params: (path: "SCENES/envlit.ron", width: 16, height: 16)),
        "bvh": (kind: "BuildBvh", params: ()),
        "turn": (kind: "TurnEnvironment", params: ()),
        "pt": (kind: "PathTrace", params: (spp: 1, max_depth: 1, seed: 1)),
    },
    edges: [("scene.scene", "bvh.scene"), ("scene.scene", "turn.scene"), ("turn.scene", "pt.scene"), ("bvh.accel", "pt.accel")],
    outputs: {"image": "pt.image"},
)
"#;

#[test]
fn dragging_sideways_turns_the_sky_and_the_image_follows() {
    let dir = tempfile::tempdir().unwrap();
    let (mut app, ctx) = open_graph(dir.path(), ENVLIT);
    assert_eq!(app.tools(), [Tool::Turn, Tool::Pick]);
    let img = app.viewer.image().unwrap().clone();
    app.tool = Some(Tool::Turn);
    drag_on_image(&ctx, &mut app, (0.3, 0.5), (0.55, 0.5), 5, false);
    assert!((float(&app, "turn", "rotation_deg") - 90.0).abs() < 1.0, "{}", float(&app, "turn", "rotation_deg"));
    until_idle(&ctx, &mut app);
    assert!(app.viewer.image().unwrap().pixels != img.pixels, "the turned sky shows");
    app.undo();
    assert_eq!(float(&app, "turn", "rotation_deg"), 0.0);
    // With shift, dragging a quarter of the image down tilts the sky by 45°.
    drag_on_image(&ctx, &mut app, (0.5, 0.3), (0.5, 0.55), 5, true);
    assert!((float(&app, "turn", "tilt_deg") - 45.0).abs() < 1.0, "{}", float(&app, "turn", "tilt_deg"));
    assert_eq!(float(&app, "turn", "rotation_deg"), 0.0);
    until_idle(&ctx, &mut app);
    assert!(app.viewer.image().unwrap().pixels != img.pixels, "the tilted sky shows");
}

const SPOT: &str = r#"Graph(
    version: 1,
    nodes: {
        "scene": (kind: "LoadScene", params: (path: "SCENES/cornell-spot.ron", width: 32, height: 32)),
        "bvh": (kind: "BuildBvh", params: ()),
        "materials": (kind: "SceneMaterials", params: ()),
        "paint": (kind: "PaintMaterial", params: (object: "", radius: 0.05, value: (0.1, 0.9, 0.1), size: 64)),
        "space": (kind: "BrdfSpaceSample", params: (n_theta_i: 8, n_theta_o: 8, n_phi: 16, samples: 21, s_min: 1.0, s_max: 200.0)),
        "pca": (kind: "BrdfPca", params: (bases: 4)),
        "project": (kind: "MaterialProject", params: (object: "")),
        "applied": (kind: "ApplyMaterials", params: ()),
        "pt": (kind: "PathTrace", params: (spp: 1, max_depth: 2, seed: 1)),
    },
    edges: [
        ("scene.scene", "bvh.scene"),
        ("scene.scene", "materials.scene"),
        ("materials.materials", "paint.materials"),
        ("space.space", "pca.space"),
        ("pca.basis", "project.basis"),
        ("paint.materials", "project.materials"),
        ("scene.scene", "applied.scene"),
        ("project.materials", "applied.materials"),
        ("applied.scene", "pt.scene"),
        ("bvh.accel", "pt.accel"),
    ],
    outputs: {"image": "pt.image", "materials": "project.materials"},
)
"#;

/// A fraction of the image where the pick finds `object` (scanning the image's middle row
/// first, then the rows around it).
fn where_is(app: &mut EditorApp, object: &str) -> (f32, f32) {
    let size = {
        let img = app.viewer.image().unwrap();
        [img.width, img.height]
    };
    let view = app.view_node().unwrap();
    let mut probe = relume_editor::pick::Probe::new(app.runner.engine(), &app.doc.graph, &view).unwrap();
    for dy in [0, 2, -2, 4, -4, 6, -6] {
        let y = size[1] as i32 / 2 + dy;
        for x in 0..size[0] {
            let p = egui::pos2(x as f32 + 0.5, y as f32 + 0.5);
            if probe.pick(p, size).is_some_and(|h| h.object == object) {
                return (p.x / size[0] as f32, p.y / size[1] as f32);
            }
        }
    }
    panic!("{object} is not in the image");
}

#[test]
fn a_pick_selects_the_material_node_and_a_paint_stroke_is_saved_and_read_back_byte_identically() {
    let dir = tempfile::tempdir().unwrap();
    let (mut app, ctx) = open_graph(dir.path(), SPOT);
    assert_eq!(app.tools(), [Tool::Pick, Tool::Paint]);
    app.doc.seal();
    let before = app.doc.graph.to_ron();

    // A click on the cow binds the free material node to it and selects it: one undo step.
    let spot = where_is(&mut app, "spot");
    app.tool = Some(Tool::Pick);
    click_on_image(&ctx, &mut app, spot);
    assert_eq!(app.doc.graph.node("project").unwrap().param("object"), Some(&ParamValue::Text("spot".into())));
    assert_eq!(app.view.selected_ids(), ["project"]);
    app.undo();
    assert_eq!(app.doc.graph.to_ron(), before);

    // A stroke over the cow: dab nodes chained after `paint`, feeding `project`; one step.
    app.tool = Some(Tool::Paint);
    let to = (spot.0 + 0.06, spot.1);
    drag_on_image(&ctx, &mut app, spot, to, 6, false);
    let dabs: Vec<String> =
        app.doc.graph.nodes.iter().filter(|n| n.kind == "PaintMaterial" && n.id != "paint").map(|n| n.id.clone()).collect();
    assert!(!dabs.is_empty(), "{}", app.status);
    let last = dabs.last().unwrap();
    assert!(app
        .doc
        .graph
        .edges
        .iter()
        .any(|e| e.from.to_string() == format!("{last}.materials") && e.to.to_string() == "project.materials"));
    for d in &dabs {
        let n = app.doc.graph.node(d).unwrap();
        assert_eq!(n.param("object"), Some(&ParamValue::Text("spot".into())));
        assert_eq!(n.param("radius"), Some(&ParamValue::Float(0.05)), "the brush is the paint node's");
    }
    // The dabs paint texels of the cow's map.
    until_idle(&ctx, &mut app);
    let report = app.report.as_ref().unwrap();
    for d in &dabs {
        let painted = report.nodes.iter().find(|n| &n.id == d).map(|n| n.metrics["texels_painted"]);
        assert!(painted.is_some_and(|t| t > 0.0), "{d}: {painted:?}");
    }
    app.undo();
    assert_eq!(app.doc.graph.to_ron(), before, "the stroke was one undo step");
    app.redo();

    // Saved, the stroke is the dab nodes' parameters; the file reads back to the same bytes.
    app.save();
    let path = dir.path().join("g.ron");
    let saved = std::fs::read(&path).unwrap();
    let mut again = self::app();
    again.open(&path).unwrap();
    assert_eq!(again.doc.graph.to_ron().as_bytes(), saved.as_slice());
    again.save();
    assert_eq!(std::fs::read(&path).unwrap(), saved);
}

#[test]
fn the_viewer_only_layout_shows_the_image_in_the_centre_and_its_manipulators_still_edit() {
    let dir = tempfile::tempdir().unwrap();
    let mut app = refract_glass_small(dir.path());
    let ctx = egui::Context::default();
    first_run(&ctx, &mut app);
    frame(&ctx, &mut app);
    let beside = app.viewer.image_rect.expect("the viewer shows the image");
    let f11 =
        |pressed| egui::Event::Key { key: egui::Key::F11, physical_key: None, pressed, repeat: false, modifiers: egui::Modifiers::NONE };
    frame_with(&ctx, &mut app, vec![f11(true), f11(false)], egui::Modifiers::NONE);
    frame(&ctx, &mut app);
    assert!(app.viewer_only, "F11 switches to the viewer-only layout");
    let centred = app.viewer.image_rect.expect("the viewer still shows the image");
    assert!(centred.min.x < beside.min.x - 100.0, "the image moved from the right panel ({beside:?}) to the centre ({centred:?})");
    app.tool = Some(Tool::Orbit);
    drag_on_image(&ctx, &mut app, (0.5, 0.5), (0.75, 0.5), 8, false);
    assert!((float(&app, "camera", "azimuth") + 45.0).abs() < 0.5, "{}", float(&app, "camera", "azimuth"));
    frame_with(&ctx, &mut app, vec![f11(true), f11(false)], egui::Modifiers::NONE);
    frame(&ctx, &mut app);
    assert!(!app.viewer_only, "F11 again brings the node graph back");
    assert!(app.viewer.image_rect.expect("shown").min.x > centred.min.x + 100.0);
}
