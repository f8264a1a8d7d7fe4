//! A sweep's CSV as text cells: written by `relume sweep`, read back by the sweep itself and by
//! `relume results` to draw the plot and the tables, so both draw from the same numbers.

/// A CSV file: its header and its rows, every cell as text (RFC 4180 quoting).
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct CsvTable {
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

impl CsvTable {
    /// Parses CSV text: cells split at commas outside double quotes, `""` inside quotes is a
    /// quote, rows end at a newline outside quotes. Every row must have the header's width.
    pub fn parse(text: &str) -> Result<CsvTable, String> {
        let mut lines: Vec<Vec<String>> = Vec::new();
        let (mut row, mut cell) = (Vec::new(), String::new());
        let (mut quoted, mut chars) = (false, text.chars().peekable());
        while let Some(c) = chars.next() {
            match (quoted, c) {
                (true, '"') if chars.peek() == Some(&'"') => {
                    chars.next();
                    cell.push('"');
                }
                (true, '"') => quoted = false,
                (true, c) => cell.push(c),
                (false, '"') if cell.is_empty() => quoted = true,
                (false, ',') => row.push(std::mem::take(&mut cell)),
                (false, '\r') => {}
                (false, '\n') => {
                    row.push(std::mem::take(&mut cell));
                    lines.push(std::mem::take(&mut row));
                }
                (false, c) => cell.push(c),
            }
        }
        if quoted {
            return Err("a quoted cell is not closed".into());
        }
        if !cell.is_empty() || !row.is_empty() {
            row.push(cell);
            lines.push(row);
        }
        let mut lines = lines.into_iter();
        let header = lines.next().ok_or("the file is empty")?;
        let rows: Vec<Vec<String>> = lines.collect();
        if let Some((i, r)) = rows.iter().enumerate().find(|(_, r)| r.len() != header.len()) {
            return Err(format!("row {} has {} cells where the header has {}", i + 2, r.len(), header.len()));
        }
        Ok(CsvTable { header, rows })
    }

    /// Several tables read as one: the union of their columns (in the order they first
    /// appear, then `source`), every row of each in turn, a cell its table lacks left empty and
    /// its `source` cell the name it is given with.
    pub fn joined(parts: &[(&str, CsvTable)]) -> CsvTable {
        let mut header: Vec<String> = Vec::new();
        for (_, t) in parts {
            for h in &t.header {
                if !header.contains(h) {
                    header.push(h.clone());
                }
            }
        }
        header.push("source".into());
        let mut rows = Vec::new();
        for (name, t) in parts {
            for r in 0..t.rows.len() {
                let mut row: Vec<String> = header[..header.len() - 1].iter().map(|h| t.text(r, h).to_string()).collect();
                row.push(name.to_string());
                rows.push(row);
            }
        }
        CsvTable { header, rows }
    }

    /// The index of column `name`.
    pub fn column(&self, name: &str) -> Option<usize> {
        self.header.iter().position(|h| h == name)
    }

    /// Row `r`'s cell in column `name` ("" where there is no such column).
    pub fn text(&self, r: usize, name: &str) -> &str {
        self.column(name).map_or("", |c| self.rows[r][c].as_str())
    }

    /// Row `r`'s cell in column `name` as a number (NaN where it is empty, absent or not one).
    pub fn number(&self, r: usize, name: &str) -> f64 {
        self.text(r, name).parse().unwrap_or(f64::NAN)
    }

    /// The distinct cells of column `name`, in the order they first appear.
    pub fn distinct(&self, name: &str) -> Vec<String> {
        let mut out: Vec<String> = Vec::new();
        for r in 0..self.rows.len() {
            let v = self.text(r, name);
            if !out.iter().any(|o| o == v) {
                out.push(v.to_string());
            }
        }
        out
    }
}

/// One CSV line: cells with commas, quotes or line breaks quoted.
pub(crate) fn csv_line(cells: &[String]) -> String {
    let quoted: Vec<String> = cells
        .iter()
        .map(|c| if c.contains([',', '"', '\n', '\r']) { format!("\"{}\"", c.replace('"', "\"\"")) } else { c.clone() })
        .collect();
    quoted.join(",") + "\n"
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn written_lines_read_back_as_the_same_cells() {
        let cells = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        let header = cells(&["series", "variant", "clean.color"]);
        let row = cells(&["method", "x=\"q\"", "(1, 0, 0)"]);
        let text = csv_line(&header) + &csv_line(&row) + &csv_line(&cells(&["baseline", "", ""]));
        let t = CsvTable::parse(&text).unwrap();
        assert_eq!(t.header, header);
        assert_eq!(t.rows, vec![row, cells(&["baseline", "", ""])]);
        assert_eq!(t.text(0, "clean.color"), "(1, 0, 0)");
        assert_eq!(t.distinct("series"), ["method", "baseline"]);
        assert!(t.number(1, "variant").is_nan() && t.number(0, "nosuch").is_nan());
    }

    #[test]
    fn ragged_rows_open_quotes_and_empty_files_are_refused() {
        assert!(CsvTable::parse("a,b\n1\n").unwrap_err().contains("row 2 has 1 cells"));
        assert!(CsvTable::parse("a,b\n\"1,2\n").is_err());
        assert!(CsvTable::parse("").is_err());
        assert_eq!(CsvTable::parse("a,b\r\n1,2").unwrap().rows, vec![vec!["1".to_string(), "2".to_string()]]);
    }

    #[test]
    fn joined_tables_keep_every_column_and_name_each_rows_source() {
        let a = CsvTable::parse("x,y\n1,2\n").unwrap();
        let b = CsvTable::parse("y,z\n3,4\n").unwrap();
        let j = CsvTable::joined(&[("a.csv", a), ("b.csv", b)]);
        assert_eq!(j.header, ["x", "y", "z", "source"]);
        assert_eq!(j.rows, [["1", "2", "", "a.csv"], ["", "3", "4", "b.csv"]]);
    }
}
