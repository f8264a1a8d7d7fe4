//! The error a command ends with: a message for the user and the exit code that goes with it.

/// An error for the user and the exit code that goes with it.
#[derive(Debug)]
pub(crate) struct CliError {
    pub code: i32,
    pub msg: String,
}

impl CliError {
    pub fn graph(msg: impl ToString) -> Self {
        CliError { code: 2, msg: msg.to_string() }
    }
    pub fn run(msg: impl ToString) -> Self {
        CliError { code: 1, msg: msg.to_string() }
    }
    /// Stopped by Ctrl-C (exit code 130, as a shell reports SIGINT).
    pub fn interrupted(msg: impl ToString) -> Self {
        CliError { code: crate::interrupt::EXIT_CODE, msg: msg.to_string() }
    }
}
