//! The editor's layout: menu bar, palette (left), properties, viewer and run report (right),
//! status bar (bottom), the node graph (centre), and the modal windows.

use crate::app::EditorApp;
use crate::edit;
use crate::file_dialog::{FileDialog, Purpose};
use crate::params_ui::{param_widget, ParamAction};
use relume_core::graph::PortRef;
use relume_core::ParamValue;
use std::path::{Path, PathBuf};

pub fn open_dialog(app: &EditorApp) -> FileDialog {
    let start = app.doc.path.as_ref().and_then(|p| p.parent()).map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
    FileDialog::new(Purpose::Open, &start, Some("ron"))
}

pub fn save_as_dialog(app: &EditorApp) -> FileDialog {
    let start = app.doc.path.clone().unwrap_or_else(|| PathBuf::from("untitled.ron"));
    FileDialog::new(Purpose::SaveAs, &start, Some("ron"))
}

pub fn draw(app: &mut EditorApp, ctx: &egui::Context) {
    menu_bar(app, ctx);
    status_bar(app, ctx);
    egui::SidePanel::left("palette").default_width(170.0).show(ctx, |ui| {
        ui.heading("Nodes");
        if let Some(kind) = app.palette.show(ui, &app.registry) {
            let at = app.view.xf.to_layout(egui::pos2(300.0, 200.0) - app.view.state.pan_zoom.pan);
            app.add_from_palette(kind, at);
        }
    });
    egui::SidePanel::right("inspector").resizable(true).default_width(440.0).max_width(640.0).show(ctx, |ui| {
        egui::ScrollArea::vertical().show(ui, |ui| {
            properties(app, ui);
            ui.separator();
            viewer(app, ui);
        });
    });
    egui::CentralPanel::default().frame(egui::Frame::canvas(&ctx.style())).show(ctx, |ui| {
        let edits = app.view.show(ui);
        app.apply_view_edits(edits);
    });
    dialogs(app, ctx);
}

fn menu_bar(app: &mut EditorApp, ctx: &egui::Context) {
    egui::TopBottomPanel::top("menu").show(ctx, |ui| {
        egui::menu::bar(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.button("Open...  (Ctrl+O)").clicked() {
                    app.dialog = Some(open_dialog(app));
                    ui.close_menu();
                }
                if ui.button("Save  (Ctrl+S)").clicked() {
                    app.save();
                    ui.close_menu();
                }
                if ui.button("Save as...  (Ctrl+Shift+S)").clicked() {
                    app.dialog = Some(save_as_dialog(app));
                    ui.close_menu();
                }
                if ui
                    .button("Save image layers (EXR)")
                    .on_hover_text("every image output of the last run as one multi-layer EXR beside the graph")
                    .clicked()
                {
                    app.save_exr_layers();
                    ui.close_menu();
                }
                if ui.button("Quit").clicked() {
                    ctx.send_viewport_cmd(egui::ViewportCommand::Close);
                    ui.close_menu();
                }
            });
            ui.menu_button("Edit", |ui| {
                if ui.add_enabled(app.doc.can_undo(), egui::Button::new("Undo  (Ctrl+Z)")).clicked() {
                    app.undo();
                    ui.close_menu();
                }
                if ui.add_enabled(app.doc.can_redo(), egui::Button::new("Redo  (Ctrl+Shift+Z)")).clicked() {
                    app.redo();
                    ui.close_menu();
                }
                if ui.button("Delete selected  (Del)").clicked() {
                    app.delete_selected();
                    ui.close_menu();
                }
            });
            ui.separator();
            let running = app.runner.is_running();
            if ui.add_enabled(!running, egui::Button::new("▶ Run (F5)")).clicked() {
                app.run();
            }
            if ui.add_enabled(running, egui::Button::new("■ Cancel")).clicked() {
                app.cancel();
            }
            ui.checkbox(&mut app.auto_run, "re-run on edit");
        });
    });
}

fn status_bar(app: &mut EditorApp, ctx: &egui::Context) {
    egui::TopBottomPanel::bottom("status").show(ctx, |ui| {
        ui.horizontal(|ui| {
            if app.runner.is_running() {
                ui.spinner();
            }
            ui.label(&app.status);
            ui.with_layout(egui::Layout::right_to_left(egui::Align::Center), |ui| {
                if let Some(ms) = app.edit_to_image_ms {
                    ui.label(format!("edit to image {}", crate::fmt_ms(ms)))
                        .on_hover_text("time from the last edit to the refreshed image in the viewer");
                }
            });
        });
    });
}

/// Parameters, ports and outputs of the selected node.
fn properties(app: &mut EditorApp, ui: &mut egui::Ui) {
    let sel = app.view.selected_ids();
    let [id] = sel.as_slice() else {
        ui.weak(if sel.is_empty() { "select a node to edit its parameters" } else { "several nodes selected" });
        return;
    };
    let Some(decl) = app.doc.graph.node(id).cloned() else { return };
    let Some(kind) = app.registry.node(&decl.kind).cloned() else { return };
    ui.heading(format!("{id}  ({})", decl.kind));
    egui::CollapsingHeader::new("about").default_open(false).show(ui, |ui| {
        ui.label(kind.doc());
    });
    for spec in &kind.schema().0 {
        let explicit = decl.param(spec.name);
        let value = explicit.or(spec.default.as_ref());
        match param_widget(ui, spec, value, explicit.is_some()) {
            Some(ParamAction::Set(v)) => {
                if let Err(m) = app.set_param(id, spec.name, v) {
                    app.status = m;
                }
            }
            Some(ParamAction::Reset) => {
                let name = spec.name;
                app.apply(&format!("param:{id}.{name}"), true, |g| edit::reset_param(g, id, name));
                app.doc.seal();
            }
            Some(ParamAction::Browse) => {
                let start = match value {
                    Some(ParamValue::Text(s)) if !s.is_empty() => app.doc.graph.base_dir.join(s),
                    _ => app.doc.graph.base_dir.clone(),
                };
                app.dialog = Some(FileDialog::new(Purpose::Param { node: id.clone(), name: spec.name.into() }, &start, None));
            }
            None => {}
        }
    }
    ui.add_space(4.0);
    ui.label("outputs");
    for p in &kind.ports().outputs {
        let port = PortRef { node: id.clone(), port: p.name.into() };
        ui.horizontal(|ui| {
            let c = egui::Color32::from_rgb(p.ty.color[0], p.ty.color[1], p.ty.color[2]);
            ui.colored_label(c, "●");
            ui.label(format!("{} ({})", p.name, p.ty.name)).on_hover_text(p.ty.doc);
            let current = app.doc.graph.outputs.iter().find(|o| o.port == port).map(|o| o.name.clone());
            let mut on = current.is_some();
            if ui.checkbox(&mut on, "graph output").changed() {
                let name = current.unwrap_or_else(|| edit::output_name(&app.doc.graph, &port));
                app.apply("outputs", true, |g| edit::set_output(g, &port, &name, on));
                app.doc.seal();
            }
            if p.ty.name == "Image" && ui.small_button("view").clicked() {
                let target = app.doc.graph.outputs.iter().find(|o| o.port == port).map(|o| o.name.clone()).unwrap_or(port.to_string());
                app.view_target = Some(target);
                app.show_target();
            }
        });
    }
}

fn viewer(app: &mut EditorApp, ui: &mut egui::Ui) {
    ui.horizontal(|ui| {
        ui.heading("Viewer");
        let mut targets = app.image_outputs();
        if let Some(t) = &app.view_target {
            if !targets.contains(t) {
                targets.push(t.clone());
            }
        }
        let before = app.view_target.clone();
        egui::ComboBox::from_id_salt("view_target").selected_text(app.view_target.clone().unwrap_or_default()).show_ui(ui, |ui| {
            for t in targets {
                ui.selectable_value(&mut app.view_target, Some(t.clone()), t);
            }
        });
        if before != app.view_target {
            app.show_target();
        }
        if app.preview_shown {
            ui.label(egui::RichText::new("preview").strong())
                .on_hover_text("the graph's `preview` output, shown while the viewed image is computed");
        }
    });
    app.viewer.controls(ui);
    let h = ui.available_width().min(420.0);
    ui.allocate_ui(egui::vec2(ui.available_width(), h), |ui| app.viewer.show(ui));
    if let Some(r) = &app.report {
        egui::CollapsingHeader::new("run report").default_open(true).show(ui, |ui| crate::viewer::report_table(ui, r));
    }
}

fn dialogs(app: &mut EditorApp, ctx: &egui::Context) {
    if let Some(d) = &mut app.dialog {
        if let Some(choice) = d.show(ctx) {
            let purpose = d.purpose.clone();
            app.dialog = None;
            if let Some(path) = choice {
                chosen(app, purpose, path);
            }
        }
    }
    if app.quit_prompt {
        egui::Window::new("Unsaved changes").collapsible(false).resizable(false).show(ctx, |ui| {
            ui.label(format!("{} has changes that are not saved.", app.doc.title()));
            ui.horizontal(|ui| {
                if ui.button("Save").clicked() {
                    app.save_and_close(ctx);
                }
                if ui.button("Discard").clicked() {
                    app.discard_and_close(ctx);
                }
                if ui.button("Cancel").clicked() {
                    app.quit_prompt = false;
                }
            });
        });
    }
    if let Some(path) = app.recovery_offer.clone() {
        egui::Window::new("Recover unsaved work?").collapsible(false).resizable(false).show(ctx, |ui| {
            ui.label(format!("{} holds changes from a session that ended without saving.", path.display()));
            ui.horizontal(|ui| {
                if ui.button("Restore").clicked() {
                    let reg = app.registry.clone();
                    app.status = match app.doc.restore_recovery(&reg) {
                        Ok(()) => "restored the unsaved changes (Ctrl+Z undoes)".into(),
                        Err(e) => e,
                    };
                    app.recovery_offer = None;
                }
                if ui.button("Discard").clicked() {
                    app.doc.drop_recovery();
                    app.recovery_offer = None;
                }
            });
        });
    }
}

fn chosen(app: &mut EditorApp, purpose: Purpose, path: PathBuf) {
    match purpose {
        Purpose::Open => {
            if app.doc.is_dirty() {
                app.status = "save or undo the unsaved changes before opening another graph".into();
                return;
            }
            if let Err(e) = app.open(&path) {
                app.status = e;
            }
        }
        Purpose::SaveAs => {
            let path = if path.extension().is_none() { path.with_extension("ron") } else { path };
            app.status = match app.doc.save_as(&path) {
                Ok(()) => format!("saved {}", path.display()),
                Err(e) => e,
            };
        }
        Purpose::Param { node, name } => {
            let base = app.doc.graph.base_dir.clone();
            let rel = path.strip_prefix(&base).map(Path::to_path_buf).unwrap_or(path);
            if let Err(m) = app.set_param(&node, &name, ParamValue::Text(rel.to_string_lossy().into_owned())) {
                app.status = m;
            }
        }
    }
}
