//! From RON text to a `Graph` (structure only; `validate` checks it against the registry).

use super::migrate::{upgrade, Migration, MIGRATIONS};
use super::{is_valid_id, Edge, EditorSection, Graph, NodeDecl, Output, PortRef, FORMAT_VERSION, MAX_NODES};
use crate::error::{GraphError, GraphErrors};
use crate::params::ParamValue;
use crate::ron::{parse, Field, Ron, RonKind};
use std::path::Path;

impl Graph {
    /// Parses graph text. `file` names it in messages and sets the folder that file
    /// parameters resolve against.
    pub fn parse(text: &str, file: Option<&Path>) -> Result<Graph, GraphErrors> {
        Graph::parse_with(text, file, MIGRATIONS)
    }

    /// As `parse`, with an explicit list of migrations.
    pub fn parse_with(text: &str, file: Option<&Path>, migrations: &[Migration]) -> Result<Graph, GraphErrors> {
        // Some editors on Windows start a UTF-8 file with a byte-order mark: not part of the text.
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let file_buf = file.map(Path::to_path_buf);
        let mut doc = parse(text)
            .map_err(|e| GraphErrors::one(GraphError::new(format!("malformed RON: {}", e.msg)).at(e.pos)).with_file(&file_buf))?;
        let mut errs = Vec::new();
        let version = read_version(&doc).map_err(|e| GraphErrors::one(e).with_file(&file_buf))?;
        if version > FORMAT_VERSION {
            let e = GraphError::new(format!(
                "graph format version {version} is newer than this relume reads ({FORMAT_VERSION}); update relume"
            ))
            .at(doc.pos);
            return Err(GraphErrors::one(e).with_file(&file_buf));
        }
        upgrade(&mut doc, version, FORMAT_VERSION, migrations)
            .map_err(|m| GraphErrors::one(GraphError::new(m).at(doc.pos)).with_file(&file_buf))?;

        let mut g = Graph {
            file: file_buf.clone(),
            base_dir: file.and_then(Path::parent).map(Path::to_path_buf).unwrap_or_default(),
            ..Graph::default()
        };
        let fields = top_fields(&doc).map_err(|e| GraphErrors::one(e).with_file(&file_buf))?;
        let mut seen_nodes = false;
        for f in fields {
            match f.name.as_str() {
                "version" => {}
                "nodes" => {
                    seen_nodes = true;
                    read_nodes(&f.value, &mut g, &mut errs)
                }
                "edges" => read_edges(&f.value, &mut g, &mut errs),
                "outputs" => read_outputs(&f.value, &mut g, &mut errs),
                "editor" => read_editor(&f.value, &mut g, &mut errs),
                other => errs.push(
                    GraphError::new(format!("unknown field `{other}` (a graph has: version, nodes, edges, outputs, editor)")).at(f.pos),
                ),
            }
        }
        if !seen_nodes {
            errs.push(GraphError::new("the graph has no `nodes` field").at(doc.pos));
        }
        if errs.is_empty() {
            Ok(g)
        } else {
            Err(GraphErrors(errs).with_file(&file_buf))
        }
    }
}

fn top_fields(doc: &Ron) -> Result<&[Field], GraphError> {
    match &doc.kind {
        RonKind::Struct(name, fields) if name.as_deref().is_none_or(|n| n == "Graph") => Ok(fields),
        _ => Err(GraphError::new(format!("expected `Graph( version: …, nodes: {{…}}, … )`, found {}", doc.what())).at(doc.pos)),
    }
}

fn read_version(doc: &Ron) -> Result<u32, GraphError> {
    let fields = top_fields(doc)?;
    let f = fields
        .iter()
        .find(|f| f.name == "version")
        .ok_or_else(|| GraphError::new("the graph has no `version` field (write `version: 1`)").at(doc.pos))?;
    match f.value.kind {
        RonKind::Int(v) if (0..=u32::MAX as i64).contains(&v) => Ok(v as u32),
        _ => Err(GraphError::new(format!("`version` must be a whole number, found {}", f.value.what())).at(f.value.pos)),
    }
}

fn map_entries<'a>(v: &'a Ron, what: &str, errs: &mut Vec<GraphError>) -> &'a [(Ron, Ron)] {
    match &v.kind {
        RonKind::Map(m) => m,
        _ => {
            errs.push(GraphError::new(format!("`{what}` must be a map {{ \"name\": … }}, found {}", v.what())).at(v.pos));
            &[]
        }
    }
}

fn key_str<'a>(k: &'a Ron, what: &str, errs: &mut Vec<GraphError>) -> Option<&'a str> {
    match k.as_str() {
        Some(s) if is_valid_id(s) => Some(s),
        Some(s) => {
            errs.push(GraphError::new(format!("{what} \"{s}\" may use only letters, digits, `_` and `-`")).at(k.pos));
            None
        }
        None => {
            errs.push(GraphError::new(format!("{what} must be a quoted string, found {}", k.what())).at(k.pos));
            None
        }
    }
}

fn read_nodes(v: &Ron, g: &mut Graph, errs: &mut Vec<GraphError>) {
    let entries = map_entries(v, "nodes", errs);
    if entries.len() > MAX_NODES {
        errs.push(
            GraphError::new(format!(
                "the graph has {} nodes; relume reads at most {MAX_NODES} (a study of many variants is a sweep: `relume sweep --vary`)",
                entries.len()
            ))
            .at(v.pos),
        );
        return;
    }
    let mut seen = std::collections::HashSet::with_capacity(entries.len());
    for (k, body) in entries {
        let Some(id) = key_str(k, "node id", errs) else { continue };
        let errs_before = errs.len();
        if !seen.insert(id) {
            errs.push(GraphError::new("node id used twice").at(k.pos).node(id));
            continue;
        }
        let Some(fields) = body.fields() else {
            errs.push(GraphError::new(format!("expected `(kind: \"…\", params: (…))`, found {}", body.what())).at(body.pos).node(id));
            continue;
        };
        let mut decl = NodeDecl::new(id, "");
        decl.pos = k.pos;
        for f in fields {
            match f.name.as_str() {
                "kind" => match f.value.as_str() {
                    Some(s) => decl.kind = s.to_string(),
                    None => errs.push(
                        GraphError::new(format!("`kind` must be a quoted node kind, found {}", f.value.what())).at(f.value.pos).node(id),
                    ),
                },
                "params" => match f.value.fields() {
                    Some(ps) => {
                        for p in ps {
                            if decl.param(&p.name).is_some() {
                                errs.push(GraphError::new("given twice").at(p.pos).node(id).param(&p.name));
                                continue;
                            }
                            match ParamValue::from_ron(&p.value) {
                                Ok(pv) => {
                                    decl.params.push((p.name.clone(), pv));
                                    decl.param_pos.push(p.pos);
                                }
                                Err(m) => errs.push(GraphError::new(m).at(p.value.pos).node(id).param(&p.name)),
                            }
                        }
                    }
                    None => errs.push(
                        GraphError::new(format!("`params` must be `( name: value, … )`, found {}", f.value.what()))
                            .at(f.value.pos)
                            .node(id),
                    ),
                },
                other => errs.push(GraphError::new(format!("unknown field `{other}` (a node has: kind, params)")).at(f.pos).node(id)),
            }
        }
        if decl.kind.is_empty() && errs.len() == errs_before {
            errs.push(GraphError::new("the node has no `kind`").at(k.pos).node(id));
        }
        g.nodes.push(decl);
    }
}

fn port_ref(v: &Ron, errs: &mut Vec<GraphError>) -> Option<PortRef> {
    match v.as_str().map(|s| (s, PortRef::parse(s))) {
        Some((_, Some(p))) => Some(p),
        Some((s, None)) => {
            errs.push(GraphError::new(format!("\"{s}\" is not of the form \"node.port\"")).at(v.pos));
            None
        }
        None => {
            errs.push(GraphError::new(format!("expected \"node.port\", found {}", v.what())).at(v.pos));
            None
        }
    }
}

fn read_edges(v: &Ron, g: &mut Graph, errs: &mut Vec<GraphError>) {
    let RonKind::List(items) = &v.kind else {
        errs.push(GraphError::new(format!("`edges` must be a list [ (\"a.out\", \"b.in\"), … ], found {}", v.what())).at(v.pos));
        return;
    };
    for e in items {
        match &e.kind {
            RonKind::Tuple(None, pair) if pair.len() == 2 => {
                if let (Some(from), Some(to)) = (port_ref(&pair[0], errs), port_ref(&pair[1], errs)) {
                    g.edges.push(Edge { from, to, pos: e.pos });
                }
            }
            _ => errs.push(GraphError::new(format!("an edge is (\"from.port\", \"to.port\"), found {}", e.what())).at(e.pos)),
        }
    }
}

fn read_outputs(v: &Ron, g: &mut Graph, errs: &mut Vec<GraphError>) {
    for (k, target) in map_entries(v, "outputs", errs) {
        let Some(name) = key_str(k, "output name", errs) else { continue };
        if g.outputs.iter().any(|o| o.name == name) {
            errs.push(GraphError::new(format!("output \"{name}\" named twice")).at(k.pos));
            continue;
        }
        if let Some(port) = port_ref(target, errs) {
            g.outputs.push(Output { name: name.to_string(), port, pos: k.pos });
        }
    }
}

fn read_editor(v: &Ron, g: &mut Graph, errs: &mut Vec<GraphError>) {
    let Some(fields) = v.fields() else {
        errs.push(GraphError::new(format!("`editor` must be `(positions: {{…}})`, found {}", v.what())).at(v.pos));
        return;
    };
    let mut ed = EditorSection::default();
    for f in fields {
        if f.name != "positions" {
            errs.push(GraphError::new(format!("unknown field `{}` in `editor` (it has: positions)", f.name)).at(f.pos));
            continue;
        }
        for (k, p) in map_entries(&f.value, "positions", errs) {
            let Some(id) = key_str(k, "node id", errs) else { continue };
            match &p.kind {
                RonKind::Tuple(None, xy) if xy.len() == 2 && xy.iter().all(|c| c.as_f64().is_some_and(f64::is_finite)) => {
                    ed.positions.push((id.to_string(), [xy[0].as_f64().unwrap(), xy[1].as_f64().unwrap()]));
                }
                _ => errs.push(GraphError::new(format!("a position is (x, y), found {}", p.what())).at(p.pos).node(id)),
            }
        }
    }
    g.editor = ed;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Graph files are parsed by a recursive parser: 200,000 nested brackets overflowed its
    /// stack and aborted the process instead of giving an error with a position.
    #[test]
    fn a_deeply_nested_graph_is_an_error_with_its_position() {
        let text = format!("Graph(version: 1, nodes: {{\n\"a\": (kind: \"TestPattern\", params: (size: {}))}})", "[".repeat(200_000));
        let e = Graph::parse(&text, Some(Path::new("deep.ron"))).unwrap_err().to_string();
        assert!(e.contains("deep.ron:2:") && e.contains("nest more than 128 levels"), "{e}");
    }

    fn chain(n: usize) -> String {
        let nodes: String = (0..n).map(|i| format!("\"n{i}\": (kind: \"K\", params: ()),\n")).collect();
        let edges: String = (1..n).map(|i| format!("(\"n{}.out\", \"n{i}.in\"),\n", i - 1)).collect();
        format!("Graph(version: 1, nodes: {{\n{nodes}}}, edges: [\n{edges}])")
    }

    #[test]
    fn a_byte_order_mark_at_the_start_is_not_part_of_the_graph() {
        let g = Graph::parse("\u{feff}Graph(version: 1, nodes: { \"a\": (kind: \"K\") })", None).unwrap();
        assert_eq!(g.nodes.len(), 1);
    }

    /// Loading looked every node up in the list of those read so far, quadratic in their count.
    /// Past `MAX_NODES` a file is refused with the count; below, ids are checked through a set.
    #[test]
    fn a_graph_past_the_node_limit_is_refused_with_its_count_and_ids_stay_unique() {
        let e = Graph::parse(&chain(MAX_NODES + 1), Some(Path::new("huge.ron"))).unwrap_err().to_string();
        assert!(e.contains("huge.ron:1:") && e.contains(&format!("the graph has {} nodes", MAX_NODES + 1)), "{e}");
        assert!(e.contains(&format!("at most {MAX_NODES}")), "{e}");
        let g = Graph::parse(&chain(20_000), None).unwrap();
        assert_eq!((g.nodes.len(), g.edges.len()), (20_000, 19_999));
        assert_eq!(g.index()["n19999"], 19_999);
        let twice = Graph::parse("Graph(version: 1, nodes: { \"a\": (kind: \"K\"), \"b\": (), \"a\": (kind: \"K\") })", None).unwrap_err();
        let msgs: Vec<String> = twice.0.iter().map(|e| e.to_string()).collect();
        assert!(msgs.iter().any(|m| m.contains("node id used twice") && m.contains("\"a\"")), "{msgs:?}");
        assert!(msgs.iter().any(|m| m.contains("the node has no `kind`") && m.contains("\"b\"")), "{msgs:?}");
    }
}
