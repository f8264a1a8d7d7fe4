//! Live re-runs, driven headlessly: a drag on a parameter whose re-run fits the frame budget
//! runs on every change (coalesced behind the run under way), one over the budget runs once
//! the drag pauses, and an edit cancels the dearer run it makes stale. What a node costs is set
//! on the editor's cost table (the last run's times decide in use), so the decision under test
//! does not hang on this machine's speed; the median filter at 1024² keeps a run under way
//! while the test edits.

use relume_core::ParamValue;
use relume_editor::EditorApp;
use std::time::{Duration, Instant};

mod common;
use common::*;

/// A slow median filter (the run under way while the test edits), a blur, and an error figure
/// that runs after the viewed image.
const GRAPH: &str = r#"Graph(
    version: 1,
    nodes: {
        "noisy": (kind: "TestPattern", params: (width: 1024, height: 1024, pattern: Constant, color: (0.5, 0.5, 0.5), noise: 0.4, seed: 1)),
        "median": (kind: "MedianFilter", params: (radius: 4)),
        "blur": (kind: "GaussianBlur", params: (sigma: 0.8)),
        "error": (kind: "ImageError", params: ()),
    },
    edges: [
        ("noisy.image", "median.image"),
        ("median.image", "blur.image"),
        ("blur.image", "error.image"),
        ("noisy.image", "error.reference"),
    ],
    outputs: {
        "image": "blur.image",
        "metrics": "error.metrics",
    },
)
"#;

const NODES: [&str; 4] = ["noisy", "median", "blur", "error"];

fn open(dir: &std::path::Path, ms_per_node: f64) -> (EditorApp, egui::Context) {
    let path = dir.join("live.ron");
    std::fs::write(&path, GRAPH).unwrap();
    let mut app = app();
    app.open(&path).unwrap();
    let ctx = egui::Context::default();
    first_run(&ctx, &mut app);
    for id in NODES {
        app.costs.set(id, ms_per_node);
    }
    (app, ctx)
}

/// The runs started since `from` runs had: revision and outputs.
fn runs_since(app: &EditorApp, from: u64) -> Vec<(u64, Vec<String>)> {
    let history = app.runner.history();
    let skip = history.len() as u64 - (app.runner.started() - from);
    history.into_iter().skip(skip as usize).collect()
}

fn view(rev: u64) -> (u64, Vec<String>) {
    (rev, vec!["image".to_string()])
}

fn all(rev: u64) -> (u64, Vec<String>) {
    (rev, vec!["image".to_string(), "metrics".to_string()])
}

fn seed(app: &mut EditorApp, s: i64) -> u64 {
    app.set_param("noisy", "seed", ParamValue::Int(s)).unwrap();
    app.doc.revision
}

/// Frames until the viewer shows `revision`; the revisions of the images shown on the way.
fn frames_until_shown(ctx: &egui::Context, app: &mut EditorApp, revision: u64) -> Vec<u64> {
    let mut seen = Vec::new();
    let mut last = app.stats.last_image.as_ref().map(|i| i.revision);
    let t0 = Instant::now();
    loop {
        frame(ctx, app);
        let r = app.stats.last_image.as_ref().map(|i| i.revision);
        if r != last {
            seen.extend(r);
            last = r;
        }
        if r == Some(revision) {
            return seen;
        }
        assert!(t0.elapsed() < Duration::from_secs(300), "revision {revision} never shown: {}", app.status);
        std::thread::sleep(Duration::from_millis(2));
    }
}

#[test]
fn a_cheap_drag_runs_on_every_change_and_coalesces_behind_the_run_under_way() {
    let dir = tempfile::tempdir().unwrap();
    let (mut app, ctx) = open(dir.path(), 1.0);
    let (s0, c0) = (app.runner.started(), app.runner.cancelled());

    // The change starts its run in the frame it is made: no pause first.
    let r2 = seed(&mut app, 2);
    frame(&ctx, &mut app);
    assert_eq!(app.runner.started(), s0 + 1, "{}", app.status);
    assert!(app.runner.is_running(), "the median at 1024² is still under way");

    // Two more changes while it runs: neither cancels it nor starts another.
    seed(&mut app, 3);
    frame(&ctx, &mut app);
    let r4 = seed(&mut app, 4);
    frame(&ctx, &mut app);
    assert_eq!((app.runner.started(), app.runner.cancelled()), (s0 + 1, c0));

    // It ends, and the worker that ran it starts the newest value at once, before any frame.
    let t0 = Instant::now();
    while app.runner.started() == s0 + 1 {
        assert!(t0.elapsed() < Duration::from_secs(300), "the queued run never started");
        std::thread::sleep(Duration::from_millis(1));
    }
    assert_eq!(runs_since(&app, s0), [view(r2), view(r4)], "the middle value never runs");

    // Both show, in order.
    let seen = frames_until_shown(&ctx, &mut app, r4);
    assert_eq!(seen, [r2, r4]);
    let ran = app.report.as_ref().unwrap().ran_ids();
    assert_eq!(ran, ["blur", "median", "noisy"], "the viewed image alone");

    // The error figure follows once the drag has paused.
    until_idle(&ctx, &mut app);
    assert_eq!(app.report.as_ref().unwrap().ran_ids(), ["error"]);
    assert_eq!(runs_since(&app, s0), [view(r2), view(r4), all(r4)]);
    assert_eq!(app.runner.cancelled(), c0);
    let i = app.stats.last_image.as_ref().unwrap();
    assert!(i.latency_ms > 0.0 && i.nodes.iter().any(|(id, _)| id == "median"), "{i:?}");
}

#[test]
fn a_drag_on_a_dear_parameter_runs_once_after_the_pause() {
    let dir = tempfile::tempdir().unwrap();
    let (mut app, ctx) = open(dir.path(), 400.0);
    let s0 = app.runner.started();
    let mut last = 0;
    for s in 2..8 {
        last = seed(&mut app, s);
        frame(&ctx, &mut app);
        assert_eq!(app.runner.started(), s0, "no run while the drag goes on");
    }
    assert_eq!(frames_until_shown(&ctx, &mut app, last), [last]);
    until_idle(&ctx, &mut app);
    assert_eq!(runs_since(&app, s0), [view(last), all(last)], "one run for the drag's last value, then the rest");
    assert_eq!(app.runner.cancelled(), 0);
}

#[test]
fn an_edit_cancels_the_dear_run_it_makes_stale() {
    let dir = tempfile::tempdir().unwrap();
    let (mut app, ctx) = open(dir.path(), 400.0);
    let r2 = seed(&mut app, 2);
    let t0 = Instant::now();
    while !app.runner.is_running() {
        assert!(t0.elapsed() < Duration::from_secs(60), "the run after the pause never started");
        frame(&ctx, &mut app);
        std::thread::sleep(Duration::from_millis(5));
    }
    let (s0, c0) = (app.runner.started() - 1, app.runner.cancelled());
    let r3 = seed(&mut app, 3);
    assert_eq!(app.runner.cancelled(), c0 + 1, "the stale run is cancelled by the edit itself");
    assert!(!app.runner.is_running());
    let seen = frames_until_shown(&ctx, &mut app, r3);
    assert!(!seen.contains(&r2), "the cancelled run's image never shows: {seen:?}");
    until_idle(&ctx, &mut app);
    assert_eq!(runs_since(&app, s0), [view(r2), view(r3), all(r3)]);
}

#[test]
fn the_recorder_writes_a_row_per_frame_with_the_images_a_drag_showed() {
    let dir = tempfile::tempdir().unwrap();
    let (mut app, ctx) = open(dir.path(), 1.0);
    app.toggle_recording();
    let last = seed(&mut app, 2);
    frames_until_shown(&ctx, &mut app, last);
    app.toggle_recording();
    assert!(app.status.contains("live.frames.csv"), "{}", app.status);
    let csv = std::fs::read_to_string(dir.path().join("live.frames.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert!(rows.len() >= 2, "{csv}");
    let images: Vec<&&str> = rows.iter().filter(|r| r.split(',').nth(4) == Some("1")).collect();
    assert_eq!(images.len(), 1, "{csv}");
    assert_eq!(images[0].split(',').nth(5), Some(last.to_string().as_str()));
    assert!(images[0].ends_with(|c: char| c.is_ascii_digit()) && images[0].contains("median:"), "{}", images[0]);
}

/// A report of `NODES` from the cache, each said to have cost `ms` when it ran.
fn cached_report(ms: f64) -> relume_core::RunReport {
    let nodes = NODES.iter().map(|id| relume_core::NodeReport::timed(id, "cached", 0.1, ms)).collect();
    relume_core::RunReport { nodes, ..Default::default() }
}

#[test]
fn a_dear_cost_read_from_the_cache_is_tried_and_the_trial_cancelled_once_past_its_grace() {
    let dir = tempfile::tempdir().unwrap();
    let (mut app, ctx) = open(dir.path(), 1.0);
    app.costs = Default::default();
    app.costs.learn(&cached_report(400.0));
    app.probe_grace = Duration::from_millis(100);
    let (s0, c0) = (app.runner.started(), app.runner.cancelled());
    // Tried at once.
    let r2 = seed(&mut app, 2);
    assert_eq!(app.runner.started(), s0 + 1, "{:?}", app.when_edited());
    std::thread::sleep(Duration::from_millis(150));
    assert!(app.runner.is_running(), "the median at 1024² is still under way");
    // Past its grace: the next edit cancels it and the nodes are dear from now on.
    let r3 = seed(&mut app, 3);
    assert_eq!(app.runner.cancelled(), c0 + 1);
    assert_eq!(app.when_edited(), relume_editor::live::When::AfterPause);
    frame(&ctx, &mut app);
    assert_eq!(app.runner.started(), s0 + 1, "the edit waits for the pause");
    let seen = frames_until_shown(&ctx, &mut app, r3);
    assert_eq!(seen, [r3]);
    until_idle(&ctx, &mut app);
    assert_eq!(runs_since(&app, s0), [view(r2), view(r3), all(r3)]);
}

#[test]
fn a_dear_drag_that_shows_nothing_for_a_while_tries_its_run_again() {
    let dir = tempfile::tempdir().unwrap();
    let (mut app, ctx) = open(dir.path(), 400.0);
    app.reprobe_after = Duration::from_millis(100);
    let s0 = app.runner.started();
    seed(&mut app, 2);
    frame(&ctx, &mut app);
    assert_eq!(app.runner.started(), s0, "dear: it waits");
    std::thread::sleep(Duration::from_millis(150));
    // Still dragging, nothing shown for longer than the wait: tried at once.
    let r3 = seed(&mut app, 3);
    assert_eq!(app.runner.started(), s0 + 1);
    assert_eq!(frames_until_shown(&ctx, &mut app, r3), [r3]);
    until_idle(&ctx, &mut app);
    assert_eq!(runs_since(&app, s0), [view(r3), all(r3)]);
    // The trial ran to its end: what it measured is the cost now.
    assert!(app.costs.measured("median"));
}

#[test]
fn an_edit_during_the_first_run_runs_once_its_image_is_in_without_cancelling_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("live.ron");
    std::fs::write(&path, GRAPH).unwrap();
    let mut app = app();
    app.open(&path).unwrap();
    let ctx = egui::Context::default();
    frame(&ctx, &mut app);
    app.run();
    let r0 = app.doc.revision;
    let r1 = seed(&mut app, 2);
    assert!(app.runner.is_running(), "the median at 1024² is still under way");
    frame(&ctx, &mut app);
    assert_eq!(app.runner.cancelled(), 0, "the first run goes on");
    let seen = frames_until_shown(&ctx, &mut app, r1);
    assert_eq!(seen, [r0, r1], "the first run's image, then the edit's");
    until_idle(&ctx, &mut app);
}
