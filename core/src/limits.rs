//! The memory a run may really use. Physical memory is one bound; a container or a Slurm job
//! (its cgroup's `memory.max`), `ulimit -v` / `ulimit -d` (`RLIMIT_AS`, `RLIMIT_DATA`) and
//! Slurm's `--mem` / `--mem-per-cpu` (`SLURM_MEM_PER_NODE`, `SLURM_MEM_PER_CPU`) are others,
//! often far lower. A run's default budget is 80 % of the smallest of them, so that a request
//! over it is refused with its estimate before anything is allocated, instead of the process
//! being aborted or killed midway.

use crate::memory::fmt_bytes;
use std::path::{Path, PathBuf};

/// The default budget of a run: 80 % of the smallest memory limit the process runs under
/// (physical memory, its cgroup, `ulimit -v`/`-d`, Slurm's `--mem`). Read
/// once per process: every node run's context starts from it.
pub fn default_budget() -> u64 {
    default_budget_source().bytes
}

/// The default budget and what set it.
pub fn default_budget_source() -> &'static Budget {
    static BUDGET: std::sync::OnceLock<Budget> = std::sync::OnceLock::new();
    BUDGET.get_or_init(|| Limits::read().budget())
}

/// A run's memory budget and what set it, in words (`relume plan` shows both).
#[derive(Clone, Debug, PartialEq)]
pub struct Budget {
    pub bytes: u64,
    pub source: String,
}

/// The share of the smallest limit a run may plan to hold, in tenths: the rest is for the
/// program itself, its threads' stacks and the allocator's slack.
const TENTHS: u64 = 8;

/// Used where no limit can be read at all.
const FALLBACK: u64 = 8 << 30;

/// The limits this process runs under, each with what it is, where it could be read.
#[derive(Clone, Debug, Default)]
pub struct Limits {
    pub found: Vec<(u64, String)>,
}

impl Limits {
    /// Reads physical memory, the cgroup (v2, else v1), the two rlimits and Slurm's
    /// variables.
    pub fn read() -> Limits {
        let read = |p: &Path| std::fs::read_to_string(p).ok();
        let mut found = Vec::new();
        if let Some(kib) = read(Path::new("/proc/meminfo")).as_deref().and_then(meminfo_total_kib) {
            found.push((kib * 1024, "physical memory".to_string()));
        }
        if let Some(l) = read(Path::new("/proc/self/cgroup")).and_then(|c| cgroup_limit(&c, Path::new("/sys/fs/cgroup"), &read)) {
            found.push(l);
        }
        found.extend(rlimits());
        if let Some(l) = slurm_limit(&|k| std::env::var(k).ok()) {
            found.push(l);
        }
        Limits { found }
    }

    /// 80 % of the smallest limit found, and which it was.
    pub fn budget(&self) -> Budget {
        match self.found.iter().min_by_key(|(b, _)| *b) {
            Some((b, what)) => Budget { bytes: b / 10 * TENTHS, source: format!("{} % of {what}: {}", TENTHS * 10, fmt_bytes(*b)) },
            None => Budget { bytes: FALLBACK, source: "no memory limit could be read; a fixed 8 GiB".into() },
        }
    }
}

/// `MemTotal` of `/proc/meminfo`, in KiB.
fn meminfo_total_kib(text: &str) -> Option<u64> {
    text.lines().find(|l| l.starts_with("MemTotal:"))?.split_whitespace().nth(1)?.parse().ok()
}

/// The tightest memory limit of this process's cgroup and the cgroups above it: v2's
/// `memory.max` along the path of the `0::` line of `/proc/self/cgroup`, else v1's
/// `memory.limit_in_bytes` of the `memory` controller's path. `read` reads a file under `root`.
fn cgroup_limit(proc_cgroup: &str, root: &Path, read: &dyn Fn(&Path) -> Option<String>) -> Option<(u64, String)> {
    let number = |s: Option<String>| s.and_then(|t| t.trim().parse::<u64>().ok());
    let along = |base: PathBuf, rel: &str, file: &str, what: &str| -> Option<(u64, String)> {
        let mut dir = base.clone();
        let mut best: Option<(u64, String)> = None;
        let mut consider = |d: &Path| {
            // v1 reports "no limit" as a huge number (near 2^63): such values are none.
            if let Some(b) = number(read(&d.join(file))).filter(|&b| b < 1 << 60) {
                if best.as_ref().is_none_or(|(x, _)| b < *x) {
                    best = Some((b, format!("the cgroup's {what} ({})", d.join(file).display())));
                }
            }
        };
        consider(&dir);
        for part in rel.split('/').filter(|p| !p.is_empty()) {
            dir.push(part);
            consider(&dir);
        }
        best
    };
    let lines: Vec<&str> = proc_cgroup.lines().collect();
    if let Some(rel) = lines.iter().find_map(|l| l.strip_prefix("0::")) {
        if let Some(l) = along(root.to_path_buf(), rel, "memory.max", "memory.max") {
            return Some(l);
        }
    }
    let v1 = lines.iter().find_map(|l| {
        let mut parts = l.splitn(3, ':');
        let (_, controllers, path) = (parts.next()?, parts.next()?, parts.next()?);
        controllers.split(',').any(|c| c == "memory").then_some(path)
    })?;
    along(root.join("memory"), v1, "memory.limit_in_bytes", "memory.limit_in_bytes")
}

/// `RLIMIT_AS` (`ulimit -v`) and `RLIMIT_DATA` (`ulimit -d`), where set.
fn rlimits() -> Vec<(u64, String)> {
    let mut out = Vec::new();
    for (res, what) in [(libc::RLIMIT_AS, "RLIMIT_AS (ulimit -v)"), (libc::RLIMIT_DATA, "RLIMIT_DATA (ulimit -d)")] {
        let mut r = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
        // SAFETY: getrlimit writes the struct it is given and nothing else.
        if unsafe { libc::getrlimit(res, &mut r) } == 0 && r.rlim_cur != libc::RLIM_INFINITY {
            #[allow(clippy::unnecessary_cast)] // rlim_t is not u64 on every target
            out.push((r.rlim_cur as u64, what.to_string()));
        }
    }
    out
}

/// Slurm's memory for this job on this node: `SLURM_MEM_PER_NODE` (MiB), else
/// `SLURM_MEM_PER_CPU` (MiB) times the CPUs the job has here (`SLURM_CPUS_ON_NODE`, else
/// `SLURM_CPUS_PER_TASK`, else 1).
fn slurm_limit(env: &dyn Fn(&str) -> Option<String>) -> Option<(u64, String)> {
    let num = |k: &str| env(k).and_then(|v| v.trim().parse::<u64>().ok()).filter(|&v| v > 0);
    if let Some(mb) = num("SLURM_MEM_PER_NODE") {
        return Some((mb << 20, "Slurm's SLURM_MEM_PER_NODE (--mem)".into()));
    }
    let mb = num("SLURM_MEM_PER_CPU")?;
    let cpus = num("SLURM_CPUS_ON_NODE").or_else(|| num("SLURM_CPUS_PER_TASK")).unwrap_or(1);
    Some(((mb << 20) * cpus, format!("Slurm's SLURM_MEM_PER_CPU (--mem-per-cpu) × {cpus} CPUs")))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    #[test]
    fn the_budget_is_80_percent_of_the_smallest_limit_and_names_it() {
        let l = Limits { found: vec![(32 << 30, "physical memory".into()), (6 << 30, "RLIMIT_AS (ulimit -v)".into())] };
        let b = l.budget();
        assert_eq!(b.bytes, (6u64 << 30) / 10 * 8);
        assert_eq!(b.source, "80 % of RLIMIT_AS (ulimit -v): 6.00 GiB");
        assert_eq!(Limits::default().budget().bytes, 8 << 30);
        assert!(default_budget() > 0 && !default_budget_source().source.is_empty());
        assert_eq!(meminfo_total_kib("MemTotal:       24576000 kB\nMemFree: 1 kB\n"), Some(24_576_000));
    }

    fn files(entries: &[(&str, &str)]) -> impl Fn(&Path) -> Option<String> {
        let m: HashMap<PathBuf, String> = entries.iter().map(|(p, t)| (PathBuf::from(p), t.to_string())).collect();
        move |p: &Path| m.get(p).cloned()
    }

    #[test]
    fn a_cgroup_limit_is_the_tightest_along_its_path_in_v2_and_v1() {
        let root = Path::new("/cg");
        // v2: the job's own cgroup says max, its parent 6 GiB, the slice above 16 GiB.
        let v2 = files(&[
            ("/cg/memory.max", "max\n"),
            ("/cg/system.slice/memory.max", "17179869184\n"),
            ("/cg/system.slice/job_7/memory.max", "6442450944\n"),
            ("/cg/system.slice/job_7/step_0/memory.max", "max\n"),
        ]);
        let (b, what) = cgroup_limit("0::/system.slice/job_7/step_0\n", root, &v2).unwrap();
        assert_eq!(b, 6 << 30);
        assert!(what.contains("memory.max") && what.contains("job_7"), "{what}");
        // No limit anywhere: none.
        assert_eq!(cgroup_limit("0::/user.slice\n", root, &files(&[("/cg/user.slice/memory.max", "max")])), None);
        // v1: the memory controller's line; "no limit" is a number near 2^63.
        let v1 = files(&[
            ("/cg/memory/memory.limit_in_bytes", "9223372036854771712\n"),
            ("/cg/memory/slurm/uid_1/job_9/memory.limit_in_bytes", "4294967296\n"),
        ]);
        let (b, _) = cgroup_limit("12:cpu,cpuacct:/slurm\n11:memory:/slurm/uid_1/job_9\n", root, &v1).unwrap();
        assert_eq!(b, 4 << 30);
    }

    #[test]
    fn slurm_memory_comes_per_node_or_per_cpu_times_the_cpus() {
        let env =
            |pairs: &'static [(&'static str, &'static str)]| move |k: &str| pairs.iter().find(|(n, _)| *n == k).map(|(_, v)| v.to_string());
        assert_eq!(slurm_limit(&env(&[("SLURM_MEM_PER_NODE", "4096")])).unwrap().0, 4 << 30);
        let (b, what) = slurm_limit(&env(&[("SLURM_MEM_PER_CPU", "1000"), ("SLURM_CPUS_ON_NODE", "4")])).unwrap();
        assert_eq!((b, what.contains("× 4 CPUs")), (4000 << 20, true));
        assert_eq!(slurm_limit(&env(&[("SLURM_MEM_PER_CPU", "512")])).unwrap().0, 512 << 20);
        assert_eq!(slurm_limit(&env(&[("SLURM_JOB_ID", "5")])), None);
        assert_eq!(slurm_limit(&env(&[("SLURM_MEM_PER_NODE", "0")])), None);
    }
}
