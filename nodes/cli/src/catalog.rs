//! `relume nodes`: the catalogue of node kinds, ports and parameter schemas, as text or (with
//! `--markdown`) as one Markdown page (`catalog_markdown`).

use crate::catalog_markdown;
use crate::error::CliError;
use relume_core::{DynNode, Registry};

pub(crate) fn print(reg: &Registry, kind: Option<&str>, markdown: bool) -> Result<(), CliError> {
    let nodes: Vec<&dyn DynNode> = reg.nodes().map(|n| n.as_ref()).filter(|n| kind.is_none_or(|k| n.kind() == k)).collect();
    if nodes.is_empty() {
        let k = kind.unwrap_or_default();
        let hint = reg.suggest(k).map(|s| format!(" (did you mean \"{s}\"?)")).unwrap_or_default();
        return Err(CliError::graph(format!("no node kind \"{k}\"{hint}; `relume nodes` lists them all")));
    }
    if markdown {
        say_part!("{}", catalog_markdown::page(&nodes));
        return Ok(());
    }
    for n in nodes {
        say_part!("{}", describe(n));
    }
    Ok(())
}

/// A node kind as text: header, doc, ports, parameters and the metrics it reports.
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
        let test = p.test.as_ref().map(|t| format!(" (test size: {})", t.to_text())).unwrap_or_default();
        s.push_str(&format!("  param {}: {}{default}{range}{unit}{test} — {}\n", p.name, p.kind.type_name(), p.help));
    }
    if !n.metrics().is_empty() {
        s.push_str(&format!("  metrics: {}\n", n.metrics().join(", ")));
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_kind_gets_the_closest_name() {
        let e = print(&crate::registry(), Some("Tonemapp"), false).err().unwrap();
        assert!(e.msg.contains("no node kind \"Tonemapp\" (did you mean \"Tonemap\"?)"), "{}", e.msg);
    }

    #[test]
    fn the_entry_lists_ports_test_sizes_and_metrics() {
        let reg = crate::registry();
        let error = describe(reg.node("ImageError").unwrap().as_ref());
        assert!(error.contains("  in  image: Image\n  in  reference: Image\n  out metrics: Metrics\n  out error_map: Image\n"), "{error}");
        assert!(error.contains("  metrics: mse, rel_mse, psnr_db, l2_percent, flip, ssim, nonfinite_pixels\n"), "{error}");
        let scene = describe(reg.node("LoadScene").unwrap().as_ref());
        assert!(scene.contains("param width: int = 0 [0, 16384] px (test size: 24)"), "{scene}");
        assert!(!scene.contains("  metrics: \n"), "{scene}");
        // A flattened group's parameters are the node's own, in place.
        let pre = describe(reg.node("TransferPrecompute").unwrap().as_ref());
        let names: Vec<&str> = pre.lines().filter_map(|l| l.strip_prefix("  param ")).map(|l| l.split(':').next().unwrap()).collect();
        assert_eq!(names, ["spp", "light_samples", "bounce_rays", "bounce_light_samples", "seed"]);
    }
}
