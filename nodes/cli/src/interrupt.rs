//! Ctrl-C. The first cancels the run under way through its `CancelToken`: nodes stop at their
//! next check, the executor keeps only whole results (the disk cache writes whole files and
//! renames them into place) and the command exits 130 without writing outputs. A second
//! Ctrl-C exits at once; a write it cuts short leaves at most a temporary file, which the
//! next `DiskCache` opened on that folder sweeps away.

use relume_core::CancelToken;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// The exit code of an interrupted command (a shell's 128 + SIGINT).
pub(crate) const EXIT_CODE: i32 = 130;

/// The token of the command under way, if one is cancellable now.
static CURRENT: Mutex<Option<CancelToken>> = Mutex::new(None);
static PRESSES: AtomicUsize = AtomicUsize::new(0);

/// Installs the handler (once per process; the binary calls it first thing).
pub(crate) fn install() {
    // Fails only when a handler is already installed, which is then this one.
    let _ = ctrlc::set_handler(on_interrupt);
}

fn on_interrupt() {
    let presses = PRESSES.fetch_add(1, Ordering::SeqCst) + 1;
    let token = CURRENT.lock().map(|c| c.clone()).unwrap_or(None);
    match token {
        Some(t) if presses == 1 => {
            say_err!("\ninterrupted: cancelling… (press Ctrl-C again to quit at once)");
            t.cancel();
        }
        Some(_) => {
            say_err!("\ninterrupted again: exiting now");
            std::process::exit(EXIT_CODE);
        }
        None => {
            say_err!("\ninterrupted");
            std::process::exit(EXIT_CODE);
        }
    }
}

/// A cancellation token that Ctrl-C cancels while the guard lives.
pub(crate) struct Watch {
    pub token: CancelToken,
}

impl Watch {
    pub fn new() -> Self {
        let token = CancelToken::new();
        if let Ok(mut c) = CURRENT.lock() {
            *c = Some(token.clone());
        }
        Watch { token }
    }

    pub fn interrupted(&self) -> bool {
        self.token.is_cancelled()
    }
}

impl Drop for Watch {
    fn drop(&mut self) {
        if let Ok(mut c) = CURRENT.lock() {
            *c = None;
        }
    }
}
