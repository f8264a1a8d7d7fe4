#!/usr/bin/env python3
"""Drives an edit in the editor's real window and keeps the rates as data: runs
`relume-editor GRAPH --drive NODE.PARAM=FROM:TO --drive-seconds 10 --record …` under Xvfb with
software OpenGL (as CI does) RUNS times, reads what each drive prints (frames and new images a
second, edit to pixels, the run's median, and the same edit through the engine alone) and
appends one row a drive to docs/results/table_editor_drag_rates.csv, with the date, machine,
threads and commit. `relume results` draws the editor guide's table from it.

usage: python3 benches/scripts/record_drive.py GRAPH NODE.PARAM=FROM:TO [--set NODE.PARAM=VALUE]
           [--viewer-only] [--runs 3] [--editor target/release/relume-editor] [--no-record]
       (run from the repository's root, with the release editor built and the graph's
       precompute in the disk cache: a drive times edits, not a first run)
"""
import argparse
import os
import re
import subprocess
import tempfile

from provenance import COLUMNS, append_rows, cells

RESULTS = os.path.join("docs", "results", "table_editor_drag_rates.csv")
HEADER = ["graph", "edit", "setting", "layout", "run", "frames_per_s", "images_per_s", "latency_median_ms", "run_median_ms",
          "engine_alone_edits_per_s", "engine_alone_median_ms", *COLUMNS]
WINDOW = re.compile(r"window: .*?\(([0-9.]+)/s,.*?new images \(([0-9.]+)/s\), edit to pixels median ([0-9.]+) ms.*?run median ([0-9.]+) ms")
ALONE = re.compile(r"engine alone: .*?: ([0-9.]+) edits/s, median ([0-9.]+) ms per edit")


def drive(a, record):
    cmd = ["xvfb-run", "-a", "-s", "-screen 0 1400x900x24", a.editor, a.graph, "--drive", a.edit, "--drive-seconds", "10",
           "--record", record]
    cmd += ["--viewer-only"] if a.viewer_only else []
    for s in a.set:
        cmd += ["--set", s]
    out = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "LIBGL_ALWAYS_SOFTWARE": "1"}, timeout=600)
    text = out.stdout + out.stderr
    w, e = WINDOW.search(text), ALONE.search(text)
    if out.returncode != 0 or not w or not e:
        raise SystemExit(f"the drive did not finish as expected (exit {out.returncode}):\n{text[-2000:]}")
    return [*w.groups(), *e.groups()]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("graph")
    ap.add_argument("edit", help="NODE.PARAM=FROM:TO, as --drive takes it")
    ap.add_argument("--set", action="append", default=[])
    ap.add_argument("--viewer-only", action="store_true")
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--editor", default=os.path.join("target", "release", "relume-editor"))
    ap.add_argument("--no-record", action="store_true", help=f"print only, do not append to {RESULTS}")
    a = ap.parse_args()
    name = os.path.splitext(os.path.basename(a.graph))[0]
    param, span = a.edit.split("=", 1)
    edit = f"{param} {span.replace(':', '..')}"
    setting = "; ".join(a.set) or "as shipped"
    layout = "viewer only" if a.viewer_only else "full"
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in range(1, a.runs + 1):
            frames, images, latency, run, alone, alone_ms = drive(a, os.path.join(tmp, f"drive{r}.csv"))
            print(f"{name} {edit} ({setting}, {layout}) drive {r}: {images} images/s, {frames} frames/s, edit to pixels "
                  f"{latency} ms, run {run} ms; engine alone {alone} edits/s")
            rows.append([name, edit, setting, layout, r, frames, images, latency, run, alone, alone_ms, *cells()])
    if a.no_record:
        return
    append_rows(RESULTS, HEADER, rows)


if __name__ == "__main__":
    main()
