//! relume-editor: the visual node editor. The core `Graph` is the document; the node-graph
//! widget (egui_node_graph2) is a view of it; runs go through the core `Engine` in the
//! background. `EditorApp::ui` draws a frame on any egui context, so everything but the
//! window itself is tested headlessly.
//!
//! Headless, as its tests drive it: open a graph, run it, wait, and read what the viewer
//! would show.
//!
//! ```
//! let mut app = relume_editor::EditorApp::new(relume_editor::registry(), relume_core::Engine::new(relume_editor::registry()));
//! app.open(std::path::Path::new("../graphs/filters.ron")).unwrap();
//! app.run();
//! app.wait_for_run();
//! assert!(app.last_output_image("image").is_some());
//! ```

pub mod app;
pub mod document;
pub mod drive;
pub mod edit;
pub mod file_dialog;
pub mod frame_stats;
pub mod live;
pub mod manipulate;
pub mod palette;
pub mod panels;
pub mod params_ui;
pub mod pick;
pub mod runner;
pub mod screenshot;
pub mod tool;
pub mod view;
pub mod viewer;

pub use app::EditorApp;

use relume_core::Registry;

/// A registry with every node kind: the base's and each pipeline's.
pub fn registry() -> Registry {
    let mut r = relume_base::registry();
    relume_pbgi::register(&mut r);
    relume_ptt::register(&mut r);
    relume_relight::register(&mut r);
    relume_volume::register(&mut r);
    r
}

/// Milliseconds for people: `85 ms`, `1.24 s`.
pub fn fmt_ms(ms: f64) -> String {
    if ms < 1000.0 {
        format!("{ms:.0} ms")
    } else {
        format!("{:.2} s", ms / 1000.0)
    }
}
