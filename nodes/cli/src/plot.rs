//! Error-against-time plots for `relume sweep`: log-log axes, one line-and-points series per
//! curve, drawn with plotters into memory and written as PNG with the `image` crate.
//!
//! The text is drawn with DejaVu Sans embedded in the binary (`nodes/assets/fonts`), because
//! the machines relume runs on need not have any system fonts.

use plotters::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

/// DejaVu Sans (Bitstream Vera license, see `nodes/assets/fonts/LICENSE.md`).
static FONT: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");
/// The family name every text style in this module uses.
const FAMILY: &str = "sans-serif";

/// Width and height of the plot in pixels.
pub(crate) const SIZE: (u32, u32) = (1024, 720);

/// One curve: points `(x, y, label)` in the order they are joined; a dashed curve is a guide
/// (a goal drawn from another curve), drawn without its points and their labels.
pub(crate) struct Curve {
    pub name: String,
    pub color: RGBColor,
    pub points: Vec<(f64, f64, String)>,
    pub dashed: bool,
}

/// What goes around the curves.
pub(crate) struct Axes {
    pub title: String,
    pub x_label: String,
    pub y_label: String,
}

/// Registers the embedded font with plotters once per process.
fn register_font() -> Result<(), String> {
    static DONE: OnceLock<Result<(), String>> = OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).map_err(|_| "the embedded plot font does not parse".to_string())
    })
    .clone()
}

/// Draws `curves` on log-log axes and writes the PNG to `path`. Points that a log axis cannot
/// show (x or y not finite or ≤ 0) are left out; each curve that lost points gets one line in
/// the returned warnings (for stderr).
pub(crate) fn plot_log_log(path: &Path, axes: &Axes, curves: &[Curve]) -> Result<Vec<String>, String> {
    let (png, warnings) = log_log_png(axes, curves)?;
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }
    relume_core::graph::write_atomic(path, &png).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    Ok(warnings)
}

/// The PNG bytes of `plot_log_log`'s figure, and its warnings: the same curves give the same
/// bytes from the same build (the font is embedded and the drawing is done in software).
pub(crate) fn log_log_png(axes: &Axes, curves: &[Curve]) -> Result<(Vec<u8>, Vec<String>), String> {
    register_font()?;
    let mut warnings = Vec::new();
    let kept: Vec<Curve> = curves
        .iter()
        .map(|c| {
            let (good, bad): (Vec<_>, Vec<_>) = c.points.iter().cloned().partition(|(x, y, _)| plottable(*x) && plottable(*y));
            if !bad.is_empty() {
                let which: Vec<String> = bad.iter().map(|(x, y, l)| format!("{l} (x={x}, y={y})")).collect();
                warnings.push(format!(
                    "plot: left out {} of {} `{}` points that a log axis cannot show (not finite or <= 0): {}",
                    bad.len(),
                    c.points.len(),
                    c.name,
                    which.join(", ")
                ));
            }
            Curve { name: c.name.clone(), color: c.color, points: good, dashed: c.dashed }
        })
        .collect();
    let (x_range, y_range) = (
        log_range(kept.iter().flat_map(|c| c.points.iter().map(|q| q.0))),
        log_range(kept.iter().flat_map(|c| c.points.iter().map(|q| q.1))),
    );
    if kept.iter().all(|c| c.points.is_empty()) {
        warnings.push("plot: no point can be shown; the plot has empty axes".to_string());
    }

    let (w, h) = SIZE;
    let mut buf = vec![255u8; w as usize * h as usize * 3];
    draw(&mut buf, axes, &kept, x_range, y_range).map_err(|e| format!("drawing the plot: {e}"))?;

    let mut png = Vec::new();
    image::ImageEncoder::write_image(image::codecs::png::PngEncoder::new(&mut png), &buf, w, h, image::ExtendedColorType::Rgb8)
        .map_err(|e| format!("encoding the plot: {e}"))?;
    Ok((png, warnings))
}

fn plottable(v: f64) -> bool {
    v.is_finite() && v > 0.0
}

/// A range on a log axis covering every value with a margin, widened to whole decades
/// (plotters labels a log axis from the first power of ten inside it); `[1, 10]` when there
/// is no value.
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values.fold((f64::INFINITY, 0.0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if !lo.is_finite() {
        return (1.0, 10.0);
    }
    let (lo, hi) = ((lo / 1.2).log10().floor(), (hi * 1.2).log10().ceil());
    // Nudged outwards so that rounding never drops the end decades' ticks.
    (10f64.powf(lo) * (1.0 - 1e-9), 10f64.powf(hi.max(lo + 1.0)) * (1.0 + 1e-9))
}

type DrawResult = Result<(), Box<dyn std::error::Error>>;

fn draw(buf: &mut [u8], axes: &Axes, curves: &[Curve], x: (f64, f64), y: (f64, f64)) -> DrawResult {
    let root = BitMapBackend::with_buffer(buf, SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(&axes.title, (FAMILY, 26))
        .margin(20)
        .x_label_area_size(56)
        .y_label_area_size(96)
        .build_cartesian_2d((x.0..x.1).log_scale(), (y.0..y.1).log_scale())?;
    chart
        .configure_mesh()
        .x_desc(&axes.x_label)
        .y_desc(&axes.y_label)
        .axis_desc_style((FAMILY, 18))
        .label_style((FAMILY, 15))
        // Up to 3 decades get ticks at 1..9 × 10^k (more decades: only 10^k); 1, 2 and 5 are labelled.
        .x_labels(30)
        .y_labels(30)
        .x_label_formatter(&|v| tick_label(*v))
        .y_label_formatter(&|v| tick_label(*v))
        .light_line_style(TRANSPARENT)
        .bold_line_style(RGBColor(215, 215, 215))
        .draw()?;

    for curve in curves {
        let points = &curve.points;
        let color = curve.color;
        let xy: Vec<(f64, f64)> = points.iter().map(|p| (p.0, p.1)).collect();
        if curve.dashed {
            chart
                .draw_series(DashedLineSeries::new(xy.iter().copied(), 10, 6, color.stroke_width(2)))?
                .label(curve.name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 10, y)], color.stroke_width(2)));
            continue;
        }
        chart
            .draw_series(LineSeries::new(xy.iter().copied(), color.stroke_width(2)))?
            .label(curve.name.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], color.stroke_width(2)));
        chart.draw_series(xy.iter().map(|&p| Circle::new(p, 4, color.filled())))?;
        let text = TextStyle::from((FAMILY, 14).into_font()).color(&color);
        chart.draw_series(
            points.iter().map(|(x, y, label)| EmptyElement::at((*x, *y)) + Text::new(label.clone(), (7, -16), text.clone())),
        )?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FAMILY, 16))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    root.present()?;
    Ok(())
}

/// The label of a log-axis tick: the number at 1, 2 and 5 × 10^k, nothing between.
fn tick_label(v: f64) -> String {
    if !(v.is_finite() && v > 0.0) {
        return String::new();
    }
    let m = v / 10f64.powf((v.log10() + 1e-9).floor());
    if [1.0, 2.0, 5.0].iter().any(|k| (m - k).abs() < 1e-6) {
        number(v)
    } else {
        String::new()
    }
}

/// A tick label: plain decimals between 0.001 and 10⁵, scientific notation outside.
fn number(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let a = v.abs();
    if (1e-3..1e5).contains(&a) {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        s.to_string()
    } else {
        format!("{v:.1e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_are_short_decimals_or_scientific() {
        assert_eq!(number(0.5), "0.5");
        assert_eq!(number(100.0), "100");
        assert_eq!(number(1e-6), "1.0e-6");
        assert_eq!(number(2.5e7), "2.5e7");
        assert_eq!(tick_label(0.2 * (1.0 + 1e-12)), "0.2");
        assert_eq!(tick_label(5000.0), "5000");
        assert_eq!(tick_label(1000.0), "1000");
        assert_eq!(tick_label(3.0), "");
    }

    #[test]
    fn log_ranges_cover_their_values_and_survive_a_single_value_or_none() {
        let close = |(a, b): (f64, f64), (c, d): (f64, f64)| ((a / c) - 1.0).abs() < 1e-6 && ((b / d) - 1.0).abs() < 1e-6;
        assert!(close(log_range([0.2, 3.0].into_iter()), (0.1, 10.0)));
        assert!(close(log_range([0.01, 0.5].into_iter()), (0.001, 1.0)));
        assert!(close(log_range([2.0].into_iter()), (1.0, 10.0)));
        assert_eq!(log_range(std::iter::empty()), (1.0, 10.0));
    }

    #[test]
    fn a_curve_with_zero_negative_and_nan_points_is_plotted_without_them() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("sub/p.png");
        let curve = |name: &str, color, points: Vec<(f64, f64)>| Curve {
            name: name.into(),
            color,
            points: points.into_iter().enumerate().map(|(i, (x, y))| (x, y, format!("v{i}"))).collect(),
            dashed: false,
        };
        let curves = [
            curve("method", RGBColor(31, 119, 180), vec![(1.0, 0.1), (0.0, 0.05), (4.0, f64::NAN), (8.0, 0.01)]),
            curve("baseline", RGBColor(214, 39, 40), vec![(-1.0, 0.2), (0.0, 0.0)]),
        ];
        let axes = Axes { title: "t".into(), x_label: "time (ms)".into(), y_label: "rel_mse".into() };
        let warnings = plot_log_log(&path, &axes, &curves).unwrap();
        assert_eq!(warnings.len(), 2, "{warnings:?}");
        assert!(warnings[0].contains("2 of 4 `method`"), "{}", warnings[0]);
        assert!(warnings[1].contains("2 of 2 `baseline`"), "{}", warnings[1]);
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), SIZE);
        assert!(img.pixels().any(|p| p.0 == [31, 119, 180]), "the method curve is drawn");
    }

    #[test]
    fn a_dashed_curve_is_drawn_as_a_broken_line() {
        let grey = RGBColor(120, 120, 120);
        let guide =
            Curve { name: "goal".into(), color: grey, points: vec![(1.0, 1.0, "a".into()), (100.0, 0.01, "b".into())], dashed: true };
        let axes = Axes { title: "t".into(), x_label: "time (ms)".into(), y_label: "rel_mse".into() };
        let (png, warnings) = log_log_png(&axes, &[guide]).unwrap();
        assert!(warnings.is_empty());
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        // Along the diagonal the line is drawn in pieces: grey pixels, then gaps, then grey again.
        let (w, h) = SIZE;
        let runs = (0..w)
            .map(|x| (0..h).any(|y| img.get_pixel(x, y).0 == [120, 120, 120]))
            .collect::<Vec<bool>>()
            .windows(2)
            .filter(|p| p[0] && !p[1])
            .count();
        assert!(runs > 10, "a dashed line breaks many times across the plot, here {runs}");
    }
}
