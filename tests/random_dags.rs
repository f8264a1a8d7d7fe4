//! Property tests on random DAGs: every needed node runs exactly once and after its inputs;
//! nodes no requested output reaches never run.

use proptest::prelude::*;
use relume_core::{Engine, Graph, RunOptions};
use relume_tests::{test_registry, Log};
use std::collections::{HashMap, HashSet};

/// A random DAG: node i takes 0..=3 inputs from nodes before it.
fn dag() -> impl Strategy<Value = (Vec<Vec<usize>>, Vec<usize>)> {
    (2usize..24).prop_flat_map(|n| {
        let inputs = (0..n)
            .map(|i| if i == 0 { Just(vec![]).boxed() } else { proptest::collection::vec(0..i, 0..=3.min(i)).boxed() })
            .collect::<Vec<_>>();
        (inputs, proptest::collection::vec(0..n, 1..4))
    })
}

fn build(inputs: &[Vec<usize>], outs: &[usize]) -> Graph {
    let mut text = String::from("Graph(version: 1, nodes: {");
    for (i, ins) in inputs.iter().enumerate() {
        text += &format!("\"n{i}\": (kind: \"Mix{}\", params: (salt: {i})),", ins.len());
    }
    text += "}, edges: [";
    for (i, ins) in inputs.iter().enumerate() {
        for (k, src) in ins.iter().enumerate() {
            text += &format!("(\"n{src}.out\", \"n{i}.in{k}\"),");
        }
    }
    text += "], outputs: {";
    for o in outs.iter().collect::<HashSet<_>>() {
        text += &format!("\"o{o}\": \"n{o}.out\",");
    }
    text += "})";
    Graph::parse(&text, None).unwrap()
}

fn needed(inputs: &[Vec<usize>], outs: &[usize]) -> HashSet<usize> {
    let mut seen = HashSet::new();
    let mut stack: Vec<usize> = outs.to_vec();
    while let Some(i) = stack.pop() {
        if seen.insert(i) {
            stack.extend(&inputs[i]);
        }
    }
    seen
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(96))]

    #[test]
    fn needed_nodes_run_once_after_their_inputs_and_unneeded_nodes_never((inputs, outs) in dag(), threads in 1usize..4) {
        let log = Log::default();
        let engine = Engine::new(test_registry(&log)).with_parallelism(threads);
        let g = build(&inputs, &outs);
        let result = engine.run(&g, &RunOptions::default()).unwrap();
        let order = log.lock().unwrap().clone();
        let pos: HashMap<usize, usize> = order.iter().enumerate().map(|(k, id)| (id[1..].parse().unwrap(), k)).collect();
        prop_assert_eq!(pos.len(), order.len(), "a node ran twice: {:?}", order);
        let want = needed(&inputs, &outs);
        prop_assert_eq!(&pos.keys().copied().collect::<HashSet<_>>(), &want);
        for (&i, &k) in &pos {
            for src in &inputs[i] {
                prop_assert!(pos[src] < k, "n{} ran before its input n{}", i, src);
            }
        }
        prop_assert_eq!(result.report.ran, pos.len());

        // A second run of the same graph runs nothing.
        log.lock().unwrap().clear();
        let again = engine.run(&g, &RunOptions::default()).unwrap();
        prop_assert!(log.lock().unwrap().is_empty());
        prop_assert_eq!(again.report.cached, want.len());
        for (name, v) in &result.outputs {
            prop_assert_eq!(again.output(name).unwrap().fingerprint(), v.fingerprint());
        }
    }
}
