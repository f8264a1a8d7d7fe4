//! Every graph of `graphs/` at test size (the sizes of `determinism.rs`), each output's encoded
//! bytes hashed with blake3 and printed a line each: `graph output digest`. Run it before and
//! after a change that must not alter any result, and compare the two listings:
//! `cargo test --release -p relume-tests --test output_digests -- --ignored --nocapture`
//! (`RELUME_DIGESTS=FILE` also writes the listing to FILE).

use relume_core::{Engine, RunOptions};
use relume_tests::{all_graphs, at_test_size};

#[test]
#[ignore = "a listing to compare by hand across a change; run with --ignored"]
fn output_digests() {
    let mut listing = String::new();
    for path in all_graphs() {
        let g = at_test_size(&path);
        let e = Engine::new(relume_cli::registry()).with_threads(2).with_parallelism(2);
        let r = e.run(&g, &RunOptions::default()).unwrap_or_else(|err| panic!("{}: {err}", path.display()));
        let name = path.file_name().unwrap().to_string_lossy();
        for (out, v) in &r.outputs {
            listing += &format!("{name} {out} {}\n", blake3::hash(&v.encode()).to_hex());
        }
    }
    print!("{listing}");
    if let Ok(file) = std::env::var("RELUME_DIGESTS") {
        std::fs::write(file, &listing).unwrap();
    }
}
