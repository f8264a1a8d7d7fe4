//! Parameter widgets generated from a node's schema: sliders with the schema's range and unit,
//! colour pickers for RGB, combo boxes for enums, path fields with a picker for files; each
//! with its help as tooltip and a reset to the default.

use relume_core::{ParamKind, ParamSpec, ParamValue};

/// What the user did to one parameter this frame.
#[derive(Debug, PartialEq)]
pub enum ParamAction {
    Set(ParamValue),
    Reset,
    /// Open the file picker for this parameter.
    Browse,
}

fn nums(v: &ParamValue) -> Vec<f64> {
    match v {
        ParamValue::Float(f) => vec![*f],
        ParamValue::Int(i) => vec![*i as f64],
        ParamValue::Tuple(items) => items.iter().flat_map(nums).collect(),
        _ => vec![],
    }
}

fn tuple(v: [f64; 3]) -> ParamValue {
    ParamValue::Tuple(v.iter().map(|&x| ParamValue::Float(x)).collect())
}

/// A slider when the range is short enough to drag across, else a drag value clamped to it.
fn float_widget(ui: &mut egui::Ui, x: &mut f64, min: f64, max: f64, unit: &str) -> bool {
    let suffix = if unit.is_empty() { String::new() } else { format!(" {unit}") };
    if (max - min).is_finite() && max - min <= 1e4 {
        let log = min > 0.0 && max / min > 1e3;
        ui.add(egui::Slider::new(x, min..=max).logarithmic(log).suffix(suffix)).changed()
    } else {
        let speed = (x.abs() * 0.01).max(0.01);
        ui.add(egui::DragValue::new(x).range(min..=max).speed(speed).suffix(suffix)).changed()
    }
}

fn int_widget(ui: &mut egui::Ui, x: &mut i64, min: i64, max: i64, unit: &str) -> bool {
    let suffix = if unit.is_empty() { String::new() } else { format!(" {unit}") };
    if max.saturating_sub(min) <= 4096 {
        ui.add(egui::Slider::new(x, min..=max).suffix(suffix)).changed()
    } else {
        let speed = ((*x).abs() as f64 * 0.01).max(1.0);
        ui.add(egui::DragValue::new(x).range(min..=max).speed(speed).suffix(suffix)).changed()
    }
}

/// Draws the widget for one parameter holding `value` (`explicit`: written in the file).
pub fn param_widget(ui: &mut egui::Ui, spec: &ParamSpec, value: Option<&ParamValue>, explicit: bool) -> Option<ParamAction> {
    let mut action = None;
    ui.horizontal(|ui| {
        let name = if explicit { egui::RichText::new(spec.name).strong() } else { egui::RichText::new(spec.name) };
        let help = format!(
            "{} ({}{}{})",
            spec.help,
            spec.kind.type_name(),
            if spec.kind.range_text().is_empty() { "" } else { " " },
            spec.kind.range_text()
        );
        ui.label(name).on_hover_text(help);
        let v = value.cloned();
        match (&spec.kind, v) {
            (ParamKind::Float { min, max }, Some(v)) => {
                let mut x = nums(&v).first().copied().unwrap_or(0.0);
                if float_widget(ui, &mut x, *min, *max, spec.unit) {
                    action = Some(ParamAction::Set(ParamValue::Float(x)));
                }
            }
            (ParamKind::Int { min, max }, Some(ParamValue::Int(mut x))) => {
                if int_widget(ui, &mut x, *min, *max, spec.unit) {
                    action = Some(ParamAction::Set(ParamValue::Int(x)));
                }
            }
            (ParamKind::Bool, Some(ParamValue::Bool(mut b))) => {
                if ui.checkbox(&mut b, "").changed() {
                    action = Some(ParamAction::Set(ParamValue::Bool(b)));
                }
            }
            (ParamKind::Enum(variants), Some(ParamValue::Ident(cur) | ParamValue::Text(cur))) => {
                let mut sel = cur.clone();
                egui::ComboBox::from_id_salt(spec.name).selected_text(&sel).show_ui(ui, |ui| {
                    for v in variants.iter() {
                        ui.selectable_value(&mut sel, v.to_string(), *v);
                    }
                });
                if sel != cur {
                    action = Some(ParamAction::Set(ParamValue::Ident(sel)));
                }
            }
            (ParamKind::Rgb { min, max }, Some(v)) => {
                let c = nums(&v);
                if c.len() == 3 {
                    let mut c3 = [c[0], c[1], c[2]];
                    let mut changed = false;
                    if *min >= 0.0 && *max <= 1.0 {
                        let mut f = [c3[0] as f32, c3[1] as f32, c3[2] as f32];
                        if ui.color_edit_button_rgb(&mut f).changed() {
                            c3 = [f[0] as f64, f[1] as f64, f[2] as f64];
                            changed = true;
                        }
                    }
                    for x in &mut c3 {
                        changed |= ui.add(egui::DragValue::new(x).range(*min..=*max).speed(0.01).max_decimals(4)).changed();
                    }
                    if changed {
                        action = Some(ParamAction::Set(tuple(c3)));
                    }
                }
            }
            (ParamKind::Vec3, Some(v)) => {
                let c = nums(&v);
                if c.len() == 3 {
                    let mut c3 = [c[0], c[1], c[2]];
                    let mut changed = false;
                    for x in &mut c3 {
                        changed |= ui.add(egui::DragValue::new(x).speed(0.01).max_decimals(4)).changed();
                    }
                    if changed {
                        action = Some(ParamAction::Set(tuple(c3)));
                    }
                }
            }
            (ParamKind::Text | ParamKind::InputFile | ParamKind::OutputFile, v) => {
                let mut s = match v {
                    Some(ParamValue::Text(s)) => s,
                    _ => String::new(),
                };
                let r = ui.add(egui::TextEdit::singleline(&mut s).desired_width(160.0).hint_text("required"));
                if r.changed() && (spec.kind == ParamKind::Text || !s.is_empty()) {
                    action = Some(ParamAction::Set(ParamValue::Text(s)));
                }
                if spec.kind != ParamKind::Text && ui.button("...").on_hover_text("choose a file").clicked() {
                    action = Some(ParamAction::Browse);
                }
            }
            (_, other) => {
                ui.label(other.map(|v| v.to_text()).unwrap_or_else(|| "(required)".into()));
            }
        }
        if explicit && spec.default.is_some() && ui.small_button("reset").on_hover_text("reset to the default").clicked() {
            action = Some(ParamAction::Reset);
        }
    });
    action
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Drives one frame of the widget headlessly and returns what it reported.
    fn frame(spec: &ParamSpec, v: Option<&ParamValue>) -> Option<ParamAction> {
        let ctx = egui::Context::default();
        let mut out = None;
        let _ = ctx.run(egui::RawInput::default(), |ctx| {
            egui::CentralPanel::default().show(ctx, |ui| out = param_widget(ui, spec, v, true));
        });
        out
    }

    #[test]
    fn every_schema_kind_draws_without_acting() {
        let reg = crate::registry();
        for n in reg.nodes() {
            for spec in &n.schema().0 {
                let v = spec.default.clone();
                assert_eq!(frame(spec, v.as_ref()), None, "{}.{} acted without input", n.kind(), spec.name);
            }
        }
    }
}
