//! `relume nodes`: the catalogue of node kinds, ports and parameter schemas.

use crate::error::CliError;
use relume_core::{DynNode, Registry};

pub(crate) fn print(reg: &Registry, kind: Option<&str>) -> Result<(), CliError> {
    let nodes: Vec<_> = reg.nodes().filter(|n| kind.is_none_or(|k| n.kind() == k)).collect();
    if nodes.is_empty() {
        return Err(CliError::graph(format!("no node kind \"{}\"", kind.unwrap_or_default())));
    }
    for n in nodes {
        print!("{}", describe(n.as_ref()));
    }
    Ok(())
}

/// A node kind as text: header, doc, ports and parameters.
pub fn describe(n: &dyn DynNode) -> String {
    let mut s = format!("{} v{} [{}]\n", n.kind(), n.version(), n.category());
    for line in n.doc().lines() {
        s.push_str(&format!("    {line}\n"));
    }
    for (dir, ports) in [("in ", &n.ports().inputs), ("out", &n.ports().outputs)] {
        for p in ports.iter() {
            s.push_str(&format!("  {dir} {}: {}\n", p.name, p.ty.name));
        }
    }
    for p in &n.schema().0 {
        let default = p.default.as_ref().map(|d| format!(" = {}", d.to_text())).unwrap_or_else(|| " (required)".into());
        let range = p.kind.range_text();
        let range = if range.is_empty() { String::new() } else { format!(" {range}") };
        let unit = if p.unit.is_empty() { String::new() } else { format!(" {}", p.unit) };
        s.push_str(&format!("  param {}: {}{default}{range}{unit} — {}\n", p.name, p.kind.type_name(), p.help));
    }
    if let Some(sh) = n.sharded() {
        s.push_str(&format!(
            "  sharded: chunks of its items become {} cache entries (relume shard, relume slurm, relume run --processes/--workers)\n",
            sh.partial_decl().ty.name
        ));
    }
    s.push('\n');
    s
}
