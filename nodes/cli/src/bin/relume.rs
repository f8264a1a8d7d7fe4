//! The `relume` command-line tool.

fn main() {
    // Rust ignores SIGPIPE, so `relume nodes | head` would panic in `println!` once `head`
    // has read enough; a command-line tool ends quietly there, as Unix tools do. (Sockets are
    // unaffected: std writes to them with MSG_NOSIGNAL, so a dead peer is still an error.)
    #[cfg(unix)]
    // SAFETY: restoring a signal's default disposition at start-up, before any thread exists.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
    std::process::exit(relume_cli::main());
}
