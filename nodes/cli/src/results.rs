//! `relume results`: the book's results pages drawn from the committed measurements. A
//! results folder (`docs/results`) holds three kinds of CSV, each row with the date, machine,
//! threads and commit of its measurement: sweeps (`sweep_NAME.csv`, written by `relume
//! sweep`), benchmarks (`bench_NAME.csv`, written by `benches/scripts/record_bench.py` from
//! divan's table) and measurement tables (`table_NAME.csv`, one row a run: editor drives, the
//! Python overhead, fresh clones timed). A measurement table may instead show chosen columns
//! of a sweep's CSV or of a single run's (`run_NAME.csv`: a one-variant `relume sweep`, every
//! node's time, output bytes and metrics). Three manifests, `sweeps.ron`, `benches.ron` and
//! `tables.ron`, list them with the command that measured each. From those alone it writes each
//! sweep's plot (`sweep_NAME.png`), each measurement's section (`sweep_NAME.md`, `bench_NAME.md`,
//! `table_NAME.md`, which the book's pages include) and the overview pages `sweeps.md`,
//! `benches.md` and `tables.md`; `--check` writes nothing and fails when a committed file
//! differs from what it would write, so a figure cannot go stale by hand.

mod grouped;
pub(crate) mod tables;

use crate::error::CliError;
use crate::plot::log_log_png;
use crate::sweep::csv_table::CsvTable;
use clap::Args;
use relume_core::ron::fields::{list_of, map_of, str_of, Fields};
use relume_core::ron::parse;
use std::path::{Path, PathBuf};

#[derive(Args)]
pub(crate) struct ResultsArgs {
    /// The results folder (its `sweeps.ron` lists the sweeps it holds).
    #[arg(default_value = "docs/results")]
    dir: PathBuf,
    /// Write nothing; exit with 1 when a generated file differs from the one in the folder.
    #[arg(long)]
    check: bool,
}

/// One measurement a manifest lists: a sweep (`sweeps.ron`) or a benchmark (`benches.ron`).
struct Entry {
    name: String,
    caption: String,
    command: String,
    /// A benchmark's case the others are divided by (a ratio of medians measured in one run).
    against: Option<String>,
    /// A sweep's row that stands for it in its page's summary (`headlines_PAGE.md`): the page
    /// and the row's variant.
    headline: Option<(String, String)>,
    /// A measurement table's columns that name a row of the generated table (its runs are
    /// the CSV rows that agree on them).
    group: Vec<String>,
    /// A measurement table's value columns and their headings, shown as ranges over the runs.
    columns: Vec<(String, String)>,
    /// A benchmark's figures from elsewhere (a thesis' table) shown beside its cases: the
    /// column's heading, and each case's figure.
    compare: Option<(String, Vec<(String, String)>)>,
    /// A measurement table's CSVs when not its own `table_NAME.csv`: sweeps' or runs'
    /// (`run_NAME.csv`, a one-variant sweep), in the same folder; several are read as one, each
    /// row with its file's name in a `source` column.
    sources: Vec<String>,
    /// A measurement table's rows kept from its CSV: those with this text in this column.
    filter: Vec<(String, String)>,
    /// A measurement table's rows named by hand, each a label, the CSV rows it draws from
    /// (those matching its filter; every row without one) and the CSV columns of its cells,
    /// under `headings`.
    rows: Vec<grouped::NamedRow>,
    headings: Vec<String>,
}

/// The three kinds of results file: their manifest, its root struct and list, the files' prefix,
/// and the fields an entry may have.
struct Kind {
    manifest: &'static str,
    root: &'static str,
    list: &'static str,
    prefix: &'static str,
    fields: &'static [&'static str],
}

const SWEEPS: Kind = Kind {
    manifest: "sweeps.ron",
    root: "SweepResults",
    list: "sweeps",
    prefix: "sweep_",
    fields: &["name", "caption", "command", "page", "headline"],
};
const BENCHES: Kind = Kind {
    manifest: "benches.ron",
    root: "BenchResults",
    list: "benches",
    prefix: "bench_",
    fields: &["name", "caption", "command", "against", "compare", "compare_heading"],
};

/// Measurements made by scripts or by hand-run drives (the editor's, the Python package's),
/// each row one run: `table_NAME.csv` with the provenance columns, shown grouped.
const TABLES: Kind = Kind {
    manifest: "tables.ron",
    root: "TableResults",
    list: "tables",
    prefix: "table_",
    fields: &["name", "caption", "command", "group", "columns", "source", "filter", "rows", "headings"],
};

/// A single run's every node time, bytes and metric (`run_NAME.csv`, written as a one-variant
/// sweep): listed by the measurement tables that draw from it (their `source`).
const RUN_PREFIX: &str = "run_";

/// An optional text field of a manifest entry.
fn optional_in(f: &mut Fields, name: &str) -> Result<Option<String>, relume_core::ron::SyntaxError> {
    f.opt(name).map(|v| str_of(v, name).map(str::to_string)).transpose()
}

/// The entries of the folder's manifest of `kind`; none where the folder has no such manifest
/// (then it may hold no CSV of that kind either).
fn load_manifest(dir: &Path, kind: &Kind) -> Result<Vec<Entry>, CliError> {
    let path = dir.join(kind.manifest);
    if !path.exists() && dir.is_dir() {
        return Ok(Vec::new());
    }
    let text = std::fs::read_to_string(&path).map_err(|e| CliError::graph(format!("cannot read {}: {e}", path.display())))?;
    let at = |e: relume_core::ron::SyntaxError| CliError::graph(format!("{}:{e}", path.display()));
    let doc = parse(&text).map_err(at)?;
    let mut f = Fields::new(&doc, kind.root).map_err(at)?;
    let list = list_of(f.req(kind.list).map_err(at)?, kind.list).map_err(at)?;
    f.finish(&[kind.list]).map_err(at)?;
    let mut out: Vec<Entry> = Vec::new();
    for item in list {
        let mut f = Fields::new(item, "an entry").map_err(at)?;
        let mut text = |name: &str| f.req(name).and_then(|v| str_of(v, name)).map(str::to_string).map_err(at);
        let (name, caption, command) = (text("name")?, text("caption")?, text("command")?);
        let has = |field: &str| kind.fields.contains(&field);
        let against = if has("against") { optional_in(&mut f, "against").map_err(at)? } else { None };
        let headline = match if has("page") { (optional_in(&mut f, "page").map_err(at)?, optional_in(&mut f, "headline").map_err(at)?) } else { (None, None) } {
            (Some(page), Some(row)) => Some((page, row)),
            (None, None) => None,
            _ => {
                return Err(CliError::graph(format!(
                    "{}: `{name}` needs both `page` and `headline` (the page's summary and the row that stands for the sweep in it), or neither",
                    path.display()
                )))
            }
        };
        let group = match f.opt("group").filter(|_| has("group")) {
            Some(v) => list_of(v, "group")
                .map_err(at)?
                .iter()
                .map(|c| str_of(c, "a group column").map(str::to_string))
                .collect::<Result<_, _>>()
                .map_err(at)?,
            None => Vec::new(),
        };
        let text_map = |v: Option<&relume_core::ron::Ron>, what: &str| match v {
            Some(v) => map_of(v, what)
                .and_then(|m| m.into_iter().map(|(k, _, h)| Ok((k.to_string(), str_of(h, k)?.to_string()))).collect())
                .map_err(at),
            None => Ok(Vec::new()),
        };
        let columns: Vec<(String, String)> = text_map(f.opt("columns").filter(|_| has("columns")), "columns")?;
        let filter = text_map(f.opt("filter").filter(|_| has("filter")), "filter")?;
        let sources: Vec<String> = match f.opt("source").filter(|_| has("source")) {
            None => Vec::new(),
            Some(v) if matches!(v.kind, relume_core::ron::RonKind::List(_)) => list_of(v, "source")
                .map_err(at)?
                .iter()
                .map(|c| str_of(c, "a source").map(str::to_string).map_err(at))
                .collect::<Result<_, _>>()?,
            Some(v) => vec![str_of(v, "source").map_err(at)?.to_string()],
        };
        if let Some(src) = sources.iter().find(|src| src.contains('/') || !src.ends_with(".csv")) {
            return Err(CliError::graph(format!("{}: `{name}`: source `{src}` must be a CSV file's name in the folder", path.display())));
        }
        let strings = |v: &relume_core::ron::Ron, what: &str| -> Result<Vec<String>, CliError> {
            list_of(v, what).map_err(at)?.iter().map(|c| str_of(c, what).map(str::to_string).map_err(at)).collect()
        };
        let headings = match f.opt("headings").filter(|_| has("headings")) {
            Some(v) => strings(v, "headings")?,
            None => Vec::new(),
        };
        let mut rows: Vec<grouped::NamedRow> = Vec::new();
        if let Some(v) = f.opt("rows").filter(|_| has("rows")) {
            for row in list_of(v, "rows").map_err(at)? {
                let bad = || {
                    CliError::graph(format!(
                        "{}: `{name}`: each of `rows` is (\"label\", [\"csv_column\", …]) or (\"label\", {{\"column\": \"text\"}}, [\"csv_column\", …])",
                        path.display()
                    ))
                };
                let relume_core::ron::RonKind::Tuple(None, parts) = &row.kind else { return Err(bad()) };
                let (label, filter, cells) = match parts.as_slice() {
                    [label, cells] => (label, Vec::new(), cells),
                    [label, filter, cells] => (label, text_map(Some(filter), "a row's filter")?, cells),
                    _ => return Err(bad()),
                };
                let label = str_of(label, "a row's label").map_err(at)?.to_string();
                rows.push(grouped::NamedRow { label, filter, cells: strings(cells, "a row's columns")? });
            }
        }
        if !rows.is_empty() && (!group.is_empty() || !columns.is_empty()) {
            return Err(CliError::graph(format!(
                "{}: `{name}`: give either `rows` and `headings` or `group` and `columns`, not both",
                path.display()
            )));
        }
        if rows.iter().any(|r| r.cells.len() + 1 != headings.len()) {
            return Err(CliError::graph(format!(
                "{}: `{name}`: `headings` has {} entries; each row needs one cell fewer (its label comes first)",
                path.display(),
                headings.len()
            )));
        }
        let compare = text_map(f.opt("compare").filter(|_| has("compare")), "compare")?;
        let compare =
            match (compare.is_empty(), if has("compare_heading") { optional_in(&mut f, "compare_heading").map_err(at)? } else { None }) {
                (true, None) => None,
                (false, Some(heading)) => Some((heading, compare)),
                _ => {
                    return Err(CliError::graph(format!(
                        "{}: `{name}` needs both `compare` (case: figure) and `compare_heading` (whose figures they are), or neither",
                        path.display()
                    )))
                }
            };
        if has("columns") && columns.is_empty() && rows.is_empty() {
            return Err(CliError::graph(format!(
                "{}: `{name}` shows no columns (`columns: {{\"csv_column\": \"heading\", …}}`, or `rows` and `headings`)",
                path.display()
            )));
        }
        f.finish(kind.fields).map_err(at)?;
        if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(CliError::graph(format!("{}: the name `{name}` must be letters, digits and _", path.display())));
        }
        if out.iter().any(|o| o.name == name) {
            return Err(CliError::graph(format!("{}: `{name}` is listed twice", path.display())));
        }
        out.push(Entry { name, caption, command, against, headline, group, columns, compare, sources, filter, rows, headings });
    }
    Ok(out)
}

const GENERATED: &str =
    "<!-- Generated by `relume results` from the CSV files and the manifest beside it: edit those, not this page. -->\n\n";

/// Every file the folder's sweeps give, with its bytes.
fn sweep_files(dir: &Path, sweeps: &[Entry]) -> Result<Vec<(PathBuf, Vec<u8>)>, CliError> {
    let mut files = Vec::new();
    let mut overview = format!(
        "{GENERATED}# Results: sweeps\n\n\
         Every sweep the book quotes, drawn from its CSV in `docs/results/` by `relume results`\n\
         (the pipeline pages include the same sections). Each was measured by the command shown,\n\
         from the repository's root; the CSV holds every node's time and metric for every variant,\n\
         and the date, machine, threads and commit of the measurement. The time axis is the compute\n\
         time of the pipeline that made the image, the reference excluded, unless the table says\n\
         otherwise.\n"
    );
    // Per page, the headline rows of its sweeps, in the manifest's order.
    let mut headlines: Vec<(String, Vec<Vec<String>>)> = Vec::new();
    for s in sweeps {
        let (csv, table) = read_csv(dir, &SWEEPS, &s.name)?;
        let fail = |e: String| CliError::run(format!("{}: {e}", csv.display()));
        let plotted = crate::sweep::replay(&s.command, &table).map_err(fail)?;
        let (png, _) = log_log_png(&plotted.axes(), &plotted.curves(&table)).map_err(fail)?;
        let body = tables::section(&s.name, &s.command, &plotted, &table).map_err(fail)?;
        files.push((dir.join(format!("sweep_{}.png", s.name)), png));
        files.push(section_file(dir, &SWEEPS, s, &body));
        overview += &format!("\n## {}\n\n{body}", s.caption);
        if let Some((page, variant)) = &s.headline {
            let cells = tables::headline(&plotted, &table, variant).map_err(fail)?;
            let row = [vec![s.caption.clone(), format!("`{variant}`")], cells.to_vec()].concat();
            match headlines.iter_mut().find(|(p, _)| p == page) {
                Some((_, rows)) => rows.push(row),
                None => headlines.push((page.clone(), vec![row])),
            }
        }
    }
    files.push((dir.join("sweeps.md"), overview.into_bytes()));
    for (page, rows) in headlines {
        let mut text = format!(
            "<!-- Generated by `relume results` from the sweeps that sweeps.ron gives a headline on page \"{page}\": edit those, not this file. -->\n\n"
        );
        text += &tables::headline_table(&rows);
        files.push((dir.join(format!("headlines_{page}.md")), text.into_bytes()));
    }
    Ok(files)
}

/// Every file the folder's benchmarks give, with its bytes.
fn bench_files(dir: &Path, benches: &[Entry]) -> Result<Vec<(PathBuf, Vec<u8>)>, CliError> {
    let mut files = Vec::new();
    let mut overview = format!(
        "{GENERATED}# Results: benchmarks\n\n\
         The benchmark figures the book quotes, each a divan benchmark measured by the command\n\
         shown (from the repository's root; `benches/scripts/record_bench.py` runs `cargo bench`\n\
         and keeps divan's table with the date, machine, threads and commit in\n\
         `docs/results/bench_NAME.csv`). Ratios are of medians measured in the same run.\n"
    );
    for b in benches {
        let (csv, table) = read_csv(dir, &BENCHES, &b.name)?;
        let compare = b.compare.as_ref().map(|(h, c)| (h.as_str(), c.as_slice()));
        let mut body = tables::bench_section(&b.name, &b.command, b.against.as_deref(), compare, &table)
            .map_err(|e| CliError::run(format!("{}: {e}", csv.display())))?;
        // What the benchmark printed itself in the same run, kept beside its CSV.
        let notes = dir.join(format!("bench_{}.txt", b.name));
        if let Ok(text) = std::fs::read_to_string(&notes) {
            body += &format!("\nPrinted by the benchmark in the same run:\n\n```text\n{}\n```\n", text.trim_end());
        }
        files.push(section_file(dir, &BENCHES, b, &body));
        overview += &format!("\n## {}\n\n{body}", b.caption);
    }
    files.push((dir.join("benches.md"), overview.into_bytes()));
    Ok(files)
}

/// Every file the folder's measurement tables give, with its bytes.
fn table_files(dir: &Path, tables: &[Entry]) -> Result<Vec<(PathBuf, Vec<u8>)>, CliError> {
    let mut files = Vec::new();
    let mut overview = format!(
        "{GENERATED}# Results: tables\n\n\
         Measurements made outside `relume sweep` and the benchmarks (drives of the editor in a\n\
         window, the Python package's overhead, fresh clones timed: each CSV row one run, with\n\
         the date, machine, threads and commit; a table row gathers the runs that agree on its\n\
         first columns and shows each figure's range over them), and the figures the pipeline\n\
         pages quote from sweeps and from single runs (`run_NAME.csv`: a one-variant\n\
         `relume sweep` with every node's time, output bytes and metrics), chosen by column.\n"
    );
    for e in tables {
        let own = [format!("{}{}.csv", TABLES.prefix, e.name)];
        let names: &[String] = if e.sources.is_empty() { &own } else { &e.sources };
        let mut parts = Vec::new();
        for n in names {
            parts.push((n.as_str(), read_named_csv(dir, n)?.1));
        }
        let table = if parts.len() == 1 { parts.pop().unwrap().1 } else { CsvTable::joined(&parts) };
        let csv = dir.join(&names[0]);
        let spec = grouped::TableSpec {
            command: &e.command,
            csvs: names,
            filter: &e.filter,
            group: &e.group,
            columns: &e.columns,
            rows: &e.rows,
            headings: &e.headings,
            formatted: !e.sources.is_empty(),
        };
        let body = grouped::section(&spec, &table).map_err(|m| CliError::run(format!("{}: `{}`: {m}", csv.display(), e.name)))?;
        files.push(section_file(dir, &TABLES, e, &body));
        overview += &format!("\n## {}\n\n{body}", e.caption);
    }
    files.push((dir.join("tables.md"), overview.into_bytes()));
    Ok(files)
}

/// `PREFIX_NAME.csv` read and parsed.
fn read_csv(dir: &Path, kind: &Kind, name: &str) -> Result<(PathBuf, CsvTable), CliError> {
    read_named_csv(dir, &format!("{}{name}.csv", kind.prefix))
}

/// The folder's CSV `file` read and parsed.
fn read_named_csv(dir: &Path, file: &str) -> Result<(PathBuf, CsvTable), CliError> {
    let csv = dir.join(file);
    let fail = |e: String| CliError::run(format!("{}: {e}", csv.display()));
    let text = std::fs::read_to_string(&csv).map_err(|e| fail(format!("cannot read it: {e}")))?;
    let table = CsvTable::parse(&text).map_err(fail)?;
    Ok((csv, table))
}

/// The section a page includes: a comment, the caption, the body.
fn section_file(dir: &Path, kind: &Kind, e: &Entry, body: &str) -> (PathBuf, Vec<u8>) {
    let csvs = if e.sources.is_empty() { format!("{}{}.csv", kind.prefix, e.name) } else { e.sources.join(", ") };
    let text = format!(
        "<!-- Generated by `relume results` from {csvs} and {m}: edit those, not this file. -->\n\n**{c}.** {body}",
        m = kind.manifest,
        c = e.caption
    );
    (dir.join(format!("{}{}.md", kind.prefix, e.name)), text.into_bytes())
}

/// The CSV files in the folder whose names start with `prefix` and that `listed` does not
/// name.
fn unlisted_csvs(dir: &Path, prefix: &str, listed: impl Fn(&str) -> bool) -> Result<Vec<String>, CliError> {
    let files = std::fs::read_dir(dir).map_err(|e| CliError::graph(format!("cannot list {}: {e}", dir.display())))?;
    let mut out: Vec<String> = files
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with(prefix) && n.ends_with(".csv") && !listed(n))
        .collect();
    out.sort();
    Ok(out)
}

/// The CSV files in the folder that their manifest does not list.
fn unlisted(dir: &Path, kind: &Kind, entries: &[Entry]) -> Result<Vec<String>, CliError> {
    unlisted_csvs(dir, kind.prefix, |n| entries.iter().any(|e| n == format!("{}{}.csv", kind.prefix, e.name)))
}

/// The run CSVs (`run_NAME.csv`) in the folder that no measurement table names as its source.
fn unlisted_runs(dir: &Path, tables: &[Entry]) -> Result<Vec<String>, CliError> {
    unlisted_csvs(dir, RUN_PREFIX, |n| tables.iter().any(|t| t.sources.iter().any(|s| s == n)))
}

pub(crate) fn results(a: &ResultsArgs) -> Result<(), CliError> {
    let (sweeps, benches, tables) = (load_manifest(&a.dir, &SWEEPS)?, load_manifest(&a.dir, &BENCHES)?, load_manifest(&a.dir, &TABLES)?);
    for (kind, entries) in [(&SWEEPS, &sweeps), (&BENCHES, &benches), (&TABLES, &tables)] {
        let stray = unlisted(&a.dir, kind, entries)?;
        if !stray.is_empty() {
            return Err(CliError::graph(format!("{}: CSV files {} does not list: {}", a.dir.display(), kind.manifest, stray.join(", "))));
        }
    }
    let runs = unlisted_runs(&a.dir, &tables)?;
    if !runs.is_empty() {
        return Err(CliError::graph(format!("{}: run CSV files no table of tables.ron draws from: {}", a.dir.display(), runs.join(", "))));
    }
    let mut files = sweep_files(&a.dir, &sweeps)?;
    files.extend(bench_files(&a.dir, &benches)?);
    files.extend(table_files(&a.dir, &tables)?);
    let stale: Vec<&(PathBuf, Vec<u8>)> = files.iter().filter(|(p, bytes)| std::fs::read(p).ok().as_ref() != Some(bytes)).collect();
    let counted = format!("{} sweeps, {} benchmarks, {} measurement tables", sweeps.len(), benches.len(), tables.len());
    if a.check {
        if stale.is_empty() {
            say!("{} generated files match their {counted}", files.len());
            return Ok(());
        }
        let names: Vec<String> = stale.iter().map(|(p, _)| p.display().to_string()).collect();
        return Err(CliError::run(format!(
            "{} generated file(s) differ from what `relume results {}` writes: {}",
            names.len(),
            a.dir.display(),
            names.join(", ")
        )));
    }
    for (path, bytes) in &stale {
        relume_core::graph::write_atomic(path, bytes).map_err(|e| CliError::run(format!("cannot write {}: {e}", path.display())))?;
        say!("wrote {}", path.display());
    }
    say!("{} of {} generated files changed ({counted})", stale.len(), files.len());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = "series,variant,blur.sigma,pt.spp,time_ms,pipeline_ms,error.rel_mse,pt_error.rel_mse,date,machine,threads,commit\n\
        method,blur.sigma=1,1,4,5,4,0.02,0.5,2026-11-29,x86_64 linux 2 cores,2,abc\n\
        baseline,pt.spp=1,1,1,3,2,0.5,0.1,2026-11-29,x86_64 linux 2 cores,2,abc\n\
        baseline,pt.spp=2,1,2,6,8,0.5,0.01,2026-11-29,x86_64 linux 2 cores,2,abc\n";

    const BENCH_CSV: &str = "bench,case,fastest_ms,slowest_ms,median_ms,mean_ms,samples,iters,date,machine,threads,commit\n\
        refract,edit_256/camera.azimuth,145.3,176.3,158.5,160.7,10,10,2026-11-29,x86_64 linux 2 cores,2,abc\n\
        refract,shade_256_only,28.29,43.51,34.81,33.67,10,10,2026-11-29,x86_64 linux 2 cores,2,abc\n";

    fn folder(manifest: &str) -> tempfile::TempDir {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("sweep_blur.csv"), CSV).unwrap();
        std::fs::write(dir.path().join("sweeps.ron"), manifest).unwrap();
        std::fs::write(dir.path().join("bench_refract.csv"), BENCH_CSV).unwrap();
        std::fs::write(dir.path().join("benches.ron"), BENCH_MANIFEST).unwrap();
        dir
    }

    const MANIFEST_TEXT: &str = r#"SweepResults(sweeps: [(name: "blur", caption: "Blur", command: "relume sweep graphs/filters.ron --vary blur.sigma=1 --baseline pt.spp --baseline-max 2 --error-node error --baseline-error-node pt_error", page: "filters", headline: "blur.sigma=1")])"#;
    const BENCH_MANIFEST: &str = r#"BenchResults(benches: [(name: "refract", caption: "Edits", command: "python3 benches/scripts/record_bench.py refract refract", against: "shade_256_only")])"#;

    #[test]
    fn a_benchmark_gives_its_cases_medians_and_ratios_measured_in_one_run() {
        let dir = folder(MANIFEST_TEXT);
        results(&ResultsArgs { dir: dir.path().to_path_buf(), check: false }).unwrap();
        let md = std::fs::read_to_string(dir.path().join("bench_refract.md")).unwrap();
        assert!(md.starts_with("<!-- Generated") && md.contains("**Edits.** Measured 2026-11-29"), "{md}");
        assert!(md.contains("| edit_256/camera.azimuth | 158 ms | 6.31 | 145 ms – 176 ms | 10 × 10 | 4.55× |"), "{md}");
        assert!(md.contains("| shade_256_only | 35 ms | 28.7 | 28 ms – 44 ms | 10 × 10 | 1.00× |"), "{md}");
        assert!(std::fs::read_to_string(dir.path().join("benches.md")).unwrap().contains("## Edits"));
        std::fs::write(dir.path().join("bench_refract.txt"), "69968 photons\n").unwrap();
        results(&ResultsArgs { dir: dir.path().to_path_buf(), check: false }).unwrap();
        let md = std::fs::read_to_string(dir.path().join("bench_refract.md")).unwrap();
        assert!(md.ends_with("Printed by the benchmark in the same run:\n\n```text\n69968 photons\n```\n"), "{md}");
        // A case that counts items (rays, samples) shows items a second instead of runs.
        let counted = BENCH_CSV.replace("iters,date", "iters,median_items_per_s,date").replace(",10,10,2026", ",10,10,6900000,2026");
        std::fs::write(dir.path().join("bench_refract.csv"), counted).unwrap();
        results(&ResultsArgs { dir: dir.path().to_path_buf(), check: false }).unwrap();
        let md = std::fs::read_to_string(dir.path().join("bench_refract.md")).unwrap();
        assert!(md.contains("| shade_256_only | 35 ms | 6.90 M items | 28 ms – 44 ms |"), "{md}");
        // Figures from elsewhere beside the cases, under their heading; a case they name must exist.
        let compared = BENCH_MANIFEST.replace(
            r#"against: "shade_256_only""#,
            r#"against: "shade_256_only", compare: {"shade_256_only": "5.8 frames/s"}, compare_heading: "[S] table 6-1""#,
        );
        std::fs::write(dir.path().join("benches.ron"), &compared).unwrap();
        results(&ResultsArgs { dir: dir.path().to_path_buf(), check: false }).unwrap();
        let md = std::fs::read_to_string(dir.path().join("bench_refract.md")).unwrap();
        assert!(md.contains("| median against `shade_256_only` | [S] table 6-1 |"), "{md}");
        assert!(md.contains("| 1.00× | 5.8 frames/s |") && md.contains("| 4.55× | — |"), "{md}");
        std::fs::write(dir.path().join("benches.ron"), compared.replace(r#"{"shade_256_only""#, r#"{"nosuch""#)).unwrap();
        assert!(results(&ResultsArgs { dir: dir.path().to_path_buf(), check: true }).unwrap_err().msg.contains("a case `nosuch`"));
        std::fs::write(dir.path().join("benches.ron"), compared.replace(r#", compare_heading: "[S] table 6-1""#, "")).unwrap();
        assert!(results(&ResultsArgs { dir: dir.path().to_path_buf(), check: true }).unwrap_err().msg.contains("needs both `compare`"));
        // Without its manifest, a benchmark's CSV is one nothing lists.
        std::fs::remove_file(dir.path().join("benches.ron")).unwrap();
        let e = results(&ResultsArgs { dir: dir.path().to_path_buf(), check: true }).unwrap_err();
        assert!(e.msg.contains("benches.ron does not list: bench_refract.csv"), "{}", e.msg);
        let bad = BENCH_MANIFEST.replace("shade_256_only", "nosuch");
        std::fs::write(dir.path().join("benches.ron"), bad).unwrap();
        let e = results(&ResultsArgs { dir: dir.path().to_path_buf(), check: true }).unwrap_err();
        assert!(e.msg.contains("no case `nosuch`"), "{}", e.msg);
    }

    #[test]
    fn a_folder_gives_plot_section_and_overview_and_checks_clean_after_writing() {
        let dir = folder(MANIFEST_TEXT);
        let args = |check| ResultsArgs { dir: dir.path().to_path_buf(), check };
        assert_eq!(results(&args(true)).unwrap_err().code, 1, "nothing generated yet");
        results(&args(false)).unwrap();
        results(&args(true)).unwrap();
        let md = std::fs::read_to_string(dir.path().join("sweep_blur.md")).unwrap();
        assert!(md.contains("Measured 2026-11-29 on x86_64 linux 2 cores, 2 threads"), "{md}");
        // The method at 4 ms and 0.02; the baseline passes 0.02 between 2 ms (0.1) and 8 ms
        // (0.01): at 2 × 4^0.699 = 5.3 ms, a speed-up of 1.32.
        assert!(md.contains("| blur.sigma=1 | 0.0200 | 4.0 ms | 0.0316 | 5.3 ms | 1.32× |"), "{md}");
        assert!(std::fs::read_to_string(dir.path().join("sweeps.md")).unwrap().contains("## Blur"));
        let headlines = std::fs::read_to_string(dir.path().join("headlines_filters.md")).unwrap();
        assert!(headlines.contains("| Blur | `blur.sigma=1` | 0.0200 (`rel_mse`) | 4.0 ms | 5.3 ms | 1.32× |"), "{headlines}");
        assert!(image::open(dir.path().join("sweep_blur.png")).is_ok());
        assert!(headlines.contains("| 1.32× | — |"), "no goal, no verdict: {headlines}");
        // A hand edit of a generated file is found.
        std::fs::write(dir.path().join("sweep_blur.md"), md.replace("1.32×", "2.00×")).unwrap();
        let e = results(&args(true)).unwrap_err();
        assert!(e.msg.contains("sweep_blur.md"), "{}", e.msg);
    }

    #[test]
    fn a_goal_is_drawn_and_its_headline_says_whether_it_is_met_or_by_how_much_not() {
        let with_goal = |g: &str| MANIFEST_TEXT.replace("--baseline-max 2", &format!("--baseline-max 2 --goal {g}"));
        let dir = folder(&with_goal("1.2"));
        let args = || ResultsArgs { dir: dir.path().to_path_buf(), check: false };
        let read = |f: &str| std::fs::read_to_string(dir.path().join(f)).unwrap();
        results(&args()).unwrap();
        assert!(read("headlines_filters.md").contains("| 1.32× | ≥ 1.2×: met |"), "{}", read("headlines_filters.md"));
        assert!(read("sweep_blur.md").contains("The dashed line is the goal, 1.2× the baseline's speed"), "{}", read("sweep_blur.md"));
        let plain = image::open(dir.path().join("sweep_blur.png")).unwrap().to_rgb8();
        assert!(plain.pixels().any(|p| p.0 == [120, 120, 120]), "the goal's line is drawn");
        // 2× asks the baseline's 5.3 ms of the method: at 4.0 ms it is 2 × 4.0 / 5.27 = 1.52× short.
        std::fs::write(dir.path().join("sweeps.ron"), with_goal("2.0")).unwrap();
        results(&args()).unwrap();
        assert!(read("headlines_filters.md").contains("| 1.32× | ≥ 2×: 1.52× short |"), "{}", read("headlines_filters.md"));
        std::fs::write(dir.path().join("sweeps.ron"), with_goal("0.5")).unwrap();
        assert!(results(&args()).unwrap_err().msg.contains("no speed-up"), "a goal under 1× is no goal");
    }

    #[test]
    fn unlisted_csvs_bad_manifests_and_missing_provenance_are_refused() {
        let dir = folder(r#"SweepResults(sweeps: [])"#);
        let args = ResultsArgs { dir: dir.path().to_path_buf(), check: false };
        assert!(results(&args).unwrap_err().msg.contains("sweep_blur.csv"));
        std::fs::write(dir.path().join("sweeps.ron"), "SweepResults(sweeps: [(name: \"a b\", caption: \"\", command: \"\")])").unwrap();
        assert!(results(&args).unwrap_err().msg.contains("letters, digits"));
        std::fs::write(dir.path().join("sweeps.ron"), MANIFEST_TEXT.replace(r#", headline: "blur.sigma=1""#, "")).unwrap();
        assert!(results(&args).unwrap_err().msg.contains("needs both `page` and `headline`"));
        std::fs::write(dir.path().join("sweeps.ron"), MANIFEST_TEXT).unwrap();
        let without: String = CSV.lines().map(|l| l.rsplitn(5, ',').last().unwrap().to_string() + "\n").collect();
        std::fs::write(dir.path().join("sweep_blur.csv"), without).unwrap();
        let e = results(&args).unwrap_err();
        assert!(e.msg.contains("no date, machine, threads, commit column"), "{}", e.msg);
    }

    #[test]
    fn a_table_may_draw_named_rows_from_a_run_csv_which_must_be_drawn_from() {
        let dir = folder(MANIFEST_TEXT);
        let args = |check| ResultsArgs { dir: dir.path().to_path_buf(), check };
        let run = "series,variant,t0.terms,ms:t0,bytes:t0,date,machine,threads,commit\nmethod,t0.terms=96,96,82800,399014228,2026-11-29,m,2,abc\n";
        std::fs::write(dir.path().join("run_ptt.csv"), run).unwrap();
        let e = results(&args(true)).unwrap_err();
        assert!(e.msg.contains("run CSV files no table of tables.ron draws from: run_ptt.csv"), "{}", e.msg);
        let manifest = r#"TableResults(tables: [(name: "stages", caption: "Stages", command: "relume sweep g.ron --vary t0.terms=96",
            source: "run_ptt.csv", rows: [("TransferT0", ["ms:t0", "bytes:t0"])], headings: ["stage", "time", "bytes"])])"#;
        std::fs::write(dir.path().join("tables.ron"), manifest).unwrap();
        results(&args(false)).unwrap();
        let md = std::fs::read_to_string(dir.path().join("table_stages.md")).unwrap();
        assert!(md.contains("([csv](../results/run_ptt.csv))") && md.contains("| TransferT0 | 82.80 s | 380.5 MiB |"), "{md}");
        std::fs::write(dir.path().join("tables.ron"), manifest.replace(r#", "bytes"]"#, "]")).unwrap();
        assert!(results(&args(true)).unwrap_err().msg.contains("`headings` has 2 entries"));
        std::fs::write(dir.path().join("tables.ron"), manifest.replace("run_ptt.csv", "../run_ptt.csv")).unwrap();
        assert!(results(&args(true)).unwrap_err().msg.contains("must be a CSV file's name in the folder"));
        std::fs::write(dir.path().join("tables.ron"), manifest.replace("headings:", r#"group: ["variant"], headings:"#)).unwrap();
        assert!(results(&args(true)).unwrap_err().msg.contains("not both"));
    }
}
