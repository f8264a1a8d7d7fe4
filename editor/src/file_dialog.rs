//! A small in-app file picker (no system dialog is needed, so it works the same on every
//! desktop and under Xvfb): a folder listing, a path field, OK and Cancel.

use std::path::{Path, PathBuf};

/// What the picker is for; the app acts on the chosen path.
#[derive(Clone, Debug, PartialEq)]
pub enum Purpose {
    Open,
    SaveAs,
    /// A file parameter of a node.
    Param {
        node: String,
        name: String,
    },
}

pub struct FileDialog {
    pub purpose: Purpose,
    dir: PathBuf,
    name: String,
    /// Only list files with this extension (`ron`), or everything.
    ext: Option<&'static str>,
}

impl FileDialog {
    pub fn new(purpose: Purpose, start: &Path, ext: Option<&'static str>) -> Self {
        let (dir, name) = if start.is_dir() {
            (start.to_path_buf(), String::new())
        } else {
            let dir = start.parent().filter(|d| !d.as_os_str().is_empty()).map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
            (dir, start.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default())
        };
        FileDialog { purpose, dir, name, ext }
    }

    /// Draws the picker; `Some(Some(path))` when chosen, `Some(None)` when cancelled.
    pub fn show(&mut self, ctx: &egui::Context) -> Option<Option<PathBuf>> {
        let mut result = None;
        let title = match &self.purpose {
            Purpose::Open => "Open graph".to_string(),
            Purpose::SaveAs => "Save graph as".to_string(),
            Purpose::Param { node, name } => format!("{node}.{name}"),
        };
        egui::Window::new(title).collapsible(false).default_width(420.0).show(ctx, |ui| {
            ui.horizontal(|ui| {
                if ui.button("up").on_hover_text("parent folder").clicked() {
                    if let Some(p) = self.dir.canonicalize().ok().and_then(|d| d.parent().map(Path::to_path_buf)) {
                        self.dir = p;
                    }
                }
                ui.monospace(self.dir.display().to_string());
            });
            egui::ScrollArea::vertical().max_height(260.0).show(ui, |ui| {
                for (name, is_dir) in list(&self.dir, self.ext) {
                    let label = if is_dir { format!("📁 {name}") } else { name.clone() };
                    let r = ui.selectable_label(self.name == name, label);
                    if r.clicked() {
                        if is_dir {
                            self.dir = self.dir.join(&name);
                        } else {
                            self.name = name.clone();
                        }
                    }
                    if r.double_clicked() && !is_dir {
                        result = Some(Some(self.dir.join(&name)));
                    }
                }
            });
            ui.horizontal(|ui| {
                ui.label("file");
                let r = ui.text_edit_singleline(&mut self.name);
                if r.lost_focus() && ui.input(|i| i.key_pressed(egui::Key::Enter)) && !self.name.is_empty() {
                    result = Some(Some(self.dir.join(&self.name)));
                }
            });
            ui.horizontal(|ui| {
                if ui.add_enabled(!self.name.is_empty(), egui::Button::new("OK")).clicked() {
                    result = Some(Some(self.dir.join(&self.name)));
                }
                if ui.button("Cancel").clicked() {
                    result = Some(None);
                }
            });
        });
        result
    }
}

/// Folders first, then files (with the extension when one is given), sorted by name.
fn list(dir: &Path, ext: Option<&str>) -> Vec<(String, bool)> {
    let Ok(rd) = std::fs::read_dir(dir) else { return Vec::new() };
    let mut v: Vec<(String, bool)> = rd
        .filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let is_dir = e.file_type().ok()?.is_dir();
            let shown = !name.starts_with('.') && (is_dir || ext.is_none_or(|x| name.ends_with(&format!(".{x}"))));
            shown.then_some((name, is_dir))
        })
        .collect();
    v.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    v
}
