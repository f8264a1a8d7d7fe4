//! The RON graph format: round trips, meaning preserved, migrations, atomic saving.

use relume_core::graph::{Migration, FORMAT_VERSION};
use relume_core::ron::{Ron, RonKind};
use relume_core::Graph;
use relume_tests::{all_graphs, engine, ran, run};

#[test]
fn a_graph_relume_saved_loads_and_saves_back_byte_identical() {
    let reg = relume_cli::registry();
    assert!(all_graphs().len() >= 2);
    for path in all_graphs() {
        let g = Graph::load(&path, &reg).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let saved = dir.path().join("g.ron");
        g.save(&saved).unwrap();
        let first = std::fs::read(&saved).unwrap();
        let again = Graph::load(&saved, &reg).unwrap();
        again.save(&saved).unwrap();
        assert_eq!(std::fs::read(&saved).unwrap(), first, "{}", path.display());
    }
}

#[test]
fn a_hand_written_graph_keeps_its_meaning_when_saved() {
    let reg = relume_cli::registry();
    let e = engine();
    let path = relume_tests::graphs_dir().join("filters.ron");
    let hand = Graph::load(&path, &reg).unwrap();
    let text = hand.to_ron();
    assert!(!text.contains("//"), "comments go");
    let mut saved = Graph::parse(&text, Some(&path)).unwrap();
    saved.base_dir = hand.base_dir.clone();
    run(&e, &hand);
    assert!(ran(&run(&e, &saved)).is_empty(), "same keys: same meaning");
    assert_eq!(saved.editor, hand.editor);
}

#[test]
fn a_file_from_a_newer_relume_is_refused_with_the_version() {
    let e = Graph::parse("Graph(version: 7, nodes: {})", None).unwrap_err().to_string();
    assert!(e.contains("version 7 is newer") && e.contains(&FORMAT_VERSION.to_string()), "{e}");
}

#[test]
fn an_old_version_is_upgraded_by_its_migration_function() {
    // A hypothetical version 0 called the edge list `links`.
    fn rename_links(doc: &mut Ron) -> Result<(), String> {
        let RonKind::Struct(_, fields) = &mut doc.kind else { return Err("not a struct".into()) };
        for f in fields.iter_mut() {
            if f.name == "links" {
                f.name = "edges".into();
            }
        }
        Ok(())
    }
    let old = r#"Graph(version: 0, nodes: { "a": (kind: "TestPattern", params: ()), "b": (kind: "Tonemap", params: ()) }, links: [("a.image", "b.image")], outputs: {})"#;
    let g = Graph::parse_with(old, None, &[Migration { from: 0, apply: rename_links }]).unwrap();
    assert_eq!(g.edges.len(), 1);
    assert!(g.to_ron().contains(&format!("version: {FORMAT_VERSION},")));
    let e = Graph::parse(old, None).unwrap_err().to_string();
    assert!(e.contains("version 0 is not supported"), "{e}");
}

#[test]
fn saving_replaces_the_file_whole_and_leaves_no_temporary_files() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.ron");
    std::fs::write(&path, "old content that is longer than the new one ".repeat(100)).unwrap();
    let g = Graph::parse("Graph(version: 1, nodes: {})", None).unwrap();
    g.save(&path).unwrap();
    assert_eq!(std::fs::read_to_string(&path).unwrap(), g.to_ron());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    // A save that cannot happen leaves the old file as it was.
    let blocked = dir.path().join("missing-dir").join("g.ron");
    assert!(g.save(&blocked).is_err());
    assert_eq!(std::fs::read_to_string(&path).unwrap(), g.to_ron());
}

#[test]
fn a_graph_built_from_code_checks_kinds_ids_connections_and_runs() {
    use relume_core::graph::PortRef;
    let reg = relume_cli::registry();
    let port = |s: &str| PortRef::parse(s).unwrap();
    let mut g = Graph::default();
    let pattern = g.add_node(&reg, "TestPattern", None).unwrap();
    assert_eq!(pattern, "test_pattern");
    assert_eq!(g.unique_id("TestPattern"), "test_pattern_2");
    assert_eq!(g.add_node(&reg, "GaussianBlur", Some("blur")).unwrap(), "blur");
    assert!(g.add_node(&reg, "GaussianBlur", Some("blur")).unwrap_err().msg.contains("already"));
    assert!(g.add_node(&reg, "GaussianBlur", Some("a.b")).unwrap_err().msg.contains("not a node id"));
    let e = g.add_node(&reg, "GausianBlur", None).unwrap_err();
    assert!(e.msg.contains("did you mean \"GaussianBlur\""), "{}", e.msg);
    // Types and cycles are checked; a second connection into an input replaces the first.
    assert!(g.connect(&reg, port("blur.image"), port("blur.image")).is_err());
    g.connect(&reg, port("test_pattern.image"), port("blur.image")).unwrap();
    g.connect(&reg, port("test_pattern.image"), port("blur.image")).unwrap();
    assert_eq!(g.edges.len(), 1);
    g.set_output(&port("blur.image"), "image", true);
    g.set_output(&port("blur.image"), "image", true);
    assert_eq!(g.outputs.len(), 1);
    g.validate(&reg).unwrap();
    // Saved and read back, it is the same graph, and it runs.
    let back = Graph::parse(&g.to_ron(), None).unwrap();
    assert_eq!(back.to_ron(), g.to_ron());
    let r = run(&engine(), &back);
    assert_eq!(ran(&r), ["blur", "test_pattern"]);
}
