"""The native crate's documentation example (the ```python block of python/src/lib.rs's crate
doc) runs as written, so the example rustdoc shows cannot go stale."""

import os
import re

from conftest import ROOT


def test_the_crate_doc_example_runs(monkeypatch):
    doc = "\n".join(
        line[4:] if line.startswith("//! ") else line[3:]
        for line in (ROOT / "python" / "src" / "lib.rs").read_text().splitlines()
        if line.startswith("//!")
    )
    blocks = re.findall(r"```python\n(.*?)```", doc, re.S)
    assert len(blocks) == 1, f"{len(blocks)} python blocks in the crate doc"
    monkeypatch.chdir(ROOT)
    exec(compile(blocks[0], "python/src/lib.rs (crate doc)", "exec"), {})
