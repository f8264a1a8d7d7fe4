//! What the command line prints: every line goes through these macros, which escape control
//! and bidirectional characters (`relume_core::printable`), so that a node id, kind or path
//! taken from a graph cannot act on the terminal; errors and warnings also cut a line too long
//! to read (`relume_core::clipped`).

/// `println!`, escaped.
macro_rules! say {
    () => { println!() };
    ($($t:tt)*) => { println!("{}", relume_core::printable(&format!($($t)*))) };
}

/// `print!`, escaped.
macro_rules! say_part {
    ($($t:tt)*) => { print!("{}", relume_core::printable(&format!($($t)*))) };
}

/// `eprintln!`, escaped, and a line too long to read cut in the middle (`relume_core::clipped`:
/// errors and warnings quote paths and values from the input).
macro_rules! say_err {
    () => { eprintln!() };
    ($($t:tt)*) => { eprintln!("{}", relume_core::printable(&relume_core::clipped(&format!($($t)*)))) };
}
