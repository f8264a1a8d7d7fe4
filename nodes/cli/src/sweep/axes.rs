//! What a sweep's plot draws: the x axis (time, a varied parameter or a metric, `--x`) and the
//! curves (one for the method's rows, or one per value of a varied parameter, `--series`).

use super::rows::{Row, Series, TimeAxis, Vary};
use crate::error::CliError;
use crate::plot::Curve;
use plotters::style::RGBColor;
use relume_core::{Graph, Registry};

/// The plot's x axis.
#[derive(PartialEq)]
pub(super) enum XAxis {
    Time(TimeAxis),
    /// A parameter column (its index among the CSV's parameter columns).
    Param(usize, String),
    /// `node.metric`.
    Metric(String, String),
}

impl XAxis {
    /// `--x COLUMN` checked against the parameter columns and the metrics the graph's nodes
    /// report, before anything runs; without it, the `--time` axis.
    pub(super) fn parse(x: Option<&str>, time: TimeAxis, columns: &[String], graph: &Graph, reg: &Registry) -> Result<XAxis, CliError> {
        let Some(x) = x else { return Ok(XAxis::Time(time)) };
        match x {
            "time_ms" => return Ok(XAxis::Time(TimeAxis::Ran)),
            "pipeline_ms" => return Ok(XAxis::Time(TimeAxis::Pipeline)),
            _ => {}
        }
        if let Some(i) = columns.iter().position(|c| c == x) {
            return Ok(XAxis::Param(i, x.to_string()));
        }
        let refuse = |why: String| {
            CliError::graph(format!(
                "--x {x}: {why}; give a varied parameter ({}), a metric as node.metric, time_ms or pipeline_ms",
                if columns.is_empty() { "none".to_string() } else { columns.join(", ") }
            ))
        };
        let (id, metric) = x.split_once('.').ok_or_else(|| refuse("not a column".into()))?;
        let node = graph.node(id).ok_or_else(|| refuse(format!("no node \"{id}\" in the graph")))?;
        let have = reg.node(&node.kind).map_or(&[][..], |k| k.metrics());
        if !have.contains(&metric) {
            return Err(refuse(if have.is_empty() {
                format!("node \"{id}\" ({}) reports no metric and `{metric}` is not a varied parameter", node.kind)
            } else {
                format!("node \"{id}\" ({}) reports no `{metric}` (it reports: {})", node.kind, have.join(", "))
            }));
        }
        Ok(XAxis::Metric(id.to_string(), metric.to_string()))
    }

    /// The row's x value (NaN where there is none; the plot leaves such points out).
    fn of(&self, r: &Row) -> f64 {
        match self {
            XAxis::Time(TimeAxis::Ran) => r.time_ms,
            XAxis::Time(TimeAxis::Pipeline) => r.pipeline_ms,
            XAxis::Param(i, _) => r.params[*i].parse().unwrap_or(f64::NAN),
            XAxis::Metric(node, m) => r.report.node(node).and_then(|n| n.metrics.get(m)).copied().unwrap_or(f64::NAN),
        }
    }

    pub(super) fn label(&self) -> String {
        match self {
            XAxis::Time(TimeAxis::Ran) => "time (ms): wall time of the nodes that ran, cached nodes cost 0".into(),
            XAxis::Time(TimeAxis::Pipeline) => "time (ms): compute time of the pipeline that made the image (reference excluded)".into(),
            XAxis::Param(_, name) => name.clone(),
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

/// How the rows become curves.
pub(super) struct Plotted<'a> {
    pub x: &'a XAxis,
    /// Index of the --vary that `--series` splits by.
    pub series: Option<usize>,
    pub varies: &'a [Vary],
    /// The varied parameters' columns.
    pub columns: &'a [String],
}

impl Plotted<'_> {
    /// A method point's label: the values of the --vary lists that neither the x axis nor the
    /// series already shows.
    fn point_label(&self, r: &Row) -> String {
        let x_vary = match self.x {
            XAxis::Param(i, _) => self.varies.iter().position(|v| v.targets.contains(&self.columns[*i])),
            _ => None,
        };
        let shown = |k: usize| Some(k) == x_vary || Some(k) == self.series;
        r.values.iter().enumerate().filter(|(k, _)| !shown(*k)).map(|(_, v)| v.as_str()).collect::<Vec<_>>().join(", ")
    }

    fn points<'r>(
        &self,
        rows: impl Iterator<Item = &'r Row>,
        node: &str,
        metric: &str,
        label: impl Fn(&Row) -> String,
    ) -> Vec<(f64, f64, String)> {
        rows.map(|r| {
            let y = r.report.node(node).and_then(|n| n.metrics.get(metric)).copied().unwrap_or(f64::NAN);
            (self.x.of(r), y, label(r))
        })
        .collect()
    }

    /// The method's rows as one curve, or one per value of the `--series` vary (in the order
    /// of its list), each in the order the rows ran.
    pub(super) fn method_curves(&self, rows: &[Row], node: &str, metric: &str) -> Vec<Curve> {
        let method = || rows.iter().filter(|r| r.series == Series::Method);
        if self.varies.is_empty() {
            return Vec::new();
        }
        let Some(k) = self.series else {
            let name = format!("method ({})", self.columns.join(", "));
            return vec![Curve { name, color: PALETTE[0], points: self.points(method(), node, metric, |r| self.point_label(r)) }];
        };
        let vary = &self.varies[k];
        let mut values: Vec<&String> = Vec::new();
        for v in &vary.values {
            if !values.contains(&v) {
                values.push(v);
            }
        }
        values
            .into_iter()
            .enumerate()
            .map(|(c, value)| Curve {
                name: format!("{} = {value}", vary.targets.join(" = ")),
                color: PALETTE[c % PALETTE.len()],
                points: self.points(method().filter(|r| &r.values[k] == value), node, metric, |r| self.point_label(r)),
            })
            .collect()
    }

    pub(super) fn baseline_curve(&self, rows: &[Row], node: &str, metric: &str, name: String) -> Curve {
        let points = self.points(rows.iter().filter(|r| r.series == Series::Baseline), node, metric, |r| r.short.clone());
        Curve { name, color: BASELINE, points }
    }
}
