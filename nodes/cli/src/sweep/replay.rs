//! A sweep's figure rebuilt from the command that measured it and the CSV it wrote, without
//! running anything: `relume results` draws the committed sweeps so.

use super::axes::{series_vary, Plotted, XAxis};
use super::csv_table::CsvTable;
use super::{parse_vary, SweepArgs};
use clap::Parser;

#[derive(Parser)]
#[command(name = "relume sweep", no_binary_name = true)]
struct SweepCommand {
    #[command(flatten)]
    a: SweepArgs,
}

/// The figure of `command` (a `relume sweep …` line) over `table`, its CSV; an error names
/// what the command and the CSV disagree on.
pub(crate) fn replay(command: &str, table: &CsvTable) -> Result<Plotted, String> {
    let words = split_words(command)?;
    if words.len() < 2 || words[0] != "relume" || words[1] != "sweep" {
        return Err(format!("`{command}` is not a `relume sweep …` command"));
    }
    let a = SweepCommand::try_parse_from(&words[2..]).map_err(|e| e.render().to_string().trim().to_string())?.a;
    let varies = a.varies.iter().map(|s| parse_vary(s)).collect::<Result<Vec<_>, _>>().map_err(|e| e.msg)?;
    let columns: Vec<String> = varies.iter().flat_map(|v| v.targets.iter().cloned()).collect();
    let series = a.series.as_deref().map(|s| series_vary(s, &varies)).transpose().map_err(|e| e.msg)?;
    let suffix = format!(".{}", a.metric);
    let error_node = match &a.error_node {
        Some(n) => n.clone(),
        None => table
            .header
            .iter()
            .find_map(|h| h.strip_suffix(&suffix).filter(|n| !n.contains('.') && !n.is_empty()))
            .ok_or_else(|| format!("no column reports `{}`", a.metric))?
            .to_string(),
    };
    let baseline = a.baseline.clone().map(|b| (b, a.baseline_error_node.clone().unwrap_or_else(|| error_node.clone())));
    let title = a.g.graph.file_name().map(|f| f.to_string_lossy().into_owned()).unwrap_or_else(|| a.g.graph.display().to_string());
    let plotted = Plotted {
        x: XAxis::of_column(a.x.as_deref(), a.time, &columns),
        series,
        varies,
        error_node,
        metric: a.metric,
        baseline,
        goal: a.goal,
        title,
    };
    let mut wanted = columns;
    wanted.extend([plotted.x.column(), plotted.y_column("method")]);
    if let Some((param, _)) = &plotted.baseline {
        wanted.extend([param.clone(), plotted.y_column("baseline")]);
    }
    let missing: Vec<&String> = wanted.iter().filter(|c| table.column(c).is_none()).collect();
    if !missing.is_empty() {
        return Err(format!(
            "the command plots columns the CSV lacks: {}",
            missing.iter().map(|c| c.as_str()).collect::<Vec<_>>().join(", ")
        ));
    }
    Ok(plotted)
}

/// Splits a command line at blanks outside quotes; `"…"` and `'…'` group (a backslash escapes
/// the next character inside double quotes).
fn split_words(line: &str) -> Result<Vec<String>, String> {
    let (mut words, mut word, mut any) = (Vec::new(), String::new(), false);
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        match c {
            '"' | '\'' => {
                any = true;
                loop {
                    match chars.next() {
                        None => return Err(format!("an unclosed {c} in `{line}`")),
                        Some(q) if q == c => break,
                        Some('\\') if c == '"' => word.push(chars.next().ok_or_else(|| format!("a trailing backslash in `{line}`"))?),
                        Some(x) => word.push(x),
                    }
                }
            }
            c if c.is_whitespace() => {
                if any {
                    words.push(std::mem::take(&mut word));
                    any = false;
                }
            }
            c => {
                word.push(c);
                any = true;
            }
        }
    }
    if any {
        words.push(word);
    }
    Ok(words)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn command_lines_split_at_blanks_outside_quotes() {
        assert_eq!(
            split_words(r#"relume sweep g.ron --vary "c.color=(1, 0, 0)" --set 'a.b=x y' --x """#).unwrap(),
            ["relume", "sweep", "g.ron", "--vary", "c.color=(1, 0, 0)", "--set", "a.b=x y", "--x", ""]
        );
        assert!(split_words("relume \"open").is_err());
    }

    fn table() -> CsvTable {
        CsvTable::parse(
            "series,variant,pbgi.resolution,pt.spp,time_ms,pipeline_ms,pbgi_error.rel_mse,pt_error.rel_mse\n\
             method,pbgi.resolution=8,8,16,10,9,0.01,0.5\n\
             baseline,pt.spp=1,16,1,3,2,0.5,0.2\n",
        )
        .unwrap()
    }

    #[test]
    fn a_sweep_command_and_its_csv_give_its_figure() {
        let p = replay("relume sweep graphs/pbgi.ron --vary pbgi.resolution=8 --baseline pt.spp --baseline-error-node pt_error", &table())
            .unwrap();
        assert_eq!((p.error_node.as_str(), p.title.as_str(), p.x.column()), ("pbgi_error", "pbgi.ron", "pipeline_ms".to_string()));
        let curves = p.curves(&table());
        assert_eq!(curves.len(), 2);
        assert_eq!(curves[0].points, vec![(9.0, 0.01, "8".to_string())]);
        assert_eq!(curves[1].points, vec![(2.0, 0.2, "1".to_string())], "the baseline reads its own error node");
    }

    #[test]
    fn a_command_that_does_not_fit_its_csv_is_refused() {
        let e = replay("relume sweep g.ron --vary pbgi.threshold=1", &table()).err().unwrap();
        assert!(e.contains("pbgi.threshold"), "{e}");
        let e = replay("relume sweep g.ron --vary pbgi.resolution=8 --metric ssim", &table()).err().unwrap();
        assert!(e.contains("no column reports `ssim`"), "{e}");
        assert!(replay("relume run g.ron", &table()).is_err());
        assert!(replay("relume sweep g.ron --nosuch", &table()).is_err());
    }
}
