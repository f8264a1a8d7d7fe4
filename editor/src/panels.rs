//! The editor's layout: menu bar, palette (left), properties, viewer and run report (right),
//! status bar (bottom), the node graph (centre), and the modal windows. The panels draw from
//! what `Panels` lends them and return what the user asked for as [`Action`]s, which the
//! editor carries out after the frame is drawn.

use crate::document::Document;
use crate::edit;
use crate::file_dialog::{FileDialog, Purpose};
use crate::palette::Palette;
use crate::params_ui::{param_widget, ParamAction};
use crate::view::{GraphView, ViewEdit};
use crate::viewer::Viewer;
use relume_core::graph::PortRef;
use relume_core::{ParamValue, Registry, RunReport};
use std::path::{Path, PathBuf};

/// What the user asked for in one frame of the panels.
pub enum Action {
    /// A node kind picked in the palette, to add at a point of the graph's layout.
    AddNode {
        kind: &'static str,
        at: [f64; 2],
    },
    /// Edits made in the node graph.
    ViewEdits(Vec<ViewEdit>),
    OpenDialog,
    SaveAsDialog,
    Save,
    SaveExrLayers,
    Undo,
    Redo,
    DeleteSelected,
    Run,
    Cancel,
    /// Start or stop recording frame times.
    ToggleRecording,
    SetParam {
        node: String,
        name: &'static str,
        value: ParamValue,
    },
    ResetParam {
        node: String,
        name: &'static str,
    },
    /// Choose a file for a file parameter, starting at `start`.
    BrowseParam {
        node: String,
        name: String,
        start: PathBuf,
    },
    /// Make a port a graph output named `name`, or stop (`on` false).
    SetOutput {
        port: PortRef,
        name: String,
        on: bool,
    },
    /// Show this output (a graph output name or `node.port`) in the viewer.
    ShowTarget(Option<String>),
    SaveAndClose,
    DiscardAndClose,
    KeepEditing,
    RestoreRecovery,
    DropRecovery,
    /// A file chosen in a file dialog, for the dialog's purpose.
    Chosen(Purpose, PathBuf),
}

/// What the panels read, and the widgets whose own state they change while drawing.
pub struct Panels<'a> {
    pub registry: &'a Registry,
    pub doc: &'a Document,
    pub view: &'a mut GraphView,
    pub viewer: &'a mut Viewer,
    pub palette: &'a mut Palette,
    pub dialog: &'a mut Option<FileDialog>,
    pub auto_run: &'a mut bool,
    /// The viewer-only layout: the viewer fills the centre, the parameters stay on the right,
    /// the palette and the node graph are hidden (F11). For drags at the pipeline's rate:
    /// under software OpenGL the node graph is about half of a frame.
    pub viewer_only: &'a mut bool,
    pub running: bool,
    pub status: &'a str,
    pub edit_to_image_ms: Option<f64>,
    pub view_target: Option<String>,
    pub image_outputs: Vec<String>,
    pub preview_shown: bool,
    pub partial_shown: bool,
    pub report: Option<&'a RunReport>,
    pub stats: &'a mut crate::frame_stats::FrameStats,
    /// The viewer tools the graph offers, and the one in use.
    pub tools: Vec<crate::tool::Tool>,
    pub tool: &'a mut Option<crate::tool::Tool>,
    pub quit_prompt: bool,
    pub recovery_offer: Option<&'a Path>,
}

/// Draws one frame of the panels; returns what the user asked for, in order.
/// A panel's frame without its fill: the window is cleared to the panels' colour
/// (`panel_clear`) instead. Under software OpenGL every pixel a shape covers costs the
/// fragment shader, and the panels' fills covered the whole window once more each frame.
fn unfilled(ctx: &egui::Context) -> egui::Frame {
    egui::Frame::side_top_panel(&ctx.style()).fill(egui::Color32::TRANSPARENT)
}

/// The colour the window is cleared to before the panels draw: theirs.
pub fn panel_clear(visuals: &egui::Visuals) -> [f32; 4] {
    visuals.panel_fill.to_normalized_gamma_f32()
}

pub fn draw(mut p: Panels, ctx: &egui::Context) -> Vec<Action> {
    let mut out = Vec::new();
    menu_bar(&mut p, ctx, &mut out);
    status_bar(&p, ctx);
    if *p.viewer_only {
        p.view.canvas_rect = None;
        egui::SidePanel::right("parameters").frame(unfilled(ctx)).resizable(true).default_width(440.0).max_width(640.0).show(ctx, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| properties(&p, ui, &mut out));
        });
        egui::CentralPanel::default().frame(unfilled(ctx)).show(ctx, |ui| {
            egui::ScrollArea::vertical().show(ui, |ui| viewer(&mut p, ui, &mut out));
        });
        dialogs(&mut p, ctx, &mut out);
        return out;
    }
    egui::SidePanel::left("palette").frame(unfilled(ctx)).default_width(170.0).show(ctx, |ui| {
        ui.heading("Nodes");
        if let Some(kind) = p.palette.show(ui, p.registry) {
            let at = p.view.xf.to_layout(egui::pos2(300.0, 200.0) - p.view.state.pan_zoom.pan);
            out.push(Action::AddNode { kind, at });
        }
    });
    egui::SidePanel::right("inspector").frame(unfilled(ctx)).resizable(true).default_width(440.0).max_width(640.0).show(ctx, |ui| {
        egui::ScrollArea::vertical().show(ui, |ui| {
            properties(&p, ui, &mut out);
            ui.separator();
            viewer(&mut p, ui, &mut out);
        });
    });
    egui::CentralPanel::default().frame(egui::Frame::canvas(&ctx.style()).fill(egui::Color32::TRANSPARENT)).show(ctx, |ui| {
        let edits = p.view.show(ui);
        if !edits.is_empty() {
            out.push(Action::ViewEdits(edits));
        }
    });
    dialogs(&mut p, ctx, &mut out);
    out
}

fn menu_bar(p: &mut Panels, ctx: &egui::Context, out: &mut Vec<Action>) {
    egui::TopBottomPanel::top("menu").frame(unfilled(ctx)).show(ctx, |ui| {
        egui::menu::bar(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open...  (Ctrl+O)").clicked() {
                    out.push(Action::OpenDialog);
                    ui.close_menu();
                }
                if ui.button("Save  (Ctrl+S)").clicked() {
                    out.push(Action::Save);
                    ui.close_menu();
                }
                if ui.button("Save as...  (Ctrl+Shift+S)").clicked() {
                    out.push(Action::SaveAsDialog);
                    ui.close_menu();
                }
                if ui
                    .button("Save image layers (EXR)")
                    .on_hover_text("every image output of the last run as one multi-layer EXR beside the graph")
                    .clicked()
                {
                    out.push(Action::SaveExrLayers);
                    ui.close_menu();
                }
                if ui.button("Quit").clicked() {
                    ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                    ui.close_menu();
                }
            });
            ui.menu_button("Edit", |ui| {
                if ui.add_enabled(p.doc.can_undo(), egui::Button::new("Undo  (Ctrl+Z)")).clicked() {
                    out.push(Action::Undo);
                    ui.close_menu();
                }
                if ui.add_enabled(p.doc.can_redo(), egui::Button::new("Redo  (Ctrl+Shift+Z)")).clicked() {
                    out.push(Action::Redo);
                    ui.close_menu();
                }
                if ui.button("Delete selected  (Del)").clicked() {
                    out.push(Action::DeleteSelected);
                    ui.close_menu();
                }
            });
            ui.menu_button("View", |ui| {
                if ui
                    .checkbox(p.viewer_only, "Viewer only  (F11)")
                    .on_hover_text("the viewer in the centre, the parameters beside it; the palette and the node graph hidden")
                    .changed()
                {
                    ui.close_menu();
                }
            });
            ui.separator();
            let running = p.running;
            if ui.add_enabled(!running, egui::Button::new("▶ Run (F5)")).clicked() {
                out.push(Action::Run);
            }
            if ui.add_enabled(running, egui::Button::new("■ Cancel")).clicked() {
                out.push(Action::Cancel);
            }
            ui.checkbox(p.auto_run, "re-run on edit");
        });
    });
}

fn status_bar(p: &Panels, ctx: &egui::Context) {
    egui::TopBottomPanel::bottom("status").frame(unfilled(ctx)).show(ctx, |ui| {
        ui.horizontal(|ui| {
            if p.running {
                ui.spinner();
            }
            ui.label(p.status);
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                if let Some(ms) = p.edit_to_image_ms {
                    ui.label(format!("edit to image {}", crate::fmt_ms(ms)))
                        .on_hover_text("time from the last edit to the refreshed image in the viewer");
                }
            });
        });
    });
}

/// Parameters, ports and outputs of the selected node.
fn properties(p: &Panels, ui: &mut egui::Ui, out: &mut Vec<Action>) {
    let sel = p.view.selected_ids();
    let [id] = sel.as_slice() else {
        ui.weak(if sel.is_empty() { "select a node to edit its parameters" } else { "several nodes selected" });
        return;
    };
    let Some(decl) = p.doc.graph.node(id) else { return };
    let Some(kind) = p.registry.node(&decl.kind) else { return };
    ui.heading(format!("{id}  ({})", decl.kind));
    egui::CollapsingHeader::new("about").default_open(false).show(ui, |ui| {
        ui.label(kind.doc());
    });
    for spec in &kind.schema().0 {
        let explicit = decl.param(spec.name);
        let value = explicit.or(spec.default.as_ref());
        match param_widget(ui, spec, value, explicit.is_some()) {
            Some(ParamAction::Set(v)) => {
                out.push(Action::SetParam { node: id.clone(), name: spec.name, value: v });
            }
            Some(ParamAction::Reset) => {
                out.push(Action::ResetParam { node: id.clone(), name: spec.name });
            }
            Some(ParamAction::Browse) => {
                let start = match value {
                    Some(ParamValue::Text(s)) if !s.is_empty() => p.doc.graph.base_dir.join(s),
                    _ => p.doc.graph.base_dir.clone(),
                };
                out.push(Action::BrowseParam { node: id.clone(), name: spec.name.into(), start });
            }
            None => {}
        }
    }
    ui.add_space(4.0);
    ui.label("outputs");
    for o in &kind.ports().outputs {
        let port = PortRef { node: id.clone(), port: o.name.into() };
        ui.horizontal(|ui| {
            let c = egui::Color32::from_rgb(o.ty.color[0], o.ty.color[1], o.ty.color[2]);
            ui.colored_label(c, "●");
            ui.label(format!("{} ({})", o.name, o.ty.name)).on_hover_text(o.ty.doc);
            let current = p.doc.graph.outputs.iter().find(|o| o.port == port).map(|o| o.name.clone());
            let mut on = current.is_some();
            if ui.checkbox(&mut on, "graph output").changed() {
                let name = current.unwrap_or_else(|| edit::output_name(&p.doc.graph, &port));
                out.push(Action::SetOutput { port: port.clone(), name, on });
            }
            if o.ty.name == "Image" && ui.small_button("view").clicked() {
                let target = p.doc.graph.outputs.iter().find(|o| o.port == port).map(|o| o.name.clone()).unwrap_or(port.to_string());
                out.push(Action::ShowTarget(Some(target)));
            }
        });
    }
}

fn viewer(p: &mut Panels, ui: &mut egui::Ui, out: &mut Vec<Action>) {
    ui.horizontal(|ui| {
        ui.heading("Viewer");
        let mut targets = p.image_outputs.clone();
        if let Some(t) = &p.view_target {
            if !targets.contains(t) {
                targets.push(t.clone());
            }
        }
        let mut chosen = p.view_target.clone();
        egui::ComboBox::from_id_salt("view_target").selected_text(chosen.clone().unwrap_or_default()).show_ui(ui, |ui| {
            for t in targets {
                ui.selectable_value(&mut chosen, Some(t.clone()), t);
            }
        });
        if chosen != p.view_target {
            out.push(Action::ShowTarget(chosen));
        }
        if p.partial_shown {
            ui.label(egui::RichText::new("partial").strong())
                .on_hover_text("the viewed image as far as its renderer got: finished bands, and the band under way pass by pass");
        }
        if p.preview_shown {
            ui.label(egui::RichText::new("preview").strong())
                .on_hover_text("the graph's `preview` output, shown while the viewed image is computed");
        }
    });
    p.viewer.controls(ui);
    ui.horizontal(|ui| {
        ui.checkbox(&mut p.stats.overlay, "frame times")
            .on_hover_text("images and frames per second, edit-to-pixels latency and the last run's slowest nodes, over the image");
        let label = if p.stats.is_recording() { "■ stop recording" } else { "● record" };
        if ui.button(label).on_hover_text("record every frame's time and each new image's latency to CSV beside the graph").clicked() {
            out.push(Action::ToggleRecording);
        }
    });
    if !p.tools.is_empty() {
        ui.horizontal_wrapped(|ui| {
            ui.label("tool");
            ui.selectable_value(p.tool, None, "none").on_hover_text("the pointer only reads pixel values");
            for &t in &p.tools {
                ui.selectable_value(p.tool, Some(t), t.label()).on_hover_text(t.hint());
            }
        });
        // Always one line, so that choosing a tool does not move the image under the pointer.
        ui.weak(p.tool.map_or("choose a tool to edit the scene in the image", |t| t.hint()));
    }
    let h = ui.available_width().min(420.0);
    ui.allocate_ui(egui::vec2(ui.available_width(), h), |ui| {
        p.viewer.show(ui);
        if let Some(r) = p.viewer.image_rect {
            p.stats.draw_overlay(ui, r);
        }
    });
    if let Some(r) = p.report {
        egui::CollapsingHeader::new("run report").default_open(true).show(ui, |ui| crate::viewer::report_table(ui, r));
    }
}

fn dialogs(p: &mut Panels, ctx: &egui::Context, out: &mut Vec<Action>) {
    if let Some(d) = p.dialog {
        if let Some(choice) = d.show(ctx) {
            let purpose = d.purpose.clone();
            *p.dialog = None;
            if let Some(path) = choice {
                out.push(Action::Chosen(purpose, path));
            }
        }
    }
    if p.quit_prompt {
        egui::Window::new("Unsaved changes").collapsible(false).resizable(false).show(ctx, |ui| {
            ui.label(format!("{} has changes that are not saved.", p.doc.title()));
            ui.horizontal(|ui| {
                if ui.button("Save").clicked() {
                    out.push(Action::SaveAndClose);
                }
                if ui.button("Discard").clicked() {
                    out.push(Action::DiscardAndClose);
                }
                if ui.button("Cancel").clicked() {
                    out.push(Action::KeepEditing);
                }
            });
        });
    }
    if let Some(path) = p.recovery_offer {
        egui::Window::new("Recover unsaved work?").collapsible(false).resizable(false).show(ctx, |ui| {
            ui.label(format!("{} holds changes from a session that ended without saving.", path.display()));
            ui.horizontal(|ui| {
                if ui.button("Restore").clicked() {
                    out.push(Action::RestoreRecovery);
                }
                if ui.button("Discard").clicked() {
                    out.push(Action::DropRecovery);
                }
            });
        });
    }
}
