//! The executor: concurrency of independent nodes, cancellation, progress events, failures.

use relume_core::{CancelToken, Engine, Event, Graph, Observer, Registry, RunError, RunOptions};
use relume_tests::{rendezvous, test_registry, Log, UntilCancelled};
use std::sync::Mutex;

#[test]
fn independent_nodes_run_at_the_same_time() {
    let mut reg = Registry::new();
    reg.add_dyn(rendezvous(2));
    let g = Graph::parse(r#"(version: 1, nodes: { "a": (kind: "Rendezvous", params: (salt: 1)), "b": (kind: "Rendezvous", params: (salt: 2)) }, outputs: { "a": "a.out", "b": "b.out" })"#, None).unwrap();
    // Each node waits until the other is running too: a sequential executor fails here.
    let r = Engine::new(reg).with_parallelism(2).run(&g, &RunOptions::default()).unwrap();
    assert_eq!(r.report.ran, 2);
}

/// Records events; cancels the run when `UntilCancelled` reports progress.
struct Recorder {
    events: Mutex<Vec<String>>,
    cancel: CancelToken,
}

impl Observer for Recorder {
    fn event(&self, e: &Event<'_>) {
        let line = match e {
            Event::Planned { nodes } => format!("planned {nodes}"),
            Event::Started { id, .. } => format!("started {id}"),
            Event::Progress { id, .. } => {
                self.cancel.cancel();
                format!("progress {id}")
            }
            Event::Finished { id, status, .. } => format!("finished {id} {}", status.as_str()),
            Event::Failed { id, .. } => format!("failed {id}"),
            Event::Partial { id, .. } => format!("partial {id}"),
            Event::Output { name, .. } => format!("output {name}"),
        };
        let mut ev = self.events.lock().unwrap();
        if ev.last() != Some(&line) {
            ev.push(line);
        }
    }
}

#[test]
fn a_cancelled_run_stops_reports_cancelled_and_leaves_the_cache_consistent() {
    let log = Log::default();
    let mut reg = test_registry(&log);
    reg.add::<UntilCancelled>();
    let g = Graph::parse(
        r#"(version: 1, nodes: { "a": (kind: "Mix0", params: ()), "slow": (kind: "UntilCancelled", params: ()), "after": (kind: "Mix1", params: ()) },
           edges: [("a.out", "slow.in0"), ("slow.out", "after.in0")], outputs: { "x": "after.out" })"#,
        None,
    )
    .unwrap();
    let engine = Engine::new(reg);
    let rec = Recorder { events: Mutex::default(), cancel: CancelToken::new() };
    let opts = RunOptions { cancel: rec.cancel.clone(), observer: Some(&rec), ..Default::default() };
    let err = engine.run(&g, &opts).err().expect("cancelled");
    assert!(matches!(err, RunError::Cancelled), "{err}");
    let events = rec.events.lock().unwrap().clone();
    assert_eq!(events, ["planned 3", "started a", "finished a ran", "started slow", "progress slow"]);
    assert_eq!(*log.lock().unwrap(), ["a"], "nothing after the cancelled node ran");
    // The next run reuses what finished and starts again at the node that did not.
    let rec2 = Recorder { events: Mutex::default(), cancel: CancelToken::new() };
    let opts = RunOptions { cancel: rec2.cancel.clone(), observer: Some(&rec2), ..Default::default() };
    assert!(matches!(engine.run(&g, &opts), Err(RunError::Cancelled)));
    assert_eq!(*rec2.events.lock().unwrap(), ["planned 3", "finished a cached", "started slow", "progress slow"]);
    assert_eq!(*log.lock().unwrap(), ["a"]);
}

#[test]
fn a_failing_node_is_named_with_its_kind_and_message() {
    let reg = relume_cli::registry();
    let g = Graph::parse(
        r#"(version: 1, nodes: { "a": (kind: "TestPattern", params: (width: 4, height: 4)), "b": (kind: "TestPattern", params: (width: 5, height: 4)), "sum": (kind: "Combine", params: ()) },
           edges: [("a.image", "sum.a"), ("b.image", "sum.b")], outputs: { "x": "sum.image" })"#,
        None,
    )
    .unwrap();
    let err = Engine::new(reg).run(&g, &RunOptions::default()).err().unwrap().to_string();
    assert_eq!(err, "node \"sum\" (Combine) failed: input `b`: is 5 × 4 but `a` is 4 × 4");
}

#[test]
fn every_needed_node_reports_start_and_finish_and_cached_nodes_only_finish() {
    let log = Log::default();
    let engine = Engine::new(test_registry(&log));
    let g = Graph::parse(r#"(version: 1, nodes: { "a": (kind: "Mix0", params: ()), "b": (kind: "Mix1", params: ()) }, edges: [("a.out", "b.in0")], outputs: { "x": "b.out" })"#, None).unwrap();
    let rec = Recorder { events: Mutex::default(), cancel: CancelToken::new() };
    let opts = RunOptions { observer: Some(&rec), ..Default::default() };
    engine.run(&g, &opts).unwrap();
    engine.run(&g, &opts).unwrap();
    let events = rec.events.lock().unwrap().clone();
    assert_eq!(
        events,
        [
            "planned 2",
            "started a",
            "finished a ran",
            "started b",
            "finished b ran",
            "output x",
            "planned 2",
            "finished a cached",
            "finished b cached",
            "output x"
        ]
    );
}

#[test]
fn each_output_is_announced_once_as_soon_as_its_node_finishes() {
    let log = Log::default();
    let mut reg = test_registry(&log);
    reg.add::<UntilCancelled>();
    // "early" is ready long before "late", whose node waits for a cancel that comes only
    // after "early" was announced.
    let g = Graph::parse(
        r#"(version: 1, nodes: { "a": (kind: "Mix0", params: ()), "slow": (kind: "UntilCancelled", params: ()) },
           edges: [("a.out", "slow.in0")], outputs: { "early": "a.out", "late": "slow.out", "again": "a.out" })"#,
        None,
    )
    .unwrap();
    let engine = Engine::new(reg);
    let rec = Recorder { events: Mutex::default(), cancel: CancelToken::new() };
    let opts = RunOptions { cancel: rec.cancel.clone(), observer: Some(&rec), ..Default::default() };
    assert!(matches!(engine.run(&g, &opts), Err(RunError::Cancelled)));
    let events = rec.events.lock().unwrap().clone();
    assert_eq!(events, ["planned 2", "started a", "finished a ran", "output early", "output again", "started slow", "progress slow"]);
}

/// Records the order in which nodes start and finish (no cancelling).
#[derive(Default)]
struct Order(Mutex<Vec<String>>);

impl Observer for Order {
    fn event(&self, e: &Event<'_>) {
        let line = match e {
            Event::Started { id, .. } => format!("started {id}"),
            Event::Finished { id, .. } => format!("finished {id}"),
            _ => return,
        };
        self.0.lock().unwrap().push(line);
    }
}

#[test]
fn of_two_ready_renders_the_one_with_a_sixteenth_of_the_samples_runs_first_and_alone() {
    // The README's graph at 8 × 8: the 64-spp render and the ground truth become ready together.
    let reg = relume_cli::registry();
    let mut g = Graph::load(&relume_tests::graphs_dir().join("reference_cornell.ron"), &reg).unwrap();
    for (a, v) in [("scene.width", "8"), ("scene.height", "8"), ("reference.spp", "16"), ("truth.spp", "256")] {
        g.set_param_text(&reg, a, v).unwrap();
    }
    let order = Order::default();
    let opts = RunOptions { observer: Some(&order), ..Default::default() };
    Engine::new(reg).with_parallelism(2).without_disk_cache().run(&g, &opts).unwrap();
    let events = order.0.lock().unwrap().clone();
    let at = |e: &str| events.iter().position(|x| x == e).unwrap_or_else(|| panic!("no \"{e}\" in {events:?}"));
    assert!(at("finished reference") < at("started truth"), "{events:?}");
}
