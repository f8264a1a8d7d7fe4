//! `relume slurm`: writes (and with `--submit`, submits) a Slurm array job for the shards of a
//! node and a gather job depending on it (`afterok`).
//!
//! Task `i` of the array job runs `relume shard GRAPH --node ID --shards N` (the index from
//! `SLURM_ARRAY_TASK_ID`): a contiguous run of the node's chunks into the shared cache folder.
//! The gather job runs `relume run GRAPH` on the same cache once every task has succeeded; it
//! finds the chunks there and computes only those that are missing. Slurm is called as an
//! external program (`sbatch`); nothing of relume's runs on the cluster but the binary.

use crate::args::GraphArgs;
use crate::error::CliError;
use crate::files::prepare_out_dir;
use crate::run::{refuse_files, CommandWrites};
use clap::Args;
use relume_core::graph::{Output, PortRef};
use relume_core::{Graph, ParamValues, Registry, RunOptions, ShardSpec};
use std::path::{Path, PathBuf};
use std::process::Command;

/// The most array tasks `relume slurm` writes: sites cap array jobs at about this many
/// (Slurm's `MaxArraySize`, 1001 by default, is often raised to a few thousand).
pub(crate) const MAX_ARRAY_TASKS: u64 = 4000;

#[derive(Args)]
pub(crate) struct SlurmArgs {
    #[command(flatten)]
    pub g: GraphArgs,
    /// The sharded node whose shards the array job runs.
    #[arg(long, value_name = "ID")]
    pub node: String,
    /// How many array tasks; each runs a contiguous run of the node's chunks (at most 4000,
    /// and at most the node's number of chunks).
    #[arg(long, value_name = "N")]
    pub shards: u64,
    /// Slurm partition for both jobs (sbatch --partition).
    #[arg(long, value_name = "P")]
    pub partition: Option<String>,
    /// Time limit of each array task and of the gather job (sbatch --time), e.g. 01:30:00.
    #[arg(long, value_name = "HH:MM:SS")]
    pub time: Option<String>,
    /// Cores per task (sbatch --cpus-per-task); relume then uses that many threads.
    #[arg(long, value_name = "C")]
    pub cpus_per_task: Option<u32>,
    /// Memory per node of each job (sbatch --mem), e.g. 8G.
    #[arg(long, value_name = "M")]
    pub mem: Option<String>,
    /// Account to charge (sbatch --account).
    #[arg(long, value_name = "A")]
    pub account: Option<String>,
    /// Folder the gather job writes the outputs and report.json to.
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
    /// Folder for the two scripts and the jobs' logs (default: OUT/slurm).
    #[arg(long, value_name = "DIR")]
    pub script_dir: Option<PathBuf>,
    /// Submit the two jobs with sbatch (the gather depending on the array job) instead of
    /// only printing the commands.
    #[arg(long)]
    pub submit: bool,
    /// The relume binary the jobs run (default: this one); the compute nodes must see it at
    /// this path.
    #[arg(long, value_name = "PATH")]
    pub relume: Option<PathBuf>,
}

/// The two scripts `relume slurm` writes and what goes into them.
pub(crate) struct SlurmJobs {
    pub array_script: PathBuf,
    pub gather_script: PathBuf,
    pub array_text: String,
    pub gather_text: String,
}

pub(crate) fn slurm(reg: &Registry, a: &SlurmArgs) -> Result<(), CliError> {
    // Everything is checked before anything is written: the graph, the node, the options.
    let graph = a.g.load(reg)?;
    super::shard::check_sharded_node(reg, &graph, &a.node)?;
    check_shard_count(a.shards)?;
    check_options(a)?;
    let paths = Paths::resolve(a)?;
    refuse_files(reg, &graph, a.g.requested().as_deref(), &a.g.write_policy(&paths.out), &a.g.read_policy(), &CommandWrites::default())?;
    std::fs::create_dir_all(&paths.cache)
        .map_err(|e| CliError::graph(format!("--cache {}: cannot create the folder: {e}", paths.cache.display())))?;
    let spec = chunk_spec(reg, a, &graph, &paths)?;
    match spec {
        Some(s) if a.shards > s.chunks() => {
            return Err(CliError::graph(format!(
                "--shards {}: node \"{}\" has only {} chunks of work ({} items, {} per chunk), so tasks beyond {} would have nothing to do; give --shards {} or fewer",
                a.shards,
                a.node,
                s.chunks(),
                s.items,
                s.chunk,
                s.chunks(),
                s.chunks()
            )))
        }
        Some(s) => {
            let (lo, hi) = (0..a.shards).map(|i| s.shard_chunks(i, a.shards).count()).fold((usize::MAX, 0), |(lo, hi), c| (lo.min(c), hi.max(c)));
            let each = if lo == hi { format!("{lo}") } else { format!("{lo} or {hi}") };
            let unit = if hi == 1 { "chunk" } else { "chunks" };
            say!("node \"{}\": {} chunks; {} array tasks of {each} {unit} each", a.node, s.chunks(), a.shards);
        }
        None => say!(
            "node \"{}\": its chunks were not counted (a sharded node upstream of it would have to run here first); array tasks beyond its number of chunks have nothing to do and finish at once",
            a.node
        ),
    }
    say!("the array tasks write into the cache {} (every compute node must see this folder)", paths.cache.display());
    prepare_out_dir("--out", &paths.out)?;
    prepare_out_dir("--script-dir", &paths.scripts)?;
    let jobs = scripts(a, &paths, spec);
    for (path, text) in [(&jobs.array_script, &jobs.array_text), (&jobs.gather_script, &jobs.gather_text)] {
        relume_core::graph::write_atomic(path, text.as_bytes())
            .map_err(|e| CliError::run(format!("cannot write {}: {e}", path.display())))?;
        say!("wrote {}", path.display());
    }
    if !a.submit {
        let (arr, gat) = (shell_quote(&path_text(&jobs.array_script)?), shell_quote(&path_text(&jobs.gather_script)?));
        say!("submit them with (or run this command again with --submit):");
        say!("  ARRAY_JOB_ID=$(sbatch --parsable {arr} | cut -d';' -f1)");
        say!("  sbatch --dependency=afterok:$ARRAY_JOB_ID {gat}");
        say!("the gather job writes {} and its report.json", paths.out.display());
        return Ok(());
    }
    let array_id = sbatch(&[], &jobs.array_script)?;
    say!("submitted array job {array_id} ({} tasks)", a.shards);
    let gather_id = sbatch(&[format!("--dependency=afterok:{array_id}")], &jobs.gather_script).map_err(|e| {
        CliError::run(format!(
            "{}\n(the array job {array_id} is submitted; submit the gather by hand with `sbatch --dependency=afterok:{array_id} {}`, or cancel it with `scancel {array_id}`)",
            e.msg,
            jobs.gather_script.display()
        ))
    })?;
    say!("submitted gather job {gather_id} (runs after every task of {array_id} succeeded; writes {})", paths.out.display());
    say!("array job {array_id}");
    say!("gather job {gather_id}");
    Ok(())
}

/// Refuses 0 shards and more array tasks than sites allow.
fn check_shard_count(n: u64) -> Result<(), CliError> {
    if n == 0 {
        return Err(CliError::graph("--shards must be at least 1"));
    }
    if n > MAX_ARRAY_TASKS {
        return Err(CliError::graph(format!(
            "--shards {n}: Slurm sites cap array jobs at about {MAX_ARRAY_TASKS} tasks (the cluster's MaxArraySize, 1001 unless raised: \
             `scontrol show config | grep MaxArraySize` shows it); each task runs a contiguous run of chunks, so fewer tasks lose nothing: \
             give a smaller --shards, e.g. --shards 1000"
        )));
    }
    Ok(())
}

/// Refuses option values that cannot go on an `#SBATCH` line as they are.
fn check_options(a: &SlurmArgs) -> Result<(), CliError> {
    let plain = |flag: &str, v: &Option<String>, ok: &dyn Fn(char) -> bool, what: &str| -> Result<(), CliError> {
        match v {
            Some(s) if s.is_empty() || !s.chars().all(ok) => Err(CliError::graph(format!("{flag} {s:?}: {what}"))),
            _ => Ok(()),
        }
    };
    let name = |c: char| c.is_ascii_alphanumeric() || "_-.,+".contains(c);
    plain("--partition", &a.partition, &name, "give a partition name (letters, digits, `_-.,+`; `sinfo -s` lists them)")?;
    plain("--account", &a.account, &name, "give an account name (letters, digits, `_-.,+`; `sacctmgr show assoc user=$USER` lists yours)")?;
    plain(
        "--time",
        &a.time,
        &|c| c.is_ascii_digit() || c == ':' || c == '-',
        "give a time limit as Slurm writes it: MM, HH:MM:SS or D-HH:MM:SS",
    )?;
    plain(
        "--mem",
        &a.mem,
        &|c| c.is_ascii_digit() || "KMGTkmgt".contains(c),
        "give a size as Slurm writes it: a number with K, M, G or T, e.g. 8G",
    )?;
    if a.cpus_per_task == Some(0) {
        return Err(CliError::graph("--cpus-per-task must be at least 1"));
    }
    // What the scripts echo besides paths (`path_text` refuses line breaks in those): a line
    // break would end the header comment or the `#SBATCH` block and make the rest a command.
    let echoed = a.g.sets.iter().map(|s| ("--set", s)).chain(a.g.outputs.iter().map(|o| ("--output", o))).chain([("--node", &a.node)]);
    for (flag, v) in echoed {
        if v.contains(['\n', '\r']) {
            return Err(CliError::graph(format!(
                "{flag} {}: the Slurm scripts repeat this value, and a line break in it would end their comment or `#SBATCH` lines and run the rest as a command; give it without line breaks",
                v.escape_debug()
            )));
        }
    }
    if a.g.no_disk_cache {
        return Err(CliError::graph(
            "the array tasks hand their results to the gather job through the disk cache: drop --no-disk-cache and give --cache DIR on a filesystem every compute node sees",
        ));
    }
    Ok(())
}

/// The absolute paths the scripts name.
struct Paths {
    graph: PathBuf,
    cache: PathBuf,
    out: PathBuf,
    scripts: PathBuf,
    relume: PathBuf,
}

impl Paths {
    fn resolve(a: &SlurmArgs) -> Result<Paths, CliError> {
        let abs = |flag: &str, p: &Path| {
            std::path::absolute(p).map_err(|e| CliError::graph(format!("{flag} {}: cannot make the path absolute: {e}", p.display())))
        };
        let (cache, _) = a.g.cache_dir().expect("--no-disk-cache was refused");
        let out = abs("--out", &a.out)?;
        let scripts = match &a.script_dir {
            Some(d) => abs("--script-dir", d)?,
            None => out.join("slurm"),
        };
        let relume = match &a.relume {
            Some(p) => {
                let p = abs("--relume", p)?;
                if !p.is_file() {
                    return Err(CliError::graph(format!(
                        "--relume {}: no such file; give the path of the relume binary as this machine and the compute nodes see it",
                        p.display()
                    )));
                }
                p
            }
            None => std::env::current_exe()
                .map_err(|e| CliError::run(format!("cannot tell where this relume binary is ({e}); give --relume PATH")))?,
        };
        let paths = Paths { graph: abs("the graph", &a.g.graph)?, cache: abs("--cache", &cache)?, out, scripts, relume };
        for p in [&paths.graph, &paths.cache, &paths.out, &paths.scripts, &paths.relume] {
            path_text(p)?;
        }
        Ok(paths)
    }
}

/// A path as script text: UTF-8, without line breaks (which no `#SBATCH` line can hold).
fn path_text(p: &Path) -> Result<String, CliError> {
    match p.to_str() {
        Some(s) if !s.contains(['\n', '\r']) => Ok(s.to_string()),
        _ => Err(CliError::graph(format!(
            "{}: a path in a Slurm script must be UTF-8 text without line breaks; rename the folder or pick another",
            p.display()
        ))),
    }
}

/// The node's shard spec, from its inputs: runs what the node needs (a scene, a BVH) here,
/// through the same cache the tasks use. `None` when a sharded node upstream of it would have
/// to run here first (too heavy for a login node).
fn chunk_spec(reg: &Registry, a: &SlurmArgs, graph: &Graph, paths: &Paths) -> Result<Option<ShardSpec>, CliError> {
    let idx = graph.node_index(&a.node).expect("checked node");
    let decl = &graph.nodes[idx];
    let kind = reg.node(&decl.kind).expect("checked node");
    let sharded = kind.sharded().expect("checked node");
    let upstream = graph.topology().upstream_of(&[idx]);
    let heavy =
        graph.nodes.iter().enumerate().any(|(i, n)| i != idx && upstream[i] && reg.node(&n.kind).is_some_and(|k| k.sharded().is_some()));
    if heavy {
        return Ok(None);
    }
    let mut g = graph.clone();
    let mut names = Vec::new();
    for (k, port) in kind.ports().inputs.iter().enumerate() {
        let edge =
            graph.edges.iter().find(|e| e.to.node == a.node && e.to.port == port.name).expect("a validated graph connects every input");
        let name = format!("__slurm_input_{k}");
        g.outputs.push(Output {
            name: name.clone(),
            port: PortRef { node: edge.from.node.clone(), port: edge.from.port.clone() },
            pos: edge.pos,
        });
        names.push(name);
    }
    let mut g_args = a.g.clone();
    g_args.cache = Some(paths.cache.clone());
    let (engine, note) = g_args.engine_for_writing(reg);
    if let Some(why) = note {
        return Err(CliError::run(format!("the array tasks need a disk cache they can write: {why}")));
    }
    let opts = RunOptions { outputs: Some(names.clone()), writes: a.g.write_policy(&paths.out), ..Default::default() };
    let result = engine.run(&g, &opts).map_err(|e| super::run::run_error(graph, e))?;
    let inputs: Vec<_> = names.iter().map(|n| result.output(n).expect("requested output").clone()).collect();
    let params = ParamValues::resolve(kind.schema(), &decl.params, &graph.base_dir)
        .map_err(|m| CliError::graph(format!("node \"{}\": missing required parameter `{}`", a.node, m.join("`, `"))))?;
    sharded
        .spec(&params, &inputs)
        .map(Some)
        .map_err(|e| CliError::run(format!("node \"{}\" ({}): cannot count its chunks: {e}", a.node, decl.kind)))
}

/// The two scripts' paths and text.
fn scripts(a: &SlurmArgs, p: &Paths, spec: Option<ShardSpec>) -> SlurmJobs {
    let txt = |p: &Path| p.to_str().expect("checked UTF-8").to_string();
    let stem = file_stem(&p.graph);
    let base = format!("{stem}-{}", a.node);
    let array_script = p.scripts.join(format!("{base}-shards.sbatch"));
    let gather_script = p.scripts.join(format!("{base}-gather.sbatch"));
    let mut directives: Vec<String> = Vec::new();
    for (flag, v) in [("partition", &a.partition), ("time", &a.time), ("mem", &a.mem), ("account", &a.account)] {
        if let Some(v) = v {
            directives.push(format!("#SBATCH --{flag}={v}"));
        }
    }
    if let Some(c) = a.cpus_per_task {
        directives.push(format!("#SBATCH --cpus-per-task={c}"));
    }
    // What both commands share: the graph, the cache, the overrides and the engine's options.
    let mut common = vec![shell_quote(&txt(&p.graph)), "--cache".into(), shell_quote(&txt(&p.cache))];
    for s in &a.g.sets {
        common.extend(["--set".into(), shell_quote(s)]);
    }
    if let Some(t) = a.g.threads.or(a.cpus_per_task.map(|c| c as usize)) {
        common.extend(["--threads".into(), t.to_string()]);
    }
    if let Some(b) = a.g.memory_budget {
        common.extend(["--memory-budget".into(), b.to_string()]);
    }
    if a.g.cache_all {
        common.push("--cache-all".into());
    }
    if a.g.allow_writes_anywhere {
        common.push("--allow-writes-anywhere".into());
    }
    let relume = shell_quote(&txt(&p.relume));
    let generated = format!(
        "# Generated by relume {} (`relume slurm`), as:\n#   {}\n# The cache folder, the graph and the relume binary must be on a filesystem every compute node sees.\n",
        env!("CARGO_PKG_VERSION"),
        command_line(a)
    );
    let chunks = spec.map(|s| format!("the {} chunks", s.chunks())).unwrap_or_else(|| "the chunks".into());
    let array_text = format!(
        "#!/bin/bash\n{generated}# Array job: task I of {n} runs shard I ({chunks} of node \"{node}\" split into {n} contiguous runs) into the cache;\n\
         # task I can be re-run alone, keeping the chunks it finished: sbatch --array=I {this}\n\
         # Then the gather job: {gather}\n\
         #SBATCH --job-name=relume-{node}\n\
         #SBATCH --array=0-{last}\n\
         #SBATCH --output={log}\n\
         {dirs}set -euo pipefail\n\
         : \"${{SLURM_ARRAY_TASK_ID:?this script is a Slurm array job: submit it with sbatch}}\"\n\
         exec {relume} shard {common} --node {node} --shards {n} --report {reports}/{base}-shard-\"$SLURM_ARRAY_TASK_ID\".json\n",
        n = a.shards,
        node = a.node,
        gather = txt(&gather_script),
        this = txt(&array_script),
        last = a.shards - 1,
        log = sbatch_quote(&format!("{}/{base}-shard-%A_%a.log", txt(&p.scripts))),
        dirs = directives.iter().map(|d| format!("{d}\n")).collect::<String>(),
        common = common.join(" "),
        reports = shell_quote(&txt(&p.scripts)),
    );
    let mut gather_cmd = vec![relume, "run".into()];
    gather_cmd.extend(common);
    gather_cmd.extend(["--out".into(), shell_quote(&txt(&p.out)), "--report".into(), shell_quote(&txt(&p.out.join("report.json")))]);
    for o in &a.g.outputs {
        gather_cmd.extend(["--output".into(), shell_quote(o)]);
    }
    let gather_text = format!(
        "#!/bin/bash\n{generated}# Gather job: submitted with --dependency=afterok:<the array job's id>, it runs the graph once every\n\
         # array task succeeded, finding the shards' chunks in the cache (any missing one is computed here).\n\
         #SBATCH --job-name=relume-{node}-gather\n\
         #SBATCH --output={log}\n\
         {dirs}set -euo pipefail\n\
         exec {cmd}\n",
        node = a.node,
        log = sbatch_quote(&format!("{}/{base}-gather-%j.log", txt(&p.scripts))),
        dirs = directives.iter().map(|d| format!("{d}\n")).collect::<String>(),
        cmd = gather_cmd.join(" "),
    );
    SlurmJobs { array_script, gather_script, array_text, gather_text }
}

/// The command that wrote the scripts, as a shell would take it (for their header).
fn command_line(a: &SlurmArgs) -> String {
    let mut v: Vec<String> = vec!["relume".into(), "slurm".into(), shell_quote(&a.g.graph.to_string_lossy())];
    v.extend(["--node".into(), a.node.clone(), "--shards".into(), a.shards.to_string()]);
    for s in &a.g.sets {
        v.extend(["--set".into(), shell_quote(s)]);
    }
    for (flag, val) in [("--partition", &a.partition), ("--time", &a.time), ("--mem", &a.mem), ("--account", &a.account)] {
        if let Some(val) = val {
            v.extend([flag.into(), shell_quote(val)]);
        }
    }
    if let Some(c) = a.cpus_per_task {
        v.extend(["--cpus-per-task".into(), c.to_string()]);
    }
    if let Some(c) = &a.g.cache {
        v.extend(["--cache".into(), shell_quote(&c.to_string_lossy())]);
    }
    v.extend(["--out".into(), shell_quote(&a.out.to_string_lossy())]);
    if a.submit {
        v.push("--submit".into());
    }
    v.join(" ")
}

/// The graph file's name without extension, reduced to characters safe in file and job names.
fn file_stem(graph: &Path) -> String {
    let s = graph.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let s: String = s.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' { c } else { '_' }).collect();
    if s.is_empty() {
        "graph".into()
    } else {
        s
    }
}

/// Quotes `s` as one word for bash: bare when it holds only characters no shell treats
/// specially, else in single quotes (a `'` inside written `'\''`).
pub(crate) fn shell_quote(s: &str) -> String {
    let safe = |c: char| c.is_ascii_alphanumeric() || "_-./=:,+@%".contains(c);
    if !s.is_empty() && s.chars().all(safe) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// Quotes `s` as one value on an `#SBATCH` line, which sbatch splits itself (not a shell):
/// bare when safe, else in double quotes with `\` and `"` escaped by a backslash.
pub(crate) fn sbatch_quote(s: &str) -> String {
    let safe = |c: char| c.is_ascii_alphanumeric() || "_-./=:,+@%".contains(c);
    if !s.is_empty() && s.chars().all(safe) {
        s.to_string()
    } else {
        format!("\"{}\"", s.replace('\\', r"\\").replace('"', r#"\""#))
    }
}

/// Runs `sbatch --parsable EXTRA SCRIPT` and returns the job id it prints.
fn sbatch(extra: &[String], script: &Path) -> Result<String, CliError> {
    let out = Command::new("sbatch").arg("--parsable").args(extra).arg(script).output().map_err(|e| {
        if e.kind() == std::io::ErrorKind::NotFound {
            CliError::run(
                "--submit needs Slurm's `sbatch`, which is not on PATH: run this on the cluster's login node, or drop --submit and submit the two scripts yourself",
            )
        } else {
            CliError::run(format!("cannot run sbatch: {e}"))
        }
    })?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        return Err(CliError::run(format!(
            "sbatch {} failed ({}): {}",
            script.display(),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    // `--parsable` prints `ID` or `ID;CLUSTER`.
    let id = stdout.trim().split(';').next().unwrap_or("").trim().to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        return Err(CliError::run(format!("sbatch {} printed {:?} where a job id was expected", script.display(), stdout.trim())));
    }
    Ok(id)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What bash makes of `words` (one word per line).
    fn bash_words(words: &str) -> Vec<String> {
        let out = Command::new("bash").arg("-c").arg(format!("printf '%s\\n' {words}")).output().expect("bash runs");
        String::from_utf8(out.stdout).unwrap().lines().map(String::from).collect()
    }

    #[test]
    fn shell_quoting_keeps_spaces_quotes_and_dollars_in_one_word() {
        let cases = ["plain/path.ron", "with space", "it's", "a \"b\" c", "$HOME `x` $(y)", "", "a\\b", "x;y|z&w", "tab\there", "'"];
        for s in cases {
            assert_eq!(bash_words(&shell_quote(s)), vec![s.to_string()], "{s:?} quoted as {}", shell_quote(s));
        }
        assert_eq!(shell_quote("/abs/path-1.ron"), "/abs/path-1.ron");
        assert_eq!(shell_quote("it's"), r"'it'\''s'");
        let two = format!("{} {}", shell_quote("a b"), shell_quote("c'd"));
        assert_eq!(bash_words(&two), vec!["a b".to_string(), "c'd".to_string()]);
    }

    #[test]
    fn sbatch_quoting_escapes_backslashes_and_double_quotes() {
        assert_eq!(sbatch_quote("/a/b-%A_%a.log"), "/a/b-%A_%a.log");
        assert_eq!(sbatch_quote("/a b/c.log"), "\"/a b/c.log\"");
        assert_eq!(sbatch_quote("/a\"b\\c"), r#""/a\"b\\c""#);
    }

    #[test]
    fn shard_counts_above_the_array_cap_or_zero_are_refused_with_a_way_out() {
        assert!(check_shard_count(1).is_ok());
        assert!(check_shard_count(MAX_ARRAY_TASKS).is_ok());
        let e = check_shard_count(MAX_ARRAY_TASKS + 1).err().unwrap();
        assert!(e.msg.contains("MaxArraySize") && e.msg.contains("smaller --shards"), "{}", e.msg);
        assert!(check_shard_count(0).is_err());
    }
}
