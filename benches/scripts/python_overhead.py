#!/usr/bin/env python3
"""The Python package's overhead on a warm edit: `g.set(...)` then `g.run()` from Python
against the same set-and-run done by the engine in Rust (`relume._relume._time_edits`, in the
same process), in alternating rounds of one run. Prints the medians, their ratio and their
difference, and appends a row to docs/results/table_python_overhead.csv (with the date, machine,
threads and commit) unless --no-record; `relume results` draws docs/guide/python.md's table from it.

usage: python benches/scripts/python_overhead.py [GRAPH] [NODE.PARAM] [--edits N] [--rounds R] [--no-record]
       (default graphs/filters.ron blur.sigma, 200 edits a round, 5 rounds; needs the
       package installed: pip install ./python)
"""
import argparse
import os
import statistics
import time

import relume
from relume import _relume

from provenance import COLUMNS, append_rows, cells

RESULTS = os.path.join("docs", "results", "table_python_overhead.csv")
HEADER = ["graph", "param", "edits", "rounds", "rust_ms", "python_ms", "ratio", "difference_ms", *COLUMNS]


def python_edits(path, assignment, values, outputs):
    g = relume.Graph.load(path, no_disk_cache=True)
    g.run(outputs, progress=False)
    times = []
    for v in values:
        t0 = time.perf_counter()
        g.set(assignment, v)
        g.run(outputs, progress=False)
        times.append((time.perf_counter() - t0) * 1e3)
    return times


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("graph", nargs="?", default="graphs/filters.ron")
    ap.add_argument("param", nargs="?", default="blur.sigma")
    ap.add_argument("--edits", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--output", action="append", help="outputs to run (default: all)")
    ap.add_argument("--low", type=float, default=0.5)
    ap.add_argument("--high", type=float, default=3.0)
    ap.add_argument("--no-record", action="store_true", help=f"print only, do not append to {RESULTS}")
    a = ap.parse_args()
    rust, py = [], []
    for r in range(a.rounds):
        # Values no earlier edit of the round used, different between rounds and sides.
        step = (a.high - a.low) / (a.edits * 2 * a.rounds + 1)
        values = [a.low + step * (1 + 2 * (r * a.edits + i)) for i in range(a.edits)]
        rust.append(statistics.median(_relume._time_edits(a.graph, a.param, values, a.output)))
        py.append(statistics.median(python_edits(a.graph, a.param, [v + step for v in values], a.output)))
        print(f"round {r + 1}: engine in Rust {rust[-1]:.3f} ms, from Python {py[-1]:.3f} ms")
    rm, pm = statistics.median(rust), statistics.median(py)
    print(f"median of the rounds' medians: Rust {rm:.3f} ms, Python {pm:.3f} ms, "
          f"ratio {pm / rm:.3f}, difference {pm - rm:.3f} ms")
    if a.no_record:
        return
    append_rows(RESULTS, HEADER, [[a.graph, a.param, a.edits, a.rounds, f"{rm:.4f}", f"{pm:.4f}", f"{pm / rm:.4f}",
                                   f"{pm - rm:.4f}", *cells()]])


if __name__ == "__main__":
    main()
