//! `relume run --processes N`: starts N copies of this command as `--workers HOSTFILE
//! --process I` on 127.0.0.1 (free ports, a temporary host file, one shared cache folder),
//! waits for them, and when one dies — timely then stops them all — runs them again: the
//! chunks that finished are in the cache, so the re-run computes only the missing ones.

use crate::args::RunArgs;
use crate::error::CliError;
use crate::interrupt;
use std::ffi::OsString;
use std::net::TcpListener;
use std::process::{Child, Command, ExitStatus};
use std::time::{Duration, Instant};

/// How one attempt ended.
enum Outcome {
    Finished,
    /// A process failed: what happened, and whether running again can help.
    Failed {
        what: String,
        retry: bool,
    },
}

pub(crate) fn launch(reg: &relume_core::Registry, a: &RunArgs) -> Result<(), CliError> {
    let n = a.cluster.processes.expect("--processes");
    if !(1..=64).contains(&n) {
        return Err(CliError::graph(format!("--processes {n}: give 1 to 64 local processes")));
    }
    // A graph that does not load is said once, here, rather than by every process.
    a.g.load(reg)?;
    let exe = std::env::var_os("RELUME_BIN").map(Into::into).or_else(|| std::env::current_exe().ok());
    let exe = exe.ok_or_else(|| CliError::run("cannot find the relume executable to start the processes (set RELUME_BIN)"))?;
    let args = child_args(&crate::args::command_line());
    let shared = !a.g.no_disk_cache;
    let mut attempt = 0;
    loop {
        match run_once(&exe, &args, n, shared, a.quiet)? {
            Outcome::Finished => {
                if attempt > 0 && !a.quiet {
                    say_err!("relume: all {n} processes finished after {attempt} re-run(s)");
                }
                return Ok(());
            }
            Outcome::Failed { what, retry } => {
                if !retry || attempt >= a.cluster.retries {
                    let tries = if attempt > 0 { format!(" (after {attempt} re-run(s))") } else { String::new() };
                    return Err(CliError::run(format!("{what}{tries}; chunks that finished are in the cache: the same command resumes")));
                }
                attempt += 1;
                say_err!(
                    "relume: {what}; timely stops every process when one dies: running all {n} again (re-run {attempt} of {}); \
                     chunks already in the cache are not computed again",
                    a.cluster.retries
                );
            }
        }
    }
}

/// The command line without `--processes N` / `--retries N` (the children are told
/// `--workers` and `--process` instead).
fn child_args(all: &[OsString]) -> Vec<OsString> {
    let mut out = Vec::new();
    let mut skip = false;
    for a in all.iter().skip(1) {
        if std::mem::take(&mut skip) {
            continue;
        }
        let s = a.to_string_lossy();
        if s == "--processes" || s == "--retries" {
            skip = true;
        } else if !(s.starts_with("--processes=") || s.starts_with("--retries=")) {
            out.push(a.clone());
        }
    }
    out
}

/// Free ports on 127.0.0.1, held until all are chosen so that they differ.
fn free_ports(n: usize) -> Result<Vec<u16>, CliError> {
    let listeners: Vec<TcpListener> = (0..n)
        .map(|_| TcpListener::bind("127.0.0.1:0"))
        .collect::<Result<_, _>>()
        .map_err(|e| CliError::run(format!("cannot find free local ports: {e}")))?;
    Ok(listeners.iter().map(|l| l.local_addr().map(|a| a.port()).unwrap_or(0)).collect())
}

fn run_once(exe: &std::path::Path, args: &[OsString], n: usize, shared: bool, quiet: bool) -> Result<Outcome, CliError> {
    let ports = free_ports(n)?;
    let hostfile = std::env::temp_dir().join(format!("relume-hosts-{}-{}.txt", std::process::id(), ports[0]));
    let text: String = ports.iter().map(|p| format!("127.0.0.1:{p}\n")).collect();
    std::fs::write(&hostfile, text).map_err(|e| CliError::run(format!("cannot write the host file {}: {e}", hostfile.display())))?;
    let mut children: Vec<Option<Child>> = Vec::with_capacity(n);
    for i in 0..n {
        let mut cmd = Command::new(exe);
        cmd.args(args).arg("--workers").arg(&hostfile).arg("--process").arg(i.to_string());
        if shared {
            cmd.arg("--shared-cache");
        }
        if i > 0 && !quiet {
            cmd.arg("--quiet");
        }
        if quiet {
            // The transport prints its connection progress on standard output; `--quiet`
            // means nothing there.
            cmd.stdout(std::process::Stdio::null());
        }
        match cmd.spawn() {
            Ok(c) => children.push(Some(c)),
            Err(e) => {
                children.iter_mut().flatten().for_each(|c| drop(c.kill()));
                let _ = std::fs::remove_file(&hostfile);
                return Err(CliError::run(format!("cannot start process {i} ({}): {e}", exe.display())));
            }
        }
    }
    let outcome = wait_all(&mut children, GRACE);
    let _ = std::fs::remove_file(&hostfile);
    Ok(outcome)
}

/// How long the other processes get, once one has failed, to stop by themselves (timely stops
/// them when they next exchange results) before they are killed. A killed process loses at
/// most the chunk it was computing: finished chunks are in the cache.
const GRACE: Duration = Duration::from_secs(10);

/// Waits for every child. Once one has failed, the others get `grace` to notice before they
/// are killed.
fn wait_all(children: &mut [Option<Child>], grace: Duration) -> Outcome {
    let mut failures: Vec<(usize, ExitStatus)> = Vec::new();
    let mut first_failure: Option<Instant> = None;
    while children.iter().any(Option::is_some) {
        for (i, slot) in children.iter_mut().enumerate() {
            let Some(child) = slot else { continue };
            if let Ok(Some(status)) = child.try_wait() {
                if !status.success() {
                    failures.push((i, status));
                    first_failure.get_or_insert_with(Instant::now);
                }
                *slot = None;
            }
        }
        if first_failure.is_some_and(|t| t.elapsed() > grace) {
            for child in children.iter_mut().flatten() {
                let _ = child.kill();
                let _ = child.wait();
            }
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    let Some(&(first, status)) = failures.first() else { return Outcome::Finished };
    let code = status.code();
    let what = match code {
        Some(c) => format!("process {first} exited with code {c}"),
        None => format!("process {first} was killed ({})", describe_signal(&status)),
    };
    // Bad input (2) and Ctrl-C (130) fail the same way again: no re-run.
    let retry = !failures.iter().any(|(_, s)| matches!(s.code(), Some(2) | Some(interrupt::EXIT_CODE)));
    Outcome::Failed { what, retry }
}

fn describe_signal(status: &ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match status.signal() {
        Some(9) => "SIGKILL".into(),
        Some(15) => "SIGTERM".into(),
        Some(s) => format!("signal {s}"),
        None => "no exit code".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_children_get_the_command_without_the_launcher_s_flags() {
        let all: Vec<OsString> =
            ["relume", "run", "g.ron", "--processes", "3", "--retries=1", "--set", "a.b=1", "--processes=2"].map(Into::into).into();
        assert_eq!(child_args(&all), ["run", "g.ron", "--set", "a.b=1"].map(OsString::from).to_vec());
    }

    #[test]
    fn free_ports_differ() {
        let Ok(p) = free_ports(4) else { panic!("no free ports") };
        let mut q = p.clone();
        q.sort_unstable();
        q.dedup();
        assert_eq!(q.len(), 4, "{p:?}");
    }
}
