//! Under a real cgroup memory limit, where this machine lets a test make one (root and a
//! writable memory controller: v2's `memory.max` or v1's `memory.limit_in_bytes`), the filters
//! graph at 6000² is refused with the estimate and the cgroup named as the source of the
//! budget, before anything is allocated. Where no cgroup can be made the test says why and
//! passes: `binary.rs` checks the same refusal under `ulimit -v`.

use std::ffi::OsStr;
use std::path::{Path, PathBuf};

mod common;

/// A memory cgroup made for one test, removed when dropped (its processes have exited).
struct Cgroup {
    dir: PathBuf,
}

impl Cgroup {
    /// A new cgroup limited to `bytes`, v2 where the memory controller is there, else v1.
    fn make(bytes: u64) -> Result<Cgroup, String> {
        let name = format!("relume-test-{}", std::process::id());
        let v2 = Path::new("/sys/fs/cgroup");
        let v2_memory =
            std::fs::read_to_string(v2.join("cgroup.subtree_control")).is_ok_and(|c| c.split_whitespace().any(|x| x == "memory"));
        let (dir, file) = if v2_memory { (v2.join(&name), "memory.max") } else { (v2.join("memory").join(&name), "memory.limit_in_bytes") };
        std::fs::create_dir(&dir).map_err(|e| format!("cannot make the cgroup {}: {e}", dir.display()))?;
        let cg = Cgroup { dir };
        std::fs::write(cg.dir.join(file), bytes.to_string()).map_err(|e| format!("cannot limit {}: {e}", cg.dir.display()))?;
        Ok(cg)
    }

    /// `relume ARGS` run inside the cgroup: (exit code, stdout, stderr); exit code 77 when the
    /// process could not be moved into it (a container may let a cgroup be made, not joined).
    fn relume(&self, args: &[&str]) -> (Option<i32>, String, String) {
        let procs = self.dir.join("cgroup.procs");
        let args: Vec<&OsStr> = args.iter().map(OsStr::new).collect();
        common::relume_after(&format!("echo $$ > '{}' 2>/dev/null || exit 77", procs.display()), &args)
    }
}

impl Drop for Cgroup {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir(&self.dir);
    }
}

#[test]
fn under_a_cgroup_memory_limit_a_run_past_it_is_refused_naming_the_cgroup() {
    let cg = match Cgroup::make(3_000_000 * 1024) {
        Ok(cg) => cg,
        Err(why) => {
            eprintln!("skipped: {why} (the refusal under a limit is checked with ulimit -v in binary.rs)");
            return;
        }
    };
    let dir = tempfile::tempdir().unwrap();
    let g = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../graphs/filters.ron").display().to_string();
    let out = dir.path().join("o").display().to_string();
    let mut args = vec!["run", &g, "--out", &out, "--no-disk-cache"];
    for s in ["clean.width=6000", "clean.height=6000", "noisy.width=6000", "noisy.height=6000"] {
        args.extend(["--set", s]);
    }
    let (code, _, err) = cg.relume(&args);
    if code == Some(77) {
        eprintln!("skipped: cannot move a process into {}", cg.dir.display());
        return;
    }
    assert_eq!(code, Some(2), "refused as bad input, not killed: {err}");
    let source = format!(
        "80 % of the cgroup's {}",
        if cg.dir.starts_with("/sys/fs/cgroup/memory") { "memory.limit_in_bytes" } else { "memory.max" }
    );
    assert!(
        err.contains("over the memory budget of 2.29 GiB") && err.contains(&source) && err.contains(&cg.dir.display().to_string()),
        "{err}"
    );
    assert!(!dir.path().join("o/image.png").exists(), "nothing ran");
    let (code, plan, err) = cg.relume(&["plan", &g, "--no-disk-cache"]);
    assert_eq!(code, Some(0), "{err}");
    assert!(plan.contains("memory budget 2.29 GiB (") && plan.contains(&source), "{plan}");
}
