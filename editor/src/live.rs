//! When an edit re-runs. The last runs say what each node costs; an edit whose re-run of the
//! viewed image costs no more than a frame's budget re-runs on every change (a slider drag
//! shows every value it can), a dearer one after the edits pause. At most one run is in
//! flight: while a cheap run is under way a newer edit waits for it and then runs the newest
//! value (coalesced); any other run a newer edit makes stale is cancelled at once.

use relume_core::RunReport;
use std::collections::HashMap;
use std::time::Duration;

/// What the nodes an edit reaches may cost, together, for the edit to re-run on every change
/// instead of after a pause: 50 ms, a 20 images-per-second floor.
pub const FRAME_BUDGET_MS: f64 = 50.0;

/// Quiet time after an edit before a re-run that is over the frame budget starts (a slider
/// drag on an expensive parameter runs once it pauses, not on every frame).
pub const RUN_DEBOUNCE: Duration = Duration::from_millis(150);

/// When an edit's re-run starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum When {
    /// On this change: the re-run fits the frame budget.
    Live,
    /// After the edits pause for [`RUN_DEBOUNCE`]: the re-run is dearer, or its cost is unknown.
    AfterPause,
}

/// What each node cost when it last ran, learnt from run reports.
#[derive(Clone, Debug, Default)]
pub struct Costs {
    ms: HashMap<String, f64>,
}

impl Costs {
    /// Takes in a run's report: each node's own cost, whether it ran or came from the cache.
    pub fn learn(&mut self, report: &RunReport) {
        for n in &report.nodes {
            self.ms.insert(n.id.clone(), n.compute_ms);
        }
    }

    /// Sets what a node costs (tests, and a caller that knows better than the last run).
    pub fn set(&mut self, id: &str, ms: f64) {
        self.ms.insert(id.to_string(), ms);
    }

    /// Forgets everything (another graph was opened).
    pub fn clear(&mut self) {
        self.ms.clear();
    }

    /// The cost of running these nodes; `None` when one of them has not run yet.
    pub fn estimate<'a>(&self, nodes: impl IntoIterator<Item = &'a str>) -> Option<f64> {
        nodes.into_iter().map(|id| self.ms.get(id).copied()).sum()
    }

    /// When a re-run of these nodes starts.
    pub fn when<'a>(&self, nodes: impl IntoIterator<Item = &'a str>) -> When {
        match self.estimate(nodes) {
            Some(ms) if ms <= FRAME_BUDGET_MS => When::Live,
            _ => When::AfterPause,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_core::NodeReport;

    fn report(nodes: &[(&str, f64)]) -> RunReport {
        let node = |&(id, ms): &(&str, f64)| NodeReport {
            id: id.into(),
            kind: "K".into(),
            status: "cached",
            cache: Some("memory"),
            wall_ms: 0.01,
            compute_ms: ms,
            bytes: 0,
            key: String::new(),
            metrics: Default::default(),
            notes: Vec::new(),
            shards: None,
        };
        RunReport { nodes: nodes.iter().map(node).collect(), ..Default::default() }
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
        // Exactly the budget is still live; a later, dearer run of the same node is learnt.
        c.learn(&report(&[("relight", FRAME_BUDGET_MS)]));
        assert_eq!(c.when(["relight"]), When::Live);
        c.learn(&report(&[("relight", FRAME_BUDGET_MS + 0.1)]));
        assert_eq!(c.when(["relight"]), When::AfterPause);
        c.clear();
        assert_eq!(c.estimate(["relight"]), None);
    }
}
