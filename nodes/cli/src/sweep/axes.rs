//! What a sweep's plot draws: the x axis (time, a varied parameter or a metric, `--x`) and the
//! curves (one for the method's rows, or one per value of a varied parameter, `--series`), read
//! from the sweep's CSV so that `relume sweep` and `relume results` draw the same figure.

use super::csv_table::CsvTable;
use super::rows::{TimeAxis, Vary};
use crate::error::CliError;
use crate::plot::{Axes, Curve};
use plotters::style::RGBColor;
use relume_core::{Graph, Registry};

/// The plot's x axis.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum XAxis {
    Time(TimeAxis),
    /// A varied parameter's column.
    Param(String),
    /// `node.metric`.
    Metric(String, String),
}

impl XAxis {
    /// `--x COLUMN` checked against the parameter columns and the metrics the graph's nodes
    /// report, before anything runs; without it, the `--time` axis.
    pub(super) fn parse(x: Option<&str>, time: TimeAxis, columns: &[String], graph: &Graph, reg: &Registry) -> Result<XAxis, CliError> {
        let axis = XAxis::of_column(x, time, columns);
        let XAxis::Metric(id, metric) = &axis else { return Ok(axis) };
        let x = x.unwrap_or_default();
        let refuse = |why: String| {
            CliError::graph(format!(
                "--x {x}: {why}; give a varied parameter ({}), a metric as node.metric, time_ms or pipeline_ms",
                if columns.is_empty() { "none".to_string() } else { columns.join(", ") }
            ))
        };
        if id.is_empty() {
            return Err(refuse("not a column".into()));
        }
        let node = graph.node(id).ok_or_else(|| refuse(format!("no node \"{id}\" in the graph")))?;
        let have = reg.node(&node.kind).map_or(&[][..], |k| k.metrics());
        if !have.contains(&metric.as_str()) {
            return Err(refuse(if have.is_empty() {
                format!("node \"{id}\" ({}) reports no metric and `{metric}` is not a varied parameter", node.kind)
            } else {
                format!("node \"{id}\" ({}) reports no `{metric}` (it reports: {})", node.kind, have.join(", "))
            }));
        }
        Ok(axis)
    }

    /// `--x COLUMN` as a column of the CSV, unchecked (a name without a dot is a metric of no
    /// node, which `parse` refuses).
    pub(crate) fn of_column(x: Option<&str>, time: TimeAxis, columns: &[String]) -> XAxis {
        match x {
            None => XAxis::Time(time),
            Some("time_ms") => XAxis::Time(TimeAxis::Ran),
            Some("pipeline_ms") => XAxis::Time(TimeAxis::Pipeline),
            Some(x) if columns.iter().any(|c| c == x) => XAxis::Param(x.to_string()),
            Some(x) => {
                let (id, metric) = x.split_once('.').unwrap_or(("", x));
                XAxis::Metric(id.to_string(), metric.to_string())
            }
        }
    }

    /// The CSV column the axis reads.
    pub(crate) fn column(&self) -> String {
        match self {
            XAxis::Time(TimeAxis::Ran) => "time_ms".into(),
            XAxis::Time(TimeAxis::Pipeline) => "pipeline_ms".into(),
            XAxis::Param(name) => name.clone(),
            XAxis::Metric(node, m) => format!("{node}.{m}"),
        }
    }

    pub(crate) fn label(&self) -> String {
        match self {
            XAxis::Time(TimeAxis::Ran) => "time (ms): wall time of the nodes that ran, cached nodes cost 0".into(),
            XAxis::Time(TimeAxis::Pipeline) => "time (ms): compute time of the pipeline that made the image (reference excluded)".into(),
            XAxis::Param(name) => name.clone(),
            XAxis::Metric(node, m) => format!("{m} of node \"{node}\""),
        }
    }
}

/// The --vary whose values `--series` splits the method's rows by; it must be varied.
pub(super) fn series_vary(target: &str, varies: &[Vary]) -> Result<usize, CliError> {
    varies.iter().position(|v| v.targets.iter().any(|t| t == target)).ok_or_else(|| {
        let all: Vec<&str> = varies.iter().flat_map(|v| v.targets.iter().map(String::as_str)).collect();
        CliError::graph(format!(
            "--series {target}: not a varied parameter (varied: {})",
            if all.is_empty() { "none".to_string() } else { all.join(", ") }
        ))
    })
}

/// Colours of the method's lines (the baseline is red).
const PALETTE: [RGBColor; 8] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(23, 190, 207),
];
const BASELINE: RGBColor = RGBColor(214, 39, 40);
/// A goal's guide line.
const GOAL: RGBColor = RGBColor(120, 120, 120);

/// A sweep's figure: which columns of its CSV are drawn, and how its rows become curves.
pub(crate) struct Plotted {
    pub x: XAxis,
    /// Index of the --vary that `--series` splits by.
    pub series: Option<usize>,
    pub varies: Vec<Vary>,
    /// The node whose metric is the y axis, for the method's rows.
    pub error_node: String,
    pub metric: String,
    /// The baseline's parameter and its error node.
    pub baseline: Option<(String, String)>,
    /// `--goal`: the speed-up at equal error the method should reach over the baseline.
    pub goal: Option<f64>,
    pub title: String,
}

impl Plotted {
    /// The rows of `series` ("method" or "baseline").
    pub(crate) fn rows<'t>(&self, t: &'t CsvTable, series: &'t str) -> impl Iterator<Item = usize> + 't {
        (0..t.rows.len()).filter(move |&r| t.text(r, "series") == series)
    }

    /// The y column of a row of `series`.
    pub(crate) fn y_column(&self, series: &str) -> String {
        match (&self.baseline, series) {
            (Some((_, node)), "baseline") => format!("{node}.{}", self.metric),
            _ => format!("{}.{}", self.error_node, self.metric),
        }
    }

    /// A method point's label: the values of the --vary lists that neither the x axis nor the
    /// series already shows.
    fn point_label(&self, t: &CsvTable, r: usize) -> String {
        let x_vary = match &self.x {
            XAxis::Param(name) => self.varies.iter().position(|v| v.targets.contains(name)),
            _ => None,
        };
        let shown = |k: usize| Some(k) == x_vary || Some(k) == self.series;
        let values = self.varies.iter().enumerate().filter(|(k, _)| !shown(*k)).map(|(_, v)| t.text(r, &v.targets[0]));
        values.collect::<Vec<_>>().join(", ")
    }

    fn points(
        &self,
        t: &CsvTable,
        rows: impl Iterator<Item = usize>,
        series: &str,
        label: impl Fn(usize) -> String,
    ) -> Vec<(f64, f64, String)> {
        let (x, y) = (self.x.column(), self.y_column(series));
        rows.map(|r| (t.number(r, &x), t.number(r, &y), label(r))).collect()
    }

    /// The method's rows as one curve, or one per value of the `--series` vary (in the order
    /// its values first appear), each in the order the rows ran; then the baseline's, and the
    /// goal's guide when there is one.
    pub(crate) fn curves(&self, t: &CsvTable) -> Vec<Curve> {
        let mut curves = Vec::new();
        let method = || self.rows(t, "method");
        if let Some(k) = self.series {
            let vary = &self.varies[k];
            let column = &vary.targets[0];
            let mut values: Vec<String> = Vec::new();
            for r in method() {
                let v = t.text(r, column);
                if !values.iter().any(|x| x == v) {
                    values.push(v.to_string());
                }
            }
            for (c, value) in values.iter().enumerate() {
                let rows = method().filter(|&r| t.text(r, column) == value);
                curves.push(Curve {
                    name: format!("{} = {value}", vary.targets.join(" = ")),
                    color: PALETTE[c % PALETTE.len()],
                    points: self.points(t, rows, "method", |r| self.point_label(t, r)),
                    dashed: false,
                });
            }
        } else if !self.varies.is_empty() {
            let columns: Vec<&str> = self.varies.iter().flat_map(|v| v.targets.iter().map(String::as_str)).collect();
            let name = format!("method ({})", columns.join(", "));
            let points = self.points(t, method(), "method", |r| self.point_label(t, r));
            curves.push(Curve { name, color: PALETTE[0], points, dashed: false });
        }
        if let Some((param, node)) = &self.baseline {
            let of = if *node != self.error_node { format!(", error of \"{node}\"") } else { String::new() };
            let points = self.points(t, self.rows(t, "baseline"), "baseline", |r| t.text(r, param).to_string());
            curves.push(Curve { name: format!("baseline ({param} = 1, 2, 4, …{of})"), color: BASELINE, points, dashed: false });
        }
        curves.extend(self.goal.and_then(|g| self.goal_curve(t, g)));
        curves
    }

    /// A goal for the speed-up at equal error, drawn: the baseline's curve at `1/goal` of its
    /// times, dashed. A method's point on or left of it reaches the goal; its distance to the
    /// right is by how much it falls short. None without a baseline on a time axis.
    fn goal_curve(&self, t: &CsvTable, goal: f64) -> Option<Curve> {
        if self.baseline.is_none() || !matches!(self.x, XAxis::Time(_)) {
            return None;
        }
        let mut points = self.points(t, self.rows(t, "baseline"), "baseline", |_| String::new());
        for p in &mut points {
            p.0 /= goal;
        }
        Some(Curve { name: format!("goal: the baseline {goal}× faster"), color: GOAL, points, dashed: true })
    }

    pub(crate) fn axes(&self) -> Axes {
        Axes {
            title: self.title.clone(),
            x_label: self.x.label(),
            y_label: format!("{}{} of node \"{}\"", self.metric, unit_of(&self.metric), self.error_node),
        }
    }
}

/// The unit a metric's name implies, for an axis label.
fn unit_of(metric: &str) -> &'static str {
    if metric.ends_with("_db") {
        " (dB)"
    } else if metric.ends_with("_percent") {
        " (%)"
    } else if metric.starts_with("rel_") {
        " (relative, no unit)"
    } else {
        ""
    }
}
