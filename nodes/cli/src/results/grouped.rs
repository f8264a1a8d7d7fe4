//! A measurement table's section: the CSV's runs gathered into rows by the columns that name
//! what was measured, each figure shown as its range over the runs.

use super::tables::{header, line, provenance};
use crate::sweep::csv_table::CsvTable;

/// The section body (after its caption): provenance, command, and one row per group of runs,
/// in the order the groups first appear: the group's cells, the number of runs, and for each
/// value column the smallest and largest figure as the CSV writes them (one figure where they
/// agree).
pub(crate) fn section(name: &str, command: &str, group: &[String], columns: &[(String, String)], t: &CsvTable) -> Result<String, String> {
    let missing: Vec<&str> =
        group.iter().chain(columns.iter().map(|(c, _)| c)).map(String::as_str).filter(|c| t.column(c).is_none()).collect();
    if !missing.is_empty() {
        return Err(format!("no column(s) {} (the CSV has {})", missing.join(", "), t.header.join(", ")));
    }
    let mut out = format!("{} ([csv](../results/table_{name}.csv)):\n\n```text\n{command}\n```\n\n", provenance(t)?);
    let mut groups: Vec<(Vec<&str>, Vec<usize>)> = Vec::new();
    for r in 0..t.rows.len() {
        let key: Vec<&str> = group.iter().map(|c| t.text(r, c)).collect();
        match groups.iter_mut().find(|(k, _)| *k == key) {
            Some((_, rows)) => rows.push(r),
            None => groups.push((key, vec![r])),
        }
    }
    let head: Vec<String> =
        group.iter().cloned().chain(std::iter::once("runs".to_string())).chain(columns.iter().map(|(_, h)| h.clone())).collect();
    out += &header(&head);
    for (key, rows) in &groups {
        let mut cells: Vec<String> = key.iter().map(|c| c.to_string()).collect();
        cells.push(rows.len().to_string());
        for (c, _) in columns {
            cells.push(range(t, rows, c)?);
        }
        out += &line(&cells);
    }
    Ok(out)
}

/// Column `c`'s figures over `rows`: "low–high" as written in the CSV, one figure where the
/// two agree, "—" where no run has one.
fn range(t: &CsvTable, rows: &[usize], c: &str) -> Result<String, String> {
    let mut figures: Vec<(f64, &str)> = Vec::new();
    for &r in rows {
        let text = t.text(r, c);
        if text.is_empty() {
            continue;
        }
        let v = t.number(r, c);
        if !v.is_finite() {
            return Err(format!("`{text}` in column {c}, row {}, is not a number", r + 2));
        }
        figures.push((v, text));
    }
    let Some(&(_, low)) = figures.iter().min_by(|a, b| a.0.total_cmp(&b.0)) else { return Ok("—".into()) };
    let &(_, high) = figures.iter().max_by(|a, b| a.0.total_cmp(&b.0)).unwrap();
    Ok(if low == high { low.to_string() } else { format!("{low}–{high}") })
}

#[cfg(test)]
mod tests {
    use super::*;

    const CSV: &str = "graph,edit,run,images_per_s,latency_ms,date,machine,threads,commit\n\
        a,orbit,1,7.3,200,2026-11-29,m,2,abc\n\
        a,orbit,2,6.9,200.4,2026-11-29,m,2,abc\n\
        b,drag,1,44,,2026-11-29,m,2,abc\n\
        a,orbit,3,7.2,199.9,2026-11-29,m,2,abc\n";

    #[test]
    fn runs_are_grouped_in_order_and_shown_as_ranges() {
        let t = CsvTable::parse(CSV).unwrap();
        let cols = [("images_per_s".to_string(), "images/s".to_string()), ("latency_ms".to_string(), "latency, ms".to_string())];
        let s = section("x", "cmd", &["graph".into(), "edit".into()], &cols, &t).unwrap();
        assert!(s.starts_with("Measured 2026-11-29 on m, 2 threads ([csv](../results/table_x.csv))"), "{s}");
        assert!(s.contains("| graph | edit | runs | images/s | latency, ms |\n"), "{s}");
        assert!(s.contains("| a | orbit | 3 | 6.9–7.3 | 199.9–200.4 |\n| b | drag | 1 | 44 | — |\n"), "{s}");
    }

    #[test]
    fn missing_columns_and_non_numbers_are_refused() {
        let t = CsvTable::parse(CSV).unwrap();
        let e = section("x", "cmd", &["layout".into()], &[], &t).unwrap_err();
        assert!(e.contains("no column(s) layout"), "{e}");
        let bad = CsvTable::parse(&CSV.replace("7.3", "fast")).unwrap();
        let e = section("x", "cmd", &["graph".into()], &[("images_per_s".into(), "i".into())], &bad).unwrap_err();
        assert!(e.contains("`fast` in column images_per_s, row 2"), "{e}");
    }
}
