//! When an edit re-runs. The last runs say what each node costs; an edit whose re-run of the
//! viewed image costs no more than a frame's budget re-runs on every change (a slider drag
//! shows every value it can), a dearer one after the edits pause. At most one run is in
//! flight: while a cheap run is under way a newer edit waits for it and then runs the newest
//! value (coalesced); any other run a newer edit makes stale is cancelled at once.
//!
//! A cost measured in this session is trusted. One known only from a cached result (the
//! time the node took when it ran, perhaps beside other nodes sharing the cores, so often
//! more than its own work) is tried: the edit runs at once as if cheap, and if a newer edit
//! comes while that run is still going after [`PROBE_GRACE`], the run is cancelled and its
//! nodes are taken to cost what it had run so far. A drag over the budget that has shown
//! nothing for [`REPROBE_FIRST`] is tried the same way (a cost measured once, say by a first
//! run after opening, may not hold), waiting twice as long after each trial it had to cancel.

use relume_core::RunReport;
use std::collections::HashMap;
use std::time::Duration;

/// What the nodes an edit reaches may cost, together, for the edit to re-run on every change
/// instead of after a pause: 150 ms. The slowest rate an interactive edit is meant to reach
/// is 8 images a second (a refraction orbit, 110–125 ms a run in the window); with a 50 ms
/// budget such a drag waited for a pause, and showed nothing for its first second (until the
/// retry after `REPROBE_FIRST`).
pub const FRAME_BUDGET_MS: f64 = 150.0;

/// Quiet time after an edit before a re-run that is over the frame budget starts (a slider
/// drag on an expensive parameter runs once it pauses, not on every frame).
pub const RUN_DEBOUNCE: Duration = Duration::from_millis(150);

/// How long a tried run (`When::Probe`) may go on before a newer edit cancels it: long
/// enough for a first run after opening a graph, which also reads the cached inputs of what
/// it re-runs from disk.
pub const PROBE_GRACE: Duration = Duration::from_secs(1);

/// How long a drag over the budget may show nothing before its run is tried again, at first
/// and at most (the wait doubles after each trial that had to be cancelled).
pub const REPROBE_FIRST: Duration = Duration::from_secs(1);
pub const REPROBE_MAX: Duration = Duration::from_secs(16);

/// When an edit's re-run starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum When {
    /// On this change: the re-run fits the frame budget.
    Live,
    /// On this change, as a trial: the re-run is over the budget only with costs read from
    /// cached results (what was measured here fits); a newer edit cancels it once it has run
    /// longer than [`PROBE_GRACE`].
    Probe,
    /// After the edits pause for [`RUN_DEBOUNCE`]: the re-run is dearer, or its cost is unknown.
    AfterPause,
}

/// How many of a node's latest measured times its cost is the median of: two slow runs (a
/// page-fault storm, the drawing taking the cores a moment) do not make a cheap node dear,
/// three of the last five do. With three, one drive of a refraction orbit in eight (110–125 ms
/// a run in the window, the budget 150) lost about a second of images with unpaced frames, as
/// an edit priced dear does while it waits for a pause.
pub const COST_RUNS: usize = 5;

/// A node's cost and whether it was measured in this session.
#[derive(Clone, Debug, PartialEq)]
struct Cost {
    ms: f64,
    measured: bool,
    /// Its latest measured times, newest last (at most `COST_RUNS`).
    recent: Vec<f64>,
}

impl Cost {
    fn read(ms: f64) -> Cost {
        Cost { ms, measured: false, recent: Vec::new() }
    }

    /// Takes in a measured time: the cost becomes the median of the latest ones.
    fn measure(&mut self, ms: f64) {
        if !self.measured {
            self.recent.clear();
        }
        if self.recent.len() == COST_RUNS {
            self.recent.remove(0);
        }
        self.recent.push(ms);
        let mut sorted = self.recent.clone();
        sorted.sort_by(f64::total_cmp);
        (self.ms, self.measured) = (sorted[(sorted.len() - 1) / 2], true);
    }
}

/// What each node cost when it last ran, learnt from run reports.
#[derive(Clone, Debug, Default)]
pub struct Costs {
    ms: HashMap<String, Cost>,
}

impl Costs {
    /// Takes in a run's report: a node that ran, its time (its cost: the median of its latest
    /// `COST_RUNS` times); one from the cache, the time its result took when it ran (kept only
    /// while nothing was measured).
    pub fn learn(&mut self, report: &RunReport) {
        for n in &report.nodes {
            if n.status == "ran" {
                self.ms.entry(n.id.clone()).or_insert_with(|| Cost::read(n.wall_ms)).measure(n.wall_ms);
            } else if !self.ms.get(&n.id).is_some_and(|c| c.measured) {
                self.ms.insert(n.id.clone(), Cost::read(n.compute_ms));
            }
        }
    }

    /// Sets what a node costs, as measured (tests, and a trial cancelled after this long).
    pub fn set(&mut self, id: &str, ms: f64) {
        self.ms.insert(id.to_string(), Cost { ms, measured: true, recent: vec![ms] });
    }

    /// Whether the node's cost was measured in this session.
    pub fn measured(&self, id: &str) -> bool {
        self.ms.get(id).is_some_and(|c| c.measured)
    }

    /// Forgets everything (another graph was opened).
    pub fn clear(&mut self) {
        self.ms.clear();
    }

    /// The cost of running these nodes; `None` when one of them has not run yet.
    pub fn estimate<'a>(&self, nodes: impl IntoIterator<Item = &'a str>) -> Option<f64> {
        nodes.into_iter().map(|id| self.ms.get(id).map(|c| c.ms)).sum()
    }

    /// When a re-run of these nodes starts.
    pub fn when<'a>(&self, nodes: impl IntoIterator<Item = &'a str> + Clone) -> When {
        let measured: f64 = nodes.clone().into_iter().filter_map(|id| self.ms.get(id).filter(|c| c.measured).map(|c| c.ms)).sum();
        match self.estimate(nodes) {
            None => When::AfterPause,
            Some(ms) if ms <= FRAME_BUDGET_MS => When::Live,
            // Over the budget by what was measured here alone: dear.
            Some(_) if measured > FRAME_BUDGET_MS => When::AfterPause,
            Some(_) => When::Probe,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_core::NodeReport;

    fn report(nodes: &[(&str, f64)]) -> RunReport {
        ran(nodes, "ran")
    }

    fn ran(nodes: &[(&str, f64)], status: &'static str) -> RunReport {
        let wall = |ms: f64| if status == "ran" { ms } else { 0.01 };
        RunReport { nodes: nodes.iter().map(|&(id, ms)| NodeReport::timed(id, status, wall(ms), ms)).collect(), ..Default::default() }
    }

    #[test]
    fn cheap_known_nodes_run_live_and_dear_or_unknown_ones_after_a_pause() {
        let mut c = Costs::default();
        c.learn(&report(&[("project", 1.5), ("relight", 4.4), ("transfer", 9000.0)]));
        assert_eq!(c.estimate(["project", "relight"]), Some(5.9));
        assert_eq!(c.when(["project", "relight"]), When::Live);
        assert_eq!(c.when([]), When::Live, "an edit that reaches nothing viewed costs nothing");
        assert_eq!(c.when(["transfer", "relight"]), When::AfterPause);
        assert_eq!(c.when(["relight", "new_node"]), When::AfterPause, "a node that never ran has no known cost");
        // A node costs the median of its latest runs: exactly the budget is still live, two
        // dear runs of five do not make it dear, three do.
        c.learn(&report(&[("relight", FRAME_BUDGET_MS)]));
        c.learn(&report(&[("relight", FRAME_BUDGET_MS)]));
        assert_eq!(c.when(["relight"]), When::Live);
        c.learn(&report(&[("relight", 4.0)]));
        c.learn(&report(&[("relight", 400.0)]));
        c.learn(&report(&[("relight", FRAME_BUDGET_MS + 0.1)]));
        assert_eq!((c.estimate(["relight"]), c.when(["relight"])), (Some(FRAME_BUDGET_MS), When::Live));
        c.learn(&report(&[("relight", FRAME_BUDGET_MS + 0.1)]));
        assert_eq!((c.estimate(["relight"]), c.when(["relight"])), (Some(FRAME_BUDGET_MS + 0.1), When::AfterPause));
        c.clear();
        assert_eq!(c.estimate(["relight"]), None);
    }

    #[test]
    fn a_dear_cost_read_from_the_cache_is_tried_and_a_measured_one_trusted() {
        let mut c = Costs::default();
        c.learn(&ran(&[("hits", 155_000.0), ("raster", 2.0)], "cached"));
        assert_eq!(c.when(["hits", "raster"]), When::Probe);
        assert_eq!(c.when(["raster"]), When::Live);
        // Measured in this session: trusted, cheap or dear; a later cached figure does not
        // replace a measured one.
        c.learn(&report(&[("hits", 3.0)]));
        assert_eq!(c.when(["hits", "raster"]), When::Live);
        c.learn(&ran(&[("hits", 155_000.0)], "cached"));
        assert_eq!(c.when(["hits", "raster"]), When::Live);
        c.set("hits", 400.0);
        assert_eq!(c.when(["hits", "raster"]), When::AfterPause);
    }
}
