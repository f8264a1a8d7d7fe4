#!/usr/bin/env python3
"""Measures one divan benchmark and keeps its figures as data: runs
`cargo bench -p relume-benches --bench BENCH -- FILTER...`, reads divan's table (every case's
fastest, slowest, median and mean, its samples and iterations) and writes it, one row a case,
with the date, machine, threads and commit of the measurement, to
docs/results/bench_NAME.csv, and what the benchmark prints itself (counts, errors measured in
the same run) to docs/results/bench_NAME.txt. `relume results` draws the book's tables from
such files.

usage: python3 benches/scripts/record_bench.py BENCH NAME [FILTER ...] [--from-output FILE]
       (run from the repository's root; --from-output reads a saved divan output instead of
       running cargo, for a measurement already made: the bench binary's stderr, what the
       benchmark printed, first, then its stdout)
"""
import argparse
import csv
import os
import re
import subprocess
import sys
import time

from provenance import COLUMNS, cells

UNITS = {"ns": 1e-6, "µs": 1e-3, "us": 1e-3, "ms": 1.0, "s": 1e3}
TREE = "├╰─│ "


def to_ms(cell):
    m = re.fullmatch(r"\s*([0-9.]+)\s*(ns|µs|us|ms|s)\s*", cell)
    return float(m.group(1)) * UNITS[m.group(2)] if m else None


RATE = {"": 1.0, "K": 1e3, "M": 1e6, "G": 1e9}


def to_rate(cell):
    """A counter's rate cell (`7.674 Mitem/s`) as items per second, else None."""
    m = re.fullmatch(r"\s*([0-9.]+)\s*([KMG]?)item/s\s*", cell)
    return float(m.group(1)) * RATE[m.group(2)] if m else None


def parse(text):
    """The cases of divan's table: (path, fastest, slowest, median, mean, samples, iters, items
    a second at the median or None), the path joining the tree's names with '/'. A case with
    an item counter has a second line of rates under it. Lines the benchmarks print themselves
    are skipped."""
    rows, stack = [], []
    for line in text.splitlines():
        if "│" not in line:
            continue
        # The tree's drawing, then the cells: the name (and a case's fastest time), slowest,
        # median, mean, samples, iterations.
        body = line.lstrip(TREE)
        depth = (len(line) - len(body)) // 3
        cells = body.split("│")
        if len(cells) != 6:
            continue
        if rows and to_rate(cells[0]) is not None and rows[-1][7] is None:
            rows[-1] = rows[-1][:7] + (to_rate(cells[2]),)
            continue
        parts = cells[0].split()
        if not parts or parts[0] == "fastest":
            continue
        # The first cell holds the name, then (for a case) the fastest time.
        name = parts[0]
        fastest = to_ms(" ".join(parts[1:])) if len(parts) > 1 else None
        del stack[depth:]
        stack.append(name)
        if fastest is None:
            continue
        slowest, median, mean = (to_ms(c) for c in cells[1:4])
        samples, iters = (int(c.strip()) for c in cells[4:6])
        rows.append(("/".join(stack[1:]) if len(stack) > 1 else stack[0], fastest, slowest, median, mean, samples, iters, None))
    return rows


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("bench")
    ap.add_argument("name")
    ap.add_argument("filters", nargs="*")
    ap.add_argument("--from-output")
    a = ap.parse_args()
    notes = []
    if a.from_output:
        text = open(a.from_output, encoding="utf-8").read()
        # A saved output holds what the benchmark printed (on stderr) before divan's table.
        head = text.split("Timer precision")[0] if "Timer precision" in text else ""
        notes = [l.rstrip() for l in head.splitlines() if l.strip()]
    else:
        cmd = ["cargo", "bench", "-p", "relume-benches", "--bench", a.bench, "--", *a.filters]
        print("running", " ".join(cmd), file=sys.stderr)
        done = subprocess.run(cmd, capture_output=True, text=True, check=True)
        text = done.stdout
        # What the benchmark itself printed (counts, errors), without cargo's and divan's own lines.
        cargo = ("Compiling", "Finished", "Running", "Executable", "Blocking", "Updating", "Downloaded", "Timer precision", "warning")
        notes = [l.rstrip() for l in done.stderr.splitlines() if l.strip() and not l.strip().startswith(cargo)]
    rows = parse(text)
    if not rows:
        sys.exit("no benchmark case found in divan's output")
    provenance = cells()
    path = os.path.join("docs", "results", f"bench_{a.name}.csv")
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f, lineterminator="\n")
        # Cases with an item counter (rays, samples) keep its rate at the median.
        counted = any(r[7] is not None for r in rows)
        w.writerow(["bench", "case", "fastest_ms", "slowest_ms", "median_ms", "mean_ms", "samples", "iters",
                    *(["median_items_per_s"] if counted else []), *COLUMNS])
        for r in rows:
            items = [f"{r[7]:.6g}" if r[7] is not None else ""] if counted else []
            w.writerow([a.bench, r[0], *(f"{v:.6g}" for v in r[1:5]), r[5], r[6], *items, *provenance])
    print(f"wrote {path}: {len(rows)} cases")
    notes_path = os.path.join("docs", "results", f"bench_{a.name}.txt")
    if notes:
        with open(notes_path, "w", encoding="utf-8") as f:
            f.write("\n".join(notes) + "\n")
        print(f"wrote {notes_path}: what the benchmark printed")
    elif os.path.exists(notes_path) and not a.from_output:
        os.remove(notes_path)


if __name__ == "__main__":
    main()
