#!/usr/bin/env python3
"""Checks that the Python package's native module resolves every crate it builds with the same
features as the workspace's test build (`cargo test --workspace --release`), so that the wheel's
build (`pip install ./python`, which resolves relume-python's features alone) reuses the test
build's artifacts instead of compiling most of the tree again.

Each crate `cargo tree` lists for relume-python, with its features (one line per distinct set:
a crate built for the proc-macros' side and for the target appears twice when the two differ),
must appear with the same features in the workspace's tree (normal, build and dev edges, as
the test build unifies them). A missing line names the crate and features to turn on in
python/Cargo.toml. `--self-test` checks the comparison on a made-up pair of trees first.

    python3 tests/scripts/feature_unification.py [--self-test]
"""
import subprocess
import sys

FORMAT = "{p} [{f}]"


def tree(*args):
    """The set of `crate version [features]` lines `cargo tree` prints for `args`."""
    out = subprocess.run(["cargo", "tree", "--prefix", "none", "-f", FORMAT, *args], capture_output=True, text=True,
                         check=True).stdout
    return {line.removesuffix(" (*)").strip() for line in out.splitlines() if line.strip()}


def missing(package_lines, workspace_lines):
    """The package's lines the workspace's tree lacks, sorted."""
    return sorted(package_lines - workspace_lines)


def self_test():
    workspace = {"clap v4.6.7 [default,env,std]", "syn v3.0.9 [fold,full]", "syn v3.0.9 [full]"}
    assert missing({"clap v4.6.7 [default,env,std]", "syn v3.0.9 [full]"}, workspace) == []
    assert missing({"clap v4.6.7 [default,std]", "syn v3.0.9 [full]"}, workspace) == ["clap v4.6.7 [default,std]"]
    print("feature_unification: self-test passed")


def main():
    if "--self-test" in sys.argv[1:]:
        self_test()
    workspace = tree("--workspace", "-e", "normal,build,dev")
    package = tree("-p", "relume-python", "-e", "normal,build")
    lacking = missing(package, workspace)
    if lacking:
        print("relume-python resolves these crates with other features than the workspace's test build:")
        for line in lacking:
            print(f"  {line}")
        print("so `pip install ./python` would compile them, and every crate above them, again. Turn on in "
              "python/Cargo.toml the features the workspace's line for each crate has (`cargo tree --workspace "
              f"-e normal,build,dev --prefix none -f '{FORMAT}'`), under [build-dependencies] for crates of the "
              "proc-macros' side; clap's in nodes/cli/Cargo.toml, since only relume-cli may depend on it.")
        sys.exit(1)
    print(f"feature_unification: relume-python's {len(package)} crates resolve as in the workspace's test build")


if __name__ == "__main__":
    main()
