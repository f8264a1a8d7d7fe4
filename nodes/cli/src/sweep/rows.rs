//! The sweep's data: what it varies, its rows (one run each) and how it groups them into
//! curves.

use relume_core::RunReport;

/// What the plot's time axis measures.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub(crate) enum TimeAxis {
    Pipeline,
    Ran,
}

/// Which curve a row belongs to.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) enum Series {
    Method,
    Baseline,
}

impl Series {
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            Series::Method => "method",
            Series::Baseline => "baseline",
        }
    }
}

/// One measured variant.
pub(crate) struct Row {
    pub(crate) series: Series,
    pub(crate) label: String,
    /// Value of each parameter column, as canonical RON text.
    pub(crate) params: Vec<String>,
    pub(crate) time_ms: f64,
    /// Compute time of the pipeline behind the plotted image (see `--time pipeline`).
    pub(crate) pipeline_ms: f64,
    pub(crate) report: RunReport,
}

/// `--vary node.param=a,b,c` (or `a.p+b.q=…`) split up.
pub(crate) struct Vary {
    /// The parameters set, each to the same value.
    pub(crate) targets: Vec<String>,
    pub(crate) values: Vec<String>,
}
