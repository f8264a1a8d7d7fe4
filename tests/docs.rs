//! The documentation stays true to the tree: the book's node example is a real node file,
//! quoted whole; every link of the README and the book resolves, anchors included; the book
//! lists every page it holds; and no document or source file points outside the repository.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn the_book_quotes_a_real_node_file_whole() {
    let page = std::fs::read_to_string(root().join("docs/guide/writing-a-node.md")).unwrap();
    let node = std::fs::read_to_string(root().join("nodes/base/src/image/combine.rs")).unwrap();
    assert!(node.contains("#[node("), "the quoted file is a node");
    assert!(page.contains(&format!("```rust\n{node}```")), "docs/guide/writing-a-node.md must quote nodes/base/src/image/combine.rs whole");
}

/// Every text file the repository tracks, by extension.
fn files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if p.is_dir() {
            if !name.starts_with('.') && name != "target" && name != "corpus" {
                files(&p, out);
            }
        } else if ["rs", "md", "ron", "toml", "py", "sh"].iter().any(|x| name.ends_with(&format!(".{x}"))) {
            out.push(p);
        }
    }
}

#[test]
fn nothing_points_outside_the_repository() {
    let mut all = Vec::new();
    files(&root(), &mut all);
    assert!(all.len() > 100, "found {} files", all.len());
    // Built from parts, so that this file does not hold what it looks for.
    let outside = [["..", "/shared"].concat(), ["shared", "/spec"].concat(), ["shared", "/seeds"].concat()];
    let bad: Vec<String> = all
        .iter()
        .filter(|p| std::fs::read_to_string(p).is_ok_and(|t| outside.iter().any(|o| t.contains(o.as_str()))))
        .map(|p| p.strip_prefix(root()).unwrap_or(p).display().to_string())
        .collect();
    assert!(bad.is_empty(), "files that point outside the repository: {bad:?}");
}

/// The heading ids a Markdown page offers to `#anchor` links, as mdBook and GitHub make them:
/// lower case, letters, digits, `-` and `_` kept, spaces to `-`, the rest dropped (a repeated
/// heading gets `-1`, `-2`, …).
fn anchors(text: &str) -> Vec<String> {
    let mut seen: Vec<String> = Vec::new();
    let mut fenced = false;
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
        }
        let Some(title) = line.strip_prefix('#').filter(|_| !fenced).map(|t| t.trim_start_matches('#')) else { continue };
        if !title.starts_with(' ') {
            continue;
        }
        let title = title.trim().replace('`', "");
        let slug: String = title
            .to_lowercase()
            .chars()
            .filter_map(|c| match c {
                ' ' => Some('-'),
                c if c.is_alphanumeric() || c == '-' || c == '_' => Some(c),
                _ => None,
            })
            .collect();
        let n =
            seen.iter().filter(|s| **s == slug || s.strip_prefix(&format!("{slug}-")).is_some_and(|r| r.parse::<u32>().is_ok())).count();
        seen.push(if n == 0 { slug } else { format!("{slug}-{n}") });
    }
    seen
}

/// The link targets of a Markdown page, outside code: `[text](target)`, `![alt](target)` and
/// `[label]: target`, with their line numbers.
fn links(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    let mut fenced = false;
    for (i, line) in text.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced || line.starts_with("    ") && !line.trim_start().starts_with(['-', '*', '|']) {
            continue;
        }
        // Inline code holds no links: drop what lies between backticks.
        let plain: String = line.split('`').step_by(2).collect::<Vec<_>>().join(" ");
        let mut rest = plain.as_str();
        while let Some(at) = rest.find("](") {
            let tail = &rest[at + 2..];
            let end = tail.find(')').unwrap_or(tail.len());
            out.push((i + 1, tail[..end].split_whitespace().next().unwrap_or("").to_string()));
            rest = &tail[end..];
        }
        if let Some(def) = plain.trim_start().strip_prefix('[').and_then(|l| l.split_once("]: ")) {
            out.push((i + 1, def.1.split_whitespace().next().unwrap_or("").to_string()));
        }
    }
    out
}

/// The files a page includes with mdBook's `{{#include path}}`, with their line numbers.
fn includes(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let mut rest = line;
        while let Some(at) = rest.find("{{#include ") {
            let tail = &rest[at + 11..];
            let end = tail.find("}}").unwrap_or(tail.len());
            // `path:anchor` or `path:from:to` name a part of the file.
            out.push((i + 1, tail[..end].trim().split(':').next().unwrap_or("").to_string()));
            rest = &tail[end..];
        }
    }
    out
}

/// `p` with its `..` parts resolved, on the path alone.
fn normalized(p: &Path) -> PathBuf {
    let mut out = PathBuf::new();
    for c in p.components() {
        if c == std::path::Component::ParentDir {
            out.pop();
        } else {
            out.push(c);
        }
    }
    out
}

/// Every Markdown page of the README and the book (`docs/`).
fn pages() -> Vec<PathBuf> {
    let mut all = vec![root().join("README.md")];
    let mut docs = Vec::new();
    files(&root().join("docs"), &mut docs);
    all.extend(docs.into_iter().filter(|p| p.extension().is_some_and(|e| e == "md")));
    all
}

#[test]
fn every_link_in_the_readme_and_the_book_resolves() {
    let mut bad = Vec::new();
    let mut checked = 0;
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        let name = page.strip_prefix(root()).unwrap_or(&page).display().to_string();
        for (line, target) in links(&text) {
            if target.is_empty() || target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            checked += 1;
            let (path, anchor) = target.split_once('#').map_or((target.as_str(), None), |(p, a)| (p, Some(a)));
            let file = if path.is_empty() { page.clone() } else { page.parent().unwrap().join(path) };
            if !file.exists() {
                bad.push(format!("{name}:{line}: {target} (no such file)"));
                continue;
            }
            if let Some(a) = anchor.filter(|_| file.extension().is_some_and(|e| e == "md")) {
                let target_text = std::fs::read_to_string(&file).unwrap_or_default();
                if !anchors(&target_text).iter().any(|h| h == a) {
                    bad.push(format!("{name}:{line}: {target} (no heading with that anchor)"));
                }
            }
        }
    }
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        let name = page.strip_prefix(root()).unwrap_or(&page).display().to_string();
        for (line, target) in includes(&text) {
            checked += 1;
            if !page.parent().unwrap().join(&target).is_file() {
                bad.push(format!("{name}:{line}: {{{{#include {target}}}}} (no such file)"));
            }
        }
    }
    assert!(checked > 20, "only {checked} links found: the scanner is broken");
    assert!(bad.is_empty(), "{} broken links:\n{}", bad.len(), bad.join("\n"));
}

#[test]
fn the_link_scanner_finds_links_and_anchors_as_mdbook_makes_them() {
    let page = "# A `Title`: here\n\nSee [x](a.md#b-c), ![p](../p.png) and `[not](code)`.\n```\n[no](fence)\n```\n[ref]: guide/x.md\n## A Title: here\n";
    let found: Vec<String> = links(page).into_iter().map(|(_, t)| t).collect();
    assert_eq!(found, ["a.md#b-c", "../p.png", "guide/x.md"]);
    let included = includes("text\n{{#include ../results/a.md}}\n{{#include b.rs:anchor}} {{#include c.md}}\n");
    assert_eq!(included, [(2, "../results/a.md".to_string()), (3, "b.rs".to_string()), (3, "c.md".to_string())]);
    assert_eq!(anchors(page), ["a-title-here", "a-title-here-1"]);
}

#[test]
fn the_book_lists_every_page_it_holds() {
    let summary = std::fs::read_to_string(root().join("docs/SUMMARY.md")).unwrap();
    let mut listed: Vec<String> = links(&summary).into_iter().map(|(_, t)| t).collect();
    // A part another page includes is not a page of its own.
    let docs = normalized(&root().join("docs"));
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        for (_, target) in includes(&text) {
            if let Ok(rel) = normalized(&page.parent().unwrap().join(target)).strip_prefix(&docs) {
                listed.push(rel.display().to_string());
            }
        }
    }
    let unlisted: Vec<String> = pages()
        .iter()
        .filter_map(|p| p.strip_prefix(root().join("docs")).ok())
        .map(|p| p.display().to_string())
        .filter(|p| p != "SUMMARY.md" && !listed.contains(p))
        .collect();
    assert!(unlisted.is_empty(), "pages in docs/ that docs/SUMMARY.md does not list (mdBook would not render them): {unlisted:?}");
}

/// The README's fresh-machine timings are the rows of `docs/results/table_fresh_machine.csv`: the
/// sentence is rebuilt from the file and must stand in the README as it is, so a re-measured
/// row fails here until the README quotes it.
#[test]
fn the_readme_quotes_the_measured_fresh_machine_timings() {
    let csv = std::fs::read_to_string(root().join("docs/results/table_fresh_machine.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap_or_else(|| panic!("no `{name}` column"));
    let (step, seconds, detail) = (col("step"), col("seconds"), col("detail"));
    // The `detail` column is last and may hold commas.
    let rows: Vec<Vec<&str>> = lines.map(|l| l.splitn(header.len(), ',').collect()).collect();
    let row = |name: &str| rows.iter().find(|r| r[step] == name).unwrap_or_else(|| panic!("no `{name}` row"));
    let secs = |name: &str| row(name)[seconds].parse::<u64>().unwrap();
    let thousands = |n: u64| if n >= 1000 { format!("{},{:03}", n / 1000, n % 1000) } else { n.to_string() };
    let passed = row("build and tests")[detail].split(" passed").next().unwrap().rsplit(' ').next().unwrap().to_string();
    let build = secs("release build done");
    let sentence = format!(
        "the build took {} s, the picture came {} s after it and the error and report at {} s; the test command, on its own fresh clone, took {} s, {} tests passing",
        thousands(build),
        thousands(secs("out/image.png written") - build),
        thousands(secs("error and report written")),
        thousands(secs("build and tests")),
        passed
    );
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap().split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(readme.contains(&sentence), "the README should say, from table_fresh_machine.csv:\n{sentence}");
}
