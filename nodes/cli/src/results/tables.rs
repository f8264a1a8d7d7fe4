//! The Markdown a results page shows of one sweep: where and when it was measured, the
//! command, the plot and a table of its rows. With a baseline on a time axis, each of the
//! method's rows stands beside the baseline at the same time and at the same error, and the
//! speed-up at equal error is read off the baseline's curve (log-log interpolation between its
//! neighbouring points, never extrapolated).

use crate::sweep::csv_table::CsvTable;
use crate::sweep::{Plotted, XAxis};

/// The section's body (after its caption): provenance, command, plot, table.
/// With a goal (`--goal`, a speed-up at equal error the method should reach), the plot's
/// dashed line is said to be it.
pub(crate) fn section(name: &str, command: &str, p: &Plotted, t: &CsvTable) -> Result<String, String> {
    let mut out = format!("{} ([csv](../results/sweep_{name}.csv)):\n\n", provenance(t)?);
    out += &format!("```text\n{command}\n```\n\n![{}](../results/sweep_{name}.png)\n\n", p.title);
    if let Some(g) = p.goal {
        out += &format!(
            "The dashed line is the goal, {g}× the baseline's speed at equal error: its curve at 1/{g} of its times. \
             A method's point on or left of it reaches the goal; how far right of it a point lies is by how much it falls short.\n\n"
        );
    }
    let metric = format!("`{}`", p.metric);
    let x = p.x.column();
    let time_axis = matches!(p.x, XAxis::Time(_));
    let label = |r: usize| t.text(r, "variant").to_string();
    match (&p.baseline, time_axis) {
        (Some((param, _)), true) => {
            let curve = baseline_curve(p, t);
            let head = [
                "variant".to_string(),
                metric.clone(),
                time_label(&x),
                format!("`{param}` baseline: {metric} at that time"),
                format!("`{param}` baseline: time for that {metric}"),
                "speed-up at equal error".into(),
            ];
            out += &header(&head);
            for r in p.rows(t, "method") {
                let (tm, e) = (t.number(r, &x), t.number(r, &p.y_column("method")));
                let (time_for, speed) = equal_error(&time_for_error(&curve, e), tm);
                let at = error_at_time(&curve, tm).map_or("outside its times".to_string(), num);
                out += &line(&[label(r), num(e), ms(tm), at, time_for, speed]);
            }
            for r in p.rows(t, "baseline") {
                out += &line(&[
                    label(r),
                    num(t.number(r, &p.y_column("baseline"))),
                    ms(t.number(r, &x)),
                    String::new(),
                    String::new(),
                    String::new(),
                ]);
            }
        }
        _ => {
            let y = p.y_column("method");
            if time_axis {
                out += &header(&["variant".into(), metric.clone(), time_label(&x)]);
            } else {
                out += &header(&["variant".into(), format!("`{x}`"), metric.clone(), time_label("pipeline_ms")]);
            }
            for series in ["method", "baseline"] {
                for r in p.rows(t, series) {
                    let y = if series == "baseline" { p.y_column("baseline") } else { y.clone() };
                    let cells = if time_axis {
                        vec![label(r), num(t.number(r, &y)), ms(t.number(r, &x))]
                    } else {
                        // A parameter as the CSV gives it; a metric as a number.
                        let xv = if matches!(p.x, XAxis::Param(_)) { t.text(r, &x).to_string() } else { num(t.number(r, &x)) };
                        vec![label(r), xv, num(t.number(r, &y)), ms(t.number(r, "pipeline_ms"))]
                    };
                    out += &line(&cells);
                }
            }
        }
    }
    Ok(out)
}

/// A sweep's headline row, the method row whose variant is `variant`: its error (with the
/// metric's name), its time, the baseline's time for that error, the speed-up at equal error
/// and, with a goal for that speed-up, whether it is met or by how much it falls short.
pub(crate) fn headline(p: &Plotted, t: &CsvTable, variant: &str) -> Result<[String; 5], String> {
    if p.baseline.is_none() || !matches!(p.x, XAxis::Time(_)) {
        return Err("a headline needs a sweep with a baseline on a time axis".into());
    }
    let r = p.rows(t, "method").find(|&r| t.text(r, "variant") == variant).ok_or_else(|| {
        let all: Vec<&str> = p.rows(t, "method").map(|r| t.text(r, "variant")).collect();
        format!("no method row `{variant}` for the headline (the rows: {})", all.join(", "))
    })?;
    let (tm, e) = (t.number(r, &p.x.column()), t.number(r, &p.y_column("method")));
    let reach = time_for_error(&baseline_curve(p, t), e);
    let (time_for, speed) = equal_error(&reach, tm);
    let against = p.goal.map_or("—".to_string(), |g| against_goal(&reach, tm, g));
    Ok([format!("{} (`{}`)", num(e), p.metric), ms(tm), time_for, speed, against])
}

/// A speed-up at equal error against its goal: `met` or how many times short, as far as the
/// baseline's curve tells (its reach outside its points is a bound, not a value).
fn against_goal(reach: &Reach, tm: f64, goal: f64) -> String {
    let met = format!("≥ {goal}×: met");
    match *reach {
        Reach::At(tb) if tb / tm >= goal => met,
        Reach::At(tb) => format!("≥ {goal}×: {:.2}× short", goal * tm / tb),
        Reach::Below(tb) if tb / tm >= goal => met,
        Reach::Above(tb) if tb / tm < goal => format!("≥ {goal}×: more than {:.2}× short", goal * tm / tb),
        _ => format!("≥ {goal}×: not known from the baseline's points"),
    }
}

/// The headline rows of a page's sweeps as a table.
pub(crate) fn headline_table(rows: &[Vec<String>]) -> String {
    let head = ["sweep", "row", "error", "pipeline time", "the baseline's time for that error", "speed-up at equal error", "goal"];
    let mut out = header(&head.map(String::from));
    for r in rows {
        out += &line(r);
    }
    out
}

/// The baseline's time for an error (`reach`, from `time_for_error`) and the speed-up over
/// time `tm`, as table cells.
fn equal_error(reach: &Reach, tm: f64) -> (String, String) {
    match *reach {
        Reach::At(tb) => (ms(tb), format!("{:.2}×", tb / tm)),
        Reach::Below(tb) => (format!("more than {} (below its last point)", ms(tb)), format!("> {:.2}×", tb / tm)),
        Reach::Above(tb) => (format!("less than {} (above its first point)", ms(tb)), format!("< {:.2}×", tb / tm)),
        Reach::Unknown => ("—".into(), "—".into()),
    }
}

/// A benchmark's section body: provenance, command, and a table of its cases: median, runs a
/// second at the median (items a second where the case counts items: rays, samples), range,
/// samples × iterations, each median against the case `against` names (measured in the same
/// run), and the figures `compare` gives for its cases (a thesis' table) under its heading.
pub(crate) fn bench_section(
    name: &str,
    command: &str,
    against: Option<&str>,
    compare: Option<(&str, &[(String, String)])>,
    t: &CsvTable,
) -> Result<String, String> {
    let mut out = format!("{} ([csv](../results/bench_{name}.csv)):\n\n```text\n{command}\n```\n\n", provenance(t)?);
    let rows = 0..t.rows.len();
    let base = match against {
        Some(case) => {
            Some(rows.clone().find(|&r| t.text(r, "case") == case).map(|r| (case, t.number(r, "median_ms"))).ok_or_else(|| {
                format!(
                    "no case `{case}` to divide by (the cases: {})",
                    rows.clone().map(|r| t.text(r, "case")).collect::<Vec<_>>().join(", ")
                )
            })?)
        }
        None => None,
    };
    let mut head = vec![
        "case".to_string(),
        "median".into(),
        "per second (at the median)".into(),
        "fastest – slowest".into(),
        "samples × iterations".into(),
    ];
    if let Some((case, _)) = base {
        head.push(format!("median against `{case}`"));
    }
    if let Some((heading, figures)) = compare {
        if let Some((case, _)) = figures.iter().find(|(case, _)| !rows.clone().any(|r| t.text(r, "case") == case)) {
            return Err(format!("`compare` names a case `{case}` the benchmark does not have"));
        }
        head.push(heading.to_string());
    }
    out += &header(&head);
    for r in rows {
        let mut cells = vec![
            t.text(r, "case").to_string(),
            ms(t.number(r, "median_ms")),
            match t.number(r, "median_items_per_s") {
                items if items.is_finite() && items >= 1e6 => format!("{} M items", num(items / 1e6)),
                items if items.is_finite() => format!("{} items", num(items)),
                _ => num(1000.0 / t.number(r, "median_ms")),
            },
            format!("{} – {}", ms(t.number(r, "fastest_ms")), ms(t.number(r, "slowest_ms"))),
            format!("{} × {}", t.text(r, "samples"), t.text(r, "iters")),
        ];
        if let Some((_, m)) = base {
            cells.push(format!("{:.2}×", t.number(r, "median_ms") / m));
        }
        if let Some((_, figures)) = compare {
            cells.push(figures.iter().find(|(case, _)| case == t.text(r, "case")).map_or("—".to_string(), |(_, f)| f.clone()));
        }
        out += &line(&cells);
    }
    Ok(out)
}

/// "Measured DATE on MACHINE, N threads", each part listing the distinct values.
pub(super) fn provenance(t: &CsvTable) -> Result<String, String> {
    let missing: Vec<&str> = crate::provenance::COLUMNS.into_iter().filter(|c| t.column(c).is_none()).collect();
    if !missing.is_empty() {
        return Err(format!(
            "the CSV has no {} column(s): a results file says when, where and on what it was measured",
            missing.join(", ")
        ));
    }
    let all = |c: &str| t.distinct(c).join(", ");
    Ok(format!("Measured {} on {}, {} threads", all("date"), all("machine"), all("threads")))
}

fn time_label(column: &str) -> String {
    match column {
        "pipeline_ms" => "pipeline time".into(),
        "time_ms" => "time of the nodes that ran".into(),
        c => format!("`{c}`"),
    }
}

pub(super) fn header(cells: &[String]) -> String {
    line(cells) + &line(&vec!["---".to_string(); cells.len()])
}

pub(super) fn line(cells: &[String]) -> String {
    format!("| {} |\n", cells.iter().map(|c| c.replace('|', "\\|")).collect::<Vec<_>>().join(" | "))
}

/// The baseline's points (time, error) in time order, those a log axis can show.
fn baseline_curve(p: &Plotted, t: &CsvTable) -> Vec<(f64, f64)> {
    let (x, y) = (p.x.column(), p.y_column("baseline"));
    let mut c: Vec<(f64, f64)> =
        p.rows(t, "baseline").map(|r| (t.number(r, &x), t.number(r, &y))).filter(|&(a, b)| a > 0.0 && b > 0.0).collect();
    c.sort_by(|a, b| a.0.total_cmp(&b.0));
    c
}

/// `a + (b − a) f` on logarithms.
fn log_lerp(a: f64, b: f64, f: f64) -> f64 {
    (a.ln() + (b.ln() - a.ln()) * f).exp()
}

/// The curve's error at time `tm` (log-log between the points around it), None outside it.
pub(crate) fn error_at_time(curve: &[(f64, f64)], tm: f64) -> Option<f64> {
    curve.windows(2).find(|w| w[0].0 <= tm && tm <= w[1].0).map(|w| {
        let f = if w[1].0 > w[0].0 { (tm.ln() - w[0].0.ln()) / (w[1].0.ln() - w[0].0.ln()) } else { 0.0 };
        log_lerp(w[0].1, w[1].1, f)
    })
}

/// When the baseline reaches an error.
#[derive(Debug, PartialEq)]
pub(crate) enum Reach {
    /// At this time, between two of its points.
    At(f64),
    /// Lower than every point: after its last (at this time).
    Below(f64),
    /// Higher than every point: before its first (at this time).
    Above(f64),
    Unknown,
}

/// The first time the curve (in time order) passes error `e`, log-log between its points.
pub(crate) fn time_for_error(curve: &[(f64, f64)], e: f64) -> Reach {
    if curve.is_empty() || !(e > 0.0) {
        return Reach::Unknown;
    }
    if let Some(&(t0, e0)) = curve.first().filter(|&&(_, e0)| e0 <= e) {
        // Already there at its first point.
        return if e0 == e { Reach::At(t0) } else { Reach::Above(t0) };
    }
    for w in curve.windows(2) {
        let ((ta, ea), (tb, eb)) = (w[0], w[1]);
        if (ea - e) * (eb - e) <= 0.0 && ea != eb {
            let f = (e.ln() - ea.ln()) / (eb.ln() - ea.ln());
            return Reach::At(log_lerp(ta, tb, f));
        }
    }
    Reach::Below(curve[curve.len() - 1].0)
}

/// Three significant digits: decimals between 0.001 and 10⁴, `a.bc × 10ⁿ` outside.
pub(crate) fn num(v: f64) -> String {
    if !v.is_finite() {
        return "—".into();
    }
    if v.fract() == 0.0 && v.abs() < 1e7 {
        // Whole numbers (counts, bytes) as they are.
        return format!("{}", v as i64);
    }
    let exp = v.abs().log10().floor() as i32;
    if (-3..4).contains(&exp) {
        let decimals = (2 - exp).max(0) as usize;
        return format!("{v:.decimals$}");
    }
    let m = v / 10f64.powi(exp);
    // Rounding may carry the mantissa to 10.
    let (m, exp) = if (m.abs() * 100.0).round() >= 1000.0 { (m / 10.0, exp + 1) } else { (m, exp) };
    format!("{m:.2} × 10{}", superscript(exp))
}

fn superscript(n: i32) -> String {
    const DIGITS: [char; 10] = ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'];
    let digits = n.unsigned_abs().to_string().chars().map(|c| DIGITS[c as usize - '0' as usize]).collect::<String>();
    if n < 0 {
        format!("⁻{digits}")
    } else {
        digits
    }
}

/// Milliseconds as `843 ms`, `8.4 ms` or `1.20 s`.
pub(crate) fn ms(v: f64) -> String {
    if !v.is_finite() {
        "—".into()
    } else if v >= 1000.0 {
        format!("{:.2} s", v / 1000.0)
    } else if v >= 10.0 {
        format!("{v:.0} ms")
    } else {
        format!("{v:.1} ms")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_keep_three_significant_digits() {
        assert_eq!(num(0.001992), "0.00199");
        assert_eq!(num(1.17), "1.17");
        assert_eq!(num(2572.4), "2572");
        assert_eq!(num(0.000257), "2.57 × 10⁻⁴");
        assert_eq!(num(9.999e-5), "1.00 × 10⁻⁴");
        assert_eq!(num(12345.6), "1.23 × 10⁴");
        assert_eq!(
            (num(f64::NAN), num(0.0), num(4.0), num(20_700_000.0)),
            ("—".to_string(), "0".to_string(), "4".to_string(), "2.07 × 10⁷".to_string())
        );
        assert_eq!((ms(1204.0), ms(843.2), ms(8.44)), ("1.20 s".to_string(), "843 ms".to_string(), "8.4 ms".to_string()));
    }

    #[test]
    fn the_baseline_is_read_between_its_points_and_never_beyond_them() {
        // error ∝ 1 / time: 0.1 at 10 ms, 0.01 at 100 ms, 0.001 at 1000 ms.
        let curve = [(10.0, 0.1), (100.0, 0.01), (1000.0, 0.001)];
        let close = |a: f64, b: f64| (a / b - 1.0).abs() < 1e-9;
        assert!(close(error_at_time(&curve, 200.0).unwrap(), 0.005));
        assert_eq!(error_at_time(&curve, 5.0), None);
        assert_eq!(error_at_time(&curve, 2000.0), None);
        let Reach::At(t) = time_for_error(&curve, 0.002) else { panic!() };
        assert!(close(t, 500.0), "{t}");
        assert_eq!(time_for_error(&curve, 0.0005), Reach::Below(1000.0));
        assert_eq!(time_for_error(&curve, 0.5), Reach::Above(10.0));
        assert_eq!(time_for_error(&curve, 0.1), Reach::At(10.0));
        assert_eq!(time_for_error(&[], 0.1), Reach::Unknown);
        // A noisy curve: the first crossing counts.
        let Reach::At(t) = time_for_error(&[(1.0, 0.1), (2.0, 0.02), (4.0, 0.03), (8.0, 0.01)], 0.025) else { panic!() };
        assert!(t > 1.0 && t < 2.0, "{t}");
    }
}
