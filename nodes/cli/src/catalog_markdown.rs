//! `relume nodes --markdown`: the catalogue as one Markdown page, committed as
//! docs/reference/nodes.md (CI compares the two).

use relume_core::{DynNode, ParamKind};
use std::collections::BTreeMap;

/// The page's title; the page starts with it (`# {TITLE}`).
const TITLE: &str = "Node catalogue";

/// The page: title, what made it, contents by category (sorted), then a `## Kind` section per
/// kind in the contents' order. `nodes` come in registry order (by kind), which each category keeps.
pub(crate) fn page(nodes: &[&dyn DynNode]) -> String {
    let mut by_category: BTreeMap<&str, Vec<&dyn DynNode>> = BTreeMap::new();
    for &n in nodes {
        by_category.entry(n.category()).or_default().push(n);
    }
    let mut blocks = vec![
        format!("# {TITLE}"),
        "Generated from the node registry by `relume nodes --markdown`; do not edit it by hand. \
         After changing a node, regenerate it with \
         `cargo build --release --bin relume && target/release/relume nodes --markdown > docs/reference/nodes.md`. \
         `relume nodes KIND` prints one kind as text."
            .to_string(),
        "## Contents".to_string(),
    ];
    for (category, kinds) in &by_category {
        blocks.push(format!("**{category}**"));
        blocks.push(kinds.iter().map(|n| format!("- [{}](#{})", n.kind(), anchor(n.kind()))).collect::<Vec<_>>().join("\n"));
    }
    for n in by_category.values().flatten() {
        blocks.extend(section(*n));
    }
    blocks.join("\n\n") + "\n"
}

/// One kind's section, as blocks: heading, version and category, doc, ports, parameters,
/// metrics and the shard contract.
fn section(n: &dyn DynNode) -> Vec<String> {
    let mut blocks = vec![format!("## {}", n.kind()), format!("Version {} · category `{}`", n.version(), n.category())];
    if !n.doc().is_empty() {
        blocks.push(n.doc().to_string());
    }
    let ports = n.ports();
    let dirs = ports.inputs.iter().map(|p| ("in", p)).chain(ports.outputs.iter().map(|p| ("out", p)));
    let rows: Vec<Vec<String>> = dirs.map(|(dir, p)| vec![dir.to_string(), code(p.name), code(p.ty.name)]).collect();
    blocks.push(table("Ports", &["Direction", "Name", "Type"], &rows));
    let rows: Vec<Vec<String>> = n
        .schema()
        .0
        .iter()
        .map(|p| {
            let range = match &p.kind {
                ParamKind::Enum(choices) => choices.iter().map(|c| code(c)).collect::<Vec<_>>().join(", "),
                kind => code(&kind.range_text()),
            };
            let default = p.default.as_ref().map_or_else(|| "required".to_string(), |d| code(&d.to_text()));
            let test = p.test.as_ref().map(|t| code(&t.to_text())).unwrap_or_default();
            vec![code(p.name), p.kind.type_name().to_string(), default, range, p.unit.to_string(), test, p.help.to_string()]
        })
        .collect();
    blocks.push(table("Parameters", &["Name", "Type", "Default", "Range / choices", "Unit", "Test size", "Help"], &rows));
    if !n.metrics().is_empty() {
        blocks.push(format!("**Metrics** it may record: {}.", n.metrics().iter().map(|m| code(m)).collect::<Vec<_>>().join(", ")));
    }
    if let Some(sh) = n.sharded() {
        blocks.push(format!(
            "**Sharded:** chunks of its items become {} cache entries \
             (`relume shard`, `relume slurm`, `relume run --processes/--workers`).",
            code(sh.partial_decl().ty.name)
        ));
    }
    blocks
}

/// A bold caption and a table, or the caption's "none" when there are no rows.
fn table(caption: &str, header: &[&str], rows: &[Vec<String>]) -> String {
    if rows.is_empty() {
        return format!("**{caption}:** none.");
    }
    let line = |cells: &mut dyn Iterator<Item = String>| format!("| {} |", cells.collect::<Vec<_>>().join(" | "));
    let mut lines =
        vec![format!("**{caption}**\n"), line(&mut header.iter().map(|h| h.to_string())), line(&mut header.iter().map(|_| "---".into()))];
    lines.extend(rows.iter().map(|r| line(&mut r.iter().map(|c| cell(c)))));
    lines.join("\n")
}

/// Text as one table cell: `|` escaped (also inside code spans, as GitHub's tables want), on one line.
fn cell(s: &str) -> String {
    s.replace('|', "\\|").replace('\n', " ")
}

/// Text as a code span (empty stays empty).
fn code(s: &str) -> String {
    match s {
        "" => String::new(),
        s if s.contains('`') => format!("`` {s} ``"),
        s => format!("`{s}`"),
    }
}

/// The anchor GitHub and mdBook give a heading: lower case, spaces as `-`, other punctuation
/// dropped (`## PathTrace` is `#pathtrace`).
pub(crate) fn anchor(heading: &str) -> String {
    let kept = heading.chars().filter(|c| c.is_alphanumeric() || matches!(c, ' ' | '-' | '_'));
    kept.map(|c| if c == ' ' { '-' } else { c }).flat_map(char::to_lowercase).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn page_of(kinds: &[&str]) -> String {
        let reg = crate::registry();
        page(&kinds.iter().map(|k| reg.node(k).unwrap().as_ref()).collect::<Vec<_>>())
    }

    #[test]
    fn a_section_has_its_heading_tables_and_metrics_and_the_contents_link_to_it() {
        let md = page_of(&["GaussianBlur", "PathTrace"]);
        assert!(md.starts_with("# Node catalogue\n\nGenerated from the node registry by `relume nodes --markdown`"), "{md}");
        assert!(md.contains("**image**\n\n- [GaussianBlur](#gaussianblur)\n\n**reference**\n\n- [PathTrace](#pathtrace)\n"), "{md}");
        assert!(md.contains("## PathTrace\n\nVersion 2 · category `reference`\n\nReference path tracer"), "{md}");
        assert!(md.contains("| in | `scene` | `Scene` |\n| in | `accel` | `Accel` |\n| out | `image` | `Image` |\n"), "{md}");
        assert!(md.contains("| `spp` | int | `16` | `[1, 1048576]` | samples/pixel | `4` | samples per pixel |\n"), "{md}");
        assert!(md.contains("**Metrics** it may record: `spp`, `rays`, `nonfinite_samples`.\n"), "{md}");
        assert!(md.contains("**Sharded:** chunks of its items become `ImageRows` cache entries"), "{md}");
        assert!(md.ends_with(" |\n") || md.ends_with(".\n"), "one line break at the end: {md:?}");
        assert!(!md.contains("\n\n\n"), "{md}");
    }

    #[test]
    fn enum_choices_are_listed_and_pipes_in_cells_are_escaped() {
        let md = page_of(&["BrdfPca"]);
        assert!(md.contains("| `weighting` | enum | `Uniform` | `SolidAngle`, `Uniform` |  |  | how grid cells count"), "{md}");
        assert_eq!(cell("|v| = n"), "\\|v\\| = n");
        assert_eq!(code("a`b"), "`` a`b ``");
        assert_eq!(anchor("PathTrace"), "pathtrace");
        assert_eq!(anchor("Node catalogue"), "node-catalogue");
    }
}
