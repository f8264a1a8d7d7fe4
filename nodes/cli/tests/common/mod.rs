//! What the binary tests share: running `relume` under a shell prelude that sets a limit.

use std::ffi::OsStr;
use std::process::Command;

/// `relume ARGS` started by `sh -c "PRELUDE; exec relume ARGS"` (a `ulimit`, joining a
/// cgroup), without `RELUME_CACHE`: (exit code, stdout, stderr).
pub fn relume_after(prelude: &str, args: &[&OsStr]) -> (Option<i32>, String, String) {
    let out = Command::new("sh")
        .arg("-c")
        .arg(format!("{prelude}; exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_relume"))
        .args(args)
        .env_remove("RELUME_CACHE")
        .output()
        .unwrap();
    (out.status.code(), String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned())
}
