#!/usr/bin/env python3
"""What sharding costs: the `cornell` reference (graphs/reference_cornell.ron, node `reference`,
PathTrace at --spp, default 4096) run

  1. unsharded, one process;
  2. over timely with 2 and 3 local processes (`relume run --processes N`);
  3. as 16 Slurm-style shards run one after the other (`relume shard --shards 16 --index I`,
     one chunk each), then gathered by `relume run` on the same cache.

On one machine the processes share its cores, so the figure is overhead, not speed-up: each
variant does the same path tracing as (1), and what it takes beyond (1) is the cost of
sharding (process start, graph load, scene and BVH per process, connecting, moving partials,
the gather). Prints a Markdown table, the overhead per shard, and the wall time projected for
M machines like this one from the measured time per chunk, and appends the measured rows of
both sample counts to docs/results/table_shard_overhead.csv with the date, machine, threads and
commit (unless --no-record); `relume results` draws the cluster guide's table from it.

Usage: python3 benches/scripts/shard_overhead.py [--spp 4096] [--relume target/release/relume] [--no-record]
Build first: cargo build --release.
"""

import argparse
import json
import math
import os
import subprocess
import tempfile
import time

from provenance import COLUMNS, append_rows, cells

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
GRAPH = os.path.join(ROOT, "graphs", "reference_cornell.ron")
RESULTS = os.path.join(ROOT, "docs", "results", "table_shard_overhead.csv")
HEADER = ["run", "spp", "shards", "wall_s", "over_unsharded_s", "chunks", "chunk_s", "images_identical", *COLUMNS]


def run(cmd):
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                   env={k: v for k, v in os.environ.items() if not k.startswith("SLURM_") and k != "RELUME_CACHE"})
    return time.perf_counter() - t0


def shards_of(report_path):
    nodes = json.load(open(report_path))["nodes"]
    return next(n for n in nodes if n["id"] == "reference")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spp", type=int, default=4096)
    ap.add_argument("--fixed-spp", type=int, default=16,
                    help="a second, short measurement where the fixed costs of sharding are not lost in the run-to-run noise")
    ap.add_argument("--relume", default=os.path.join(ROOT, "target", "release", "relume"))
    ap.add_argument("--no-record", action="store_true", help=f"print only, do not append to {RESULTS}")
    a = ap.parse_args()
    rows, t1, chunks, chunk_ms, same = measure(a.relume, a.spp)
    print(f"cornell 256x256, PathTrace {a.spp} spp, {chunks} chunks of 16 rows; {os.cpu_count()} cores; images identical: {same}\n")
    table(rows, t1)
    fixed, f1, fchunks, fchunk_ms, fsame = measure(a.relume, a.fixed_spp)
    print(f"\nthe same at {a.fixed_spp} spp (fixed costs; images identical: {fsame}):\n")
    table(fixed, f1)
    # Per Slurm-style shard: the larger of the two measurements, never below zero (at high spp
    # the fixed cost drowns in the run-to-run noise of the path tracing).
    per_shard = max(0.0, (rows[-1][2] - t1) / chunks, (fixed[-1][2] - f1) / chunks)
    print(f"\nmean time per chunk (unsharded run): {chunk_ms / 1e3:.2f} s; overhead per Slurm-style shard: {per_shard:.2f} s")
    print("\nprojected wall time on M machines like this one, one shard each (ceil(chunks/M) chunks + one shard's overhead):\n")
    print("| machines | projected wall s | speed-up |")
    print("|---:|---:|---:|")
    for m in (1, 2, 4, 8, 16):
        w = math.ceil(chunks / m) * chunk_ms / 1e3 + (per_shard if m > 1 else 0.0)
        print(f"| {m} | {w:.1f} | {t1 / w:.1f}x |")
    if a.no_record:
        return
    out = []
    for spp, measured, base, n, ms, identical in ((a.spp, rows, t1, chunks, chunk_ms, same),
                                                  (a.fixed_spp, fixed, f1, fchunks, fchunk_ms, fsame)):
        for name, shards, t in measured:
            out.append([name, spp, shards, f"{t:.2f}", f"{t - base:+.2f}", n, f"{ms / 1e3:.3f}",
                        "yes" if identical else "no", *cells()])
    append_rows(RESULTS, HEADER, out)


def measure(relume, spp):
    """Wall times of the four variants at `spp`; the unsharded time, chunks, mean chunk time."""
    base = [relume, "run", GRAPH, "--output", "image", "--set", f"reference.spp={spp}", "-q"]
    rows = []
    with tempfile.TemporaryDirectory() as d:
        rep = os.path.join(d, "one.json")
        t1 = run(base + ["--no-disk-cache", "--out", os.path.join(d, "one"), "--report", rep])
        node = shards_of(rep)
        chunks = node["shards"]["chunks"]
        chunk_ms = node["shards"]["ran_ms"] / chunks
        rows.append(("unsharded, 1 process", 1, t1))
        for n in (2, 3):
            t = run(base + ["--processes", str(n), "--no-disk-cache", "--out", os.path.join(d, f"p{n}")])
            rows.append((f"timely, {n} local processes", n, t))
        cache = os.path.join(d, "slurm-cache")
        ts = 0.0
        for i in range(chunks):
            ts += run([relume, "shard", GRAPH, "--node", "reference", "--set", f"reference.spp={spp}",
                       "--shards", str(chunks), "--index", str(i), "--cache", cache, "-q"])
        tg = run(base + ["--cache", cache, "--out", os.path.join(d, "gather")])
        rows.append((f"{chunks} Slurm-style shards one after another + gather", chunks, ts + tg))
        one = open(os.path.join(d, "one", "image.exr"), "rb").read()
        same = all(open(os.path.join(d, x, "image.exr"), "rb").read() == one for x in ("p2", "p3", "gather"))
    return rows, t1, chunks, chunk_ms, same


def table(rows, t1):
    print("| run | shards | wall s | over unsharded s | per shard s |")
    print("|---|---:|---:|---:|---:|")
    for name, n, t in rows:
        extra = t - t1
        per = f"{extra / n:+.2f}" if n > 1 else "–"
        print(f"| {name} | {n} | {t:.2f} | {extra:+.2f} | {per} |")


if __name__ == "__main__":
    main()
