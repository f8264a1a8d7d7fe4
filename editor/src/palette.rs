//! The palette: every registered node kind by category, filtered by a search field; the
//! doc comment is the tooltip. Clicking a kind adds it to the graph.

use relume_core::Registry;
use std::collections::BTreeMap;

#[derive(Default)]
pub struct Palette {
    pub search: String,
}

impl Palette {
    /// Kinds matching the search (case-insensitive, in name or category), by category.
    pub fn matches(&self, reg: &Registry) -> BTreeMap<&'static str, Vec<&'static str>> {
        let q = self.search.to_lowercase();
        let mut out: BTreeMap<&'static str, Vec<&'static str>> = BTreeMap::new();
        for n in reg.nodes() {
            if q.is_empty() || n.kind().to_lowercase().contains(&q) || n.category().to_lowercase().contains(&q) {
                out.entry(n.category()).or_default().push(n.kind());
            }
        }
        out
    }

    /// Draws the palette; returns the kind clicked.
    pub fn show(&mut self, ui: &mut egui::Ui, reg: &Registry) -> Option<&'static str> {
        let mut picked = None;
        ui.add(egui::TextEdit::singleline(&mut self.search).hint_text("search nodes"));
        let searching = !self.search.is_empty();
        egui::ScrollArea::vertical().show(ui, |ui| {
            for (cat, kinds) in self.matches(reg) {
                egui::CollapsingHeader::new(cat).default_open(true).open(searching.then_some(true)).show(ui, |ui| {
                    for k in kinds {
                        let doc = reg.node(k).map(|n| n.doc().to_string()).unwrap_or_default();
                        if ui.button(k).on_hover_text(doc).clicked() {
                            picked = Some(k);
                        }
                    }
                });
            }
        });
        picked
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn search_filters_by_name_and_category() {
        let reg = crate::registry();
        let mut p = Palette::default();
        let all: usize = p.matches(&reg).values().map(Vec::len).sum();
        assert_eq!(all, reg.nodes().count());
        p.search = "blur".into();
        let found: Vec<&str> = p.matches(&reg).into_values().flatten().collect();
        assert_eq!(found, ["GaussianBlur"]);
    }
}
