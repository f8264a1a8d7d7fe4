"""Shared fixtures: the repository's graphs and the command-line binary the tests compare
with (``$RELUME``, else ``target/release/relume``, which the README's test command builds)."""

import os
import pathlib
import shutil
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[2]
GRAPHS = ROOT / "graphs"


@pytest.fixture
def relume_bin():
    path = pathlib.Path(os.environ.get("RELUME", ROOT / "target" / "release" / "relume"))
    if not path.exists():
        pytest.skip(f"no relume binary at {path}: build it (cargo build --release) or set RELUME")
    return path


@pytest.fixture
def filters(tmp_path):
    """filters.ron copied into a fresh folder (its outputs and cache stay there)."""
    shutil.copy(GRAPHS / "filters.ron", tmp_path / "filters.ron")
    return tmp_path / "filters.ron"


def cli(relume_bin, *args, cwd=None):
    """Runs the command line; its completed process (stdout and stderr as text)."""
    return subprocess.run([str(relume_bin), *map(str, args)], capture_output=True, text=True, cwd=cwd)
