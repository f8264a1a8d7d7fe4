//! A measurement table's section: CSV rows gathered into table rows, each figure shown as its
//! range over the runs. Two layouts: one table row per group of CSV rows that agree on the
//! `group` columns (a run a CSV row: editor drives, fresh clones), or rows named by hand, each a
//! list of CSV columns (a stage's time and bytes from one run's report). A table may draw from
//! another results file than its own `table_NAME.csv` (a sweep's, or a single run's
//! `run_NAME.csv`), keeping only the rows its `filter` names; such figures are written for
//! reading (three significant digits, times in ms or s, bytes in KiB to GiB).

use super::tables::{header, line, ms, num, provenance};
use crate::sweep::csv_table::CsvTable;
use relume_core::memory::fmt_bytes;

/// What a table shows of its CSV.
pub(crate) struct TableSpec<'a> {
    pub command: &'a str,
    /// The CSVs' file names in the results folder (several read as one).
    pub csvs: &'a [String],
    /// Only the CSV rows whose column has this text.
    pub filter: &'a [(String, String)],
    pub group: &'a [String],
    pub columns: &'a [(String, String)],
    /// Rows named by hand.
    pub rows: &'a [NamedRow],
    /// The headings of the hand-named rows' table, the label's first.
    pub headings: &'a [String],
    /// Figures written for reading rather than as the CSV writes them.
    pub formatted: bool,
}

/// A table row named by hand: its label, the CSV rows its cells range over (those with this
/// text in these columns; all rows where the filter is empty) and the CSV column of each cell
/// ("" leaves the cell empty).
pub(crate) struct NamedRow {
    pub label: String,
    pub filter: Vec<(String, String)>,
    pub cells: Vec<String>,
}

/// The section body (after its caption): provenance, command, and the table.
pub(crate) fn section(s: &TableSpec, all: &CsvTable) -> Result<String, String> {
    let t = filtered(all, s.filter)?;
    let named = s.rows.iter().flat_map(|r| r.cells.iter());
    let missing: Vec<&str> = s
        .group
        .iter()
        .chain(s.columns.iter().map(|(c, _)| c))
        .chain(named)
        .map(String::as_str)
        .filter(|c| !c.is_empty() && t.column(c).is_none())
        .collect();
    if !missing.is_empty() {
        return Err(format!("no column(s) {} (the CSV has {})", missing.join(", "), t.header.join(", ")));
    }
    let links: Vec<String> = s.csvs.iter().map(|c| format!("[{}](../results/{c})", if s.csvs.len() == 1 { "csv" } else { c })).collect();
    let mut out = format!("{} ({}):\n\n```text\n{}\n```\n\n", provenance(&t)?, links.join(", "), s.command);
    if !s.rows.is_empty() {
        out += &header(s.headings);
        for row in s.rows {
            let (label, mine) = (&row.label, filtered(&t, &row.filter).map_err(|e| format!("row `{}`: {e}", row.label))?);
            let every: Vec<usize> = (0..mine.rows.len()).collect();
            let mut shown = vec![label.clone()];
            for c in &row.cells {
                shown.push(range(&mine, &every, c, s.formatted)?);
            }
            out += &line(&shown);
        }
        return Ok(out);
    }
    let mut groups: Vec<(Vec<&str>, Vec<usize>)> = Vec::new();
    for r in 0..t.rows.len() {
        let key: Vec<&str> = s.group.iter().map(|c| t.text(r, c)).collect();
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, rows)) => rows.push(r),
            None => groups.push((key, vec![r])),
        }
    }
    let head: Vec<String> =
        s.group.iter().cloned().chain(std::iter::once("runs".to_string())).chain(s.columns.iter().map(|(_, h)| h.clone())).collect();
    out += &header(&head);
    for (key, rows) in &groups {
        let mut cells: Vec<String> = key.iter().map(|c| c.to_string()).collect();
        cells.push(rows.len().to_string());
        for (c, _) in s.columns {
            cells.push(range(&t, rows, c, s.formatted)?);
        }
        out += &line(&cells);
    }
    Ok(out)
}

/// The rows of `t` whose cells match every `(column, text)` of `filter`; refused when a
/// column is missing or no row is left.
fn filtered(t: &CsvTable, filter: &[(String, String)]) -> Result<CsvTable, String> {
    if let Some((c, _)) = filter.iter().find(|(c, _)| t.column(c).is_none()) {
        return Err(format!("the filter's column {c} is not in the CSV"));
    }
    let rows: Vec<Vec<String>> =
        (0..t.rows.len()).filter(|&r| filter.iter().all(|(c, v)| t.text(r, c) == v)).map(|r| t.rows[r].clone()).collect();
    if rows.is_empty() {
        let wanted: Vec<String> = filter.iter().map(|(c, v)| format!("{c} = {v}")).collect();
        return Err(format!("no row has {}", wanted.join(" and ")));
    }
    Ok(CsvTable { header: t.header.clone(), rows })
}

/// Column `c`'s figures over `rows`: "low–high", one figure where the two agree, "—" where no
/// run has one. As the CSV writes them, or, `formatted`, written for reading by the column's
/// name: `ms:NODE` and `…_ms` as times (a node's 0 ms is a run that loaded it from the cache:
/// left out, and "cached" where every run did), `bytes:NODE` and `…bytes` as bytes, text as it is, other
/// numbers to three significant digits.
fn range(t: &CsvTable, rows: &[usize], c: &str, formatted: bool) -> Result<String, String> {
    if c.is_empty() {
        // A named row's cell left empty on purpose.
        return Ok(String::new());
    }
    let time = c.starts_with("ms:") || c.ends_with("_ms");
    let mut figures: Vec<(f64, &str)> = Vec::new();
    let mut cached = false;
    for &r in rows {
        let text = t.text(r, c);
        if text.is_empty() {
            continue;
        }
        let v = t.number(r, c);
        if !v.is_finite() {
            if formatted {
                // A text column (a variant, a scene): its distinct cells.
                let all: Vec<&str> = rows.iter().map(|&r| t.text(r, c)).collect();
                let mut distinct: Vec<&str> = Vec::new();
                all.into_iter().for_each(|x| {
                    if !distinct.contains(&x) {
                        distinct.push(x)
                    }
                });
                return Ok(distinct.join(", "));
            }
            return Err(format!("`{text}` in column {c}, row {}, is not a number", r + 2));
        }
        if formatted && c.starts_with("ms:") && v == 0.0 {
            cached = true;
            continue;
        }
        figures.push((v, text));
    }
    let Some(&(low_v, low)) = figures.iter().min_by(|a, b| a.0.total_cmp(&b.0)) else {
        return Ok(if cached { "cached".into() } else { "—".into() });
    };
    let &(high_v, high) = figures.iter().max_by(|a, b| a.0.total_cmp(&b.0)).unwrap();
    let (low, high) = if !formatted {
        (low.to_string(), high.to_string())
    } else if time {
        (ms(low_v), ms(high_v))
    } else if c.starts_with("bytes:") || c.ends_with("bytes") {
        (fmt_bytes(low_v as u64), fmt_bytes(high_v as u64))
    } else {
        (num(low_v), num(high_v))
    };
    Ok(if low == high { low } else { format!("{low}–{high}") })
}

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = "graph,edit,run,images_per_s,latency_ms,date,machine,threads,commit\n\
        a,orbit,1,7.3,200,2026-11-29,m,2,abc\n\
        a,orbit,2,6.9,200.4,2026-11-29,m,2,abc\n\
        b,drag,1,44,,2026-11-29,m,2,abc\n\
        a,orbit,3,7.2,199.9,2026-11-29,m,2,abc\n";

    fn spec<'a>(group: &'a [String], columns: &'a [(String, String)]) -> TableSpec<'a> {
        TableSpec {
            command: "cmd",
            csvs: Box::leak(Box::new(["table_x.csv".to_string()])),
            filter: &[],
            group,
            columns,
            rows: &[],
            headings: &[],
            formatted: false,
        }
    }

    #[test]
    fn runs_are_grouped_in_order_and_shown_as_ranges() {
        let t = CsvTable::parse(CSV).unwrap();
        let cols = [("images_per_s".to_string(), "images/s".to_string()), ("latency_ms".to_string(), "latency, ms".to_string())];
        let group = ["graph".to_string(), "edit".to_string()];
        let s = section(&spec(&group, &cols), &t).unwrap();
        assert!(s.starts_with("Measured 2026-11-29 on m, 2 threads ([csv](../results/table_x.csv))"), "{s}");
        assert!(s.contains("| graph | edit | runs | images/s | latency, ms |\n"), "{s}");
        assert!(s.contains("| a | orbit | 3 | 6.9–7.3 | 199.9–200.4 |\n| b | drag | 1 | 44 | — |\n"), "{s}");
    }

    #[test]
    fn missing_columns_and_non_numbers_are_refused() {
        let t = CsvTable::parse(CSV).unwrap();
        let e = section(&spec(&["layout".into()], &[]), &t).unwrap_err();
        assert!(e.contains("no column(s) layout"), "{e}");
        let bad = CsvTable::parse(&CSV.replace("7.3", "fast")).unwrap();
        let e = section(&spec(&["graph".into()], &[("images_per_s".into(), "i".into())]), &bad).unwrap_err();
        assert!(e.contains("`fast` in column images_per_s, row 2"), "{e}");
    }

    const SWEEP: &str = "series,variant,t0.terms,error.rel_mse,ms:t0,bytes:t0,date,machine,threads,commit\n\
        method,t0.terms=48,48,0.016506674,286234.4777,228768212,2026-11-24,m,2,abc\n\
        method,t0.terms=96,96,0.012241203,0,399014228,2026-11-24,m,2,abc\n\
        baseline,pt.spp=1,96,0.5,0,399014228,2026-11-24,m,2,abc\n";

    #[test]
    fn a_view_of_a_sweep_keeps_the_filtered_rows_and_writes_figures_for_reading() {
        let t = CsvTable::parse(SWEEP).unwrap();
        let filter = [("series".to_string(), "method".to_string())];
        let group = ["t0.terms".to_string()];
        let cols =
            [("error.rel_mse", "rel. MSE"), ("ms:t0", "TransferT0"), ("bytes:t0", "T0")].map(|(a, b)| (a.to_string(), b.to_string()));
        let csvs = ["sweep_t.csv".to_string()];
        let s = section(&TableSpec { filter: &filter, formatted: true, csvs: &csvs, ..spec(&group, &cols) }, &t).unwrap();
        assert!(s.contains("([csv](../results/sweep_t.csv))"), "{s}");
        assert!(s.contains("| 48 | 1 | 0.0165 | 286.23 s | 218.2 MiB |\n| 96 | 1 | 0.0122 | cached | 380.5 MiB |\n"), "{s}");
        assert!(!s.contains("| 0.500 |"), "the baseline row is filtered out: {s}");
        // Hand-named rows: a label and a column a cell, over every (filtered) row.
        let rows = [NamedRow { label: "TransferT0".into(), filter: vec![], cells: vec!["ms:t0".into(), "bytes:t0".into()] }];
        let headings = ["stage", "time", "bytes"].map(String::from);
        let s = section(&TableSpec { filter: &filter, formatted: true, rows: &rows, headings: &headings, ..spec(&[], &[]) }, &t).unwrap();
        assert!(s.contains("| stage | time | bytes |\n| --- | --- | --- |\n| TransferT0 | 286.23 s | 218.2 MiB–380.5 MiB |\n"), "{s}");
        let nothing = [("series".to_string(), "none".to_string())];
        let e = section(&TableSpec { filter: &nothing, ..spec(&group, &cols) }, &t).unwrap_err();
        assert!(e.contains("no row has series = none"), "{e}");
        // A named row's own filter picks its CSV rows.
        let rows = [NamedRow { label: "48 terms".into(), filter: vec![("t0.terms".into(), "48".into())], cells: vec!["bytes:t0".into()] }];
        let s = section(&TableSpec { formatted: true, rows: &rows, headings: &headings[..2], ..spec(&[], &[]) }, &t).unwrap();
        assert!(s.contains("| 48 terms | 218.2 MiB |\n"), "{s}");
    }
}
