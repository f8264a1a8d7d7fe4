//! The `relume` command-line tool.

fn main() {
    std::process::exit(relume_nodes::cli::main());
}
