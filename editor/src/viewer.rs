//! The viewer panel: an image output tone-mapped for the screen (exposure in stops, curve),
//! the linear pixel value under the pointer, and the run report.

use egui::{Color32, ColorImage, TextureHandle, TextureOptions};
use relume_base::image::tonemap::{tonemap_channel, Operator};
use relume_base::math::srgb::srgb_encode_u8;
use relume_base::types::Image;
use relume_core::RunReport;
use std::sync::Arc;

/// What the pointer did on the image this frame, in image pixels (x right, y down), for the
/// manipulators.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ViewerInput {
    /// The image's size in pixels.
    pub size: [usize; 2],
    /// Where the pointer is over the image (or dragging from it).
    pub pointer: Option<egui::Pos2>,
    /// Where the button went down, while it is held.
    pub origin: Option<egui::Pos2>,
    /// A drag began on the image this frame.
    pub pressed: bool,
    /// A drag is under way.
    pub dragging: bool,
    /// The drag ended this frame.
    pub released: bool,
    /// A click (press and release without a drag).
    pub clicked: bool,
    /// The drag uses the secondary button or holds shift.
    pub alternate: bool,
    /// Wheel turn over the image this frame (points; positive away from the user).
    pub scroll: f32,
}

pub struct Viewer {
    pub exposure: f32,
    pub operator: Operator,
    image: Option<Arc<Image>>,
    texture: Option<TextureHandle>,
    /// The texture needs rebuilding (new image or new exposure).
    dirty: bool,
    /// Where the image was drawn last frame, in points (the screenshot check reads it).
    pub image_rect: Option<egui::Rect>,
    /// What the pointer did on the image this frame.
    pub input: ViewerInput,
}

impl Default for Viewer {
    fn default() -> Self {
        Viewer {
            exposure: 0.0,
            operator: Operator::Aces,
            image: None,
            texture: None,
            dirty: false,
            image_rect: None,
            input: ViewerInput::default(),
        }
    }
}

/// Display colour of a linear pixel: exposure, curve, sRGB encoding.
pub fn display(p: [f32; 3], exposure: f32, op: Operator) -> Color32 {
    shown(p, exposure.exp2(), op)
}

/// `display` with the exposure as a factor.
fn shown(p: [f32; 3], scale: f32, op: Operator) -> Color32 {
    let c = |x: f32| srgb_encode_u8(tonemap_channel(x, scale, op));
    Color32::from_rgb(c(p[0]), c(p[1]), c(p[2]))
}

/// The whole image for the screen.
pub fn to_color_image(img: &Image, exposure: f32, op: Operator) -> ColorImage {
    let scale = exposure.exp2();
    ColorImage { size: [img.width, img.height], pixels: img.pixels.iter().map(|&p| shown(p, scale, op)).collect() }
}

impl Viewer {
    pub fn set_image(&mut self, img: Option<Arc<Image>>) {
        self.image = img;
        self.dirty = true;
    }

    pub fn image(&self) -> Option<&Arc<Image>> {
        self.image.as_ref()
    }

    pub fn has_image(&self) -> bool {
        self.image.is_some()
    }

    /// Exposure and curve controls.
    pub fn controls(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            let before = (self.exposure, self.operator);
            ui.label("exposure");
            ui.add(egui::Slider::new(&mut self.exposure, -10.0..=10.0).step_by(0.1).suffix(" stops"));
            egui::ComboBox::from_id_salt("tonecurve").selected_text(format!("{:?}", self.operator)).show_ui(ui, |ui| {
                for op in [Operator::Aces, Operator::Reinhard, Operator::Clamp] {
                    ui.selectable_value(&mut self.operator, op, format!("{op:?}"));
                }
            });
            if before != (self.exposure, self.operator) {
                self.dirty = true;
            }
        });
    }

    /// The image, scaled to fit, with the pixel under the pointer.
    pub fn show(&mut self, ui: &mut egui::Ui) {
        let Some(img) = self.image.clone() else {
            self.image_rect = None;
            self.input = ViewerInput::default();
            ui.weak("no image yet: run the graph (F5)");
            return;
        };
        if self.dirty || self.texture.is_none() {
            let ci = to_color_image(&img, self.exposure, self.operator);
            match &mut self.texture {
                Some(t) => t.set(ci, TextureOptions::NEAREST),
                None => self.texture = Some(ui.ctx().load_texture("viewer", ci, TextureOptions::NEAREST)),
            }
            self.dirty = false;
        }
        let tex = self.texture.as_ref().expect("made above");
        let avail = ui.available_size() - egui::vec2(0.0, 24.0);
        let s = (avail.x / img.width as f32).min(avail.y / img.height as f32).max(0.05);
        let size = egui::vec2(img.width as f32, img.height as f32) * s;
        let resp = ui.add(egui::Image::new((tex.id(), size)).sense(egui::Sense::click_and_drag()));
        self.image_rect = Some(resp.rect);
        self.input = pointer_input(ui, &resp, s, [img.width, img.height]);
        let text = match resp.hover_pos() {
            Some(p) => {
                let x = (((p.x - resp.rect.min.x) / s) as usize).min(img.width - 1);
                let y = (((p.y - resp.rect.min.y) / s) as usize).min(img.height - 1);
                let v = img.get(x, y);
                format!("({x}, {y})  R {:.4}  G {:.4}  B {:.4}", v[0], v[1], v[2])
            }
            None => format!("{} × {}  (hover for pixel values)", img.width, img.height),
        };
        ui.monospace(text);
    }
}

/// The pointer's doings on the image drawn at `scale` points per pixel.
fn pointer_input(ui: &egui::Ui, resp: &egui::Response, scale: f32, size: [usize; 2]) -> ViewerInput {
    let to_image = |p: egui::Pos2| ((p - resp.rect.min) / scale).to_pos2();
    let (secondary, shift, scroll) = ui.input(|i| (i.pointer.secondary_down(), i.modifiers.shift, i.raw_scroll_delta.y));
    let dragging = resp.dragged();
    ViewerInput {
        size,
        pointer: resp.interact_pointer_pos().or(resp.hover_pos()).map(to_image),
        origin: ui.input(|i| i.pointer.press_origin()).map(to_image),
        pressed: resp.drag_started(),
        dragging,
        released: resp.drag_stopped(),
        clicked: resp.clicked(),
        alternate: (dragging || resp.drag_started()) && (secondary || shift),
        scroll: if resp.hovered() { scroll } else { 0.0 },
    }
}

/// The run report as a table: node, status, time, cache, metrics.
pub fn report_table(ui: &mut egui::Ui, report: &RunReport) {
    ui.label(format!("total {} — {} ran, {} cached", crate::fmt_ms(report.total_ms), report.ran, report.cached));
    egui::Grid::new("report").striped(true).num_columns(4).show(ui, |ui| {
        ui.strong("node");
        ui.strong("status");
        ui.strong("time");
        ui.strong("metrics");
        ui.end_row();
        for n in &report.nodes {
            ui.label(&n.id).on_hover_text(&n.kind);
            let status = match n.cache {
                Some(c) => format!("cached ({c})"),
                None => n.status.to_string(),
            };
            ui.label(status);
            let t = if n.status == "ran" { crate::fmt_ms(n.wall_ms) } else { format!("({})", crate::fmt_ms(n.compute_ms)) };
            ui.label(t).on_hover_text("time this run; in brackets, what the cached result cost when it ran");
            let m: Vec<String> = n.metrics.iter().map(|(k, v)| format!("{k} {}", fmt_num(*v))).collect();
            ui.add(egui::Label::new(m.join("  ")).wrap());
            ui.end_row();
        }
    });
}

/// A metric for reading: integers as integers, small and large values in scientific form.
pub fn fmt_num(v: f64) -> String {
    if v.fract() == 0.0 && v.abs() < 1e9 {
        format!("{v:.0}")
    } else if (1e-3..1e4).contains(&v.abs()) {
        format!("{v:.4}")
    } else {
        format!("{v:.3e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn display_is_monotone_and_survives_bad_pixels() {
        let a = display([0.1, 0.1, 0.1], 0.0, Operator::Aces);
        let b = display([0.5, 0.5, 0.5], 0.0, Operator::Aces);
        assert!(b.r() > a.r());
        assert!(display([0.1; 3], 2.0, Operator::Aces).r() > a.r(), "exposure brightens");
        let bad = display([f32::NAN, f32::INFINITY, -1.0], 0.0, Operator::Aces);
        assert_eq!((bad.r(), bad.g(), bad.b()), (0, 255, 0));
    }

    #[test]
    fn numbers_read_well() {
        assert_eq!(fmt_num(61500.0), "61500");
        assert_eq!(fmt_num(0.00172), "0.0017");
        assert_eq!(fmt_num(1.7e-6), "1.700e-6");
        assert_eq!(fmt_num(f64::NAN), "NaN");
    }
}
