#!/usr/bin/env python3
"""The reference path tracer's throughput against Mitsuba 3 on the same machine, in one run:
`cornell` (or `cornell-bunny-diffuse`: the walls and light of Mitsuba's Cornell box and the
69 K-triangle Stanford bunny, every surface diffuse) at 256², max_depth -1, box filter, on 1
and 2 threads, relume's PathTrace (the `reference` node of graphs/reference_cornell.ron, timed by
its run report, the BVH built by its own node and not counted) against Mitsuba's scalar_rgb and
llvm_ad_rgb (`mi.render` timed after one untimed render, so the LLVM variant's JIT compilation
is not counted; the scene is loaded and its BVH built before the clock starts). Each renderer
runs in a process of its own, pinned with taskset to as many cores as it is given threads
(Mitsuba 3.6's scalar_rgb ignores Dr.Jit's thread count: told one, it used both cores; and no
variant inherits another's state), and the median of
`--renders` timed renders counts. The three alternate in rounds, and each round's ratios are of
figures measured minutes apart at most. A renderer that used more CPU time than its threads
allow (CPU over wall time above threads + 0.25) stops the script before anything is recorded.

Appends one row a round to docs/results/table_path_tracer_vs_mitsuba.csv (with the date,
machine, threads and commit; `relume results` draws the reference page's table from it).
Not needed by the tests. Needs `pip install mitsuba numpy` and the release binary. Dr.Jit's
LLVM variant loads the system's libLLVM, and LLVM 14 and 15 fail on the code it generates
("Cannot select: fminimum"); with LLVM 19 (Debian's libllvm19) it runs:

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so \

        python3 benches/scripts/mitsuba_speed.py [--scene cornell|cornell-bunny-diffuse] [--spp 32] [--rounds 3]
            [--renders 3] [--relume target/release/relume] [--no-record]
"""
import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

from provenance import COLUMNS, append_rows, cells

RESULTS = os.path.join("docs", "results", "table_path_tracer_vs_mitsuba.csv")
HEADER = ["scene", "size", "spp", "threads", "round", "relume_msamples_per_s", "scalar_rgb_msamples_per_s",
          "llvm_ad_rgb_msamples_per_s", "relume_over_scalar_rgb", "relume_over_llvm_ad_rgb", *COLUMNS]
SIZE = 256


BUNNY = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "graphs", "assets", "meshes",
                     "stanford-bunny.obj")


def mitsuba_scene(name):
    """Mitsuba's built-in Cornell box, or for `cornell-bunny-diffuse` its walls and light with the
    bunny placed as graphs/scenes/cornell-bunny-diffuse.ron places it (translate · scale)."""
    import mitsuba as mi
    scene = mi.cornell_box()
    if name == "cornell-bunny-diffuse":
        del scene["small-box"], scene["large-box"]
        to_world = mi.ScalarTransform4f().translate([0.101, -1.198, -0.09]).scale(6.0)
        scene["bunny"] = {"type": "obj", "filename": BUNNY, "to_world": to_world, "bsdf": {"type": "ref", "id": "white"}}
    return scene


def pinned(threads):
    """The command prefix that keeps a process on `threads` cores (taskset), where it can."""
    if shutil.which("taskset") and (os.cpu_count() or 1) >= threads:
        return ["taskset", "-c", ",".join(str(c) for c in range(threads))]
    return []


def cpu_seconds(who=resource.RUSAGE_SELF):
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def mitsuba_child(variant, scene_name, spp, threads, renders):
    """In a process of its own: Mitsuba's samples per second (millions, the median of `renders`
    timed renders after an untimed one) and its CPU time over wall time while timed."""
    import drjit as dr
    import mitsuba as mi
    mi.set_variant(variant)
    dr.set_thread_count(threads)
    scene = mitsuba_scene(scene_name)
    scene["integrator"] = {"type": "path", "max_depth": -1}
    scene["sensor"]["film"] = {"type": "hdrfilm", "width": SIZE, "height": SIZE, "rfilter": {"type": "box"},
                               "pixel_format": "rgb"}
    scene["sensor"]["sampler"] = {"type": "independent", "sample_count": spp}
    loaded = mi.load_dict(scene)
    dr.eval(mi.render(loaded, spp=spp, seed=1))
    rates, cpu, wall = [], 0.0, 0.0
    for seed in range(renders):
        c, start = cpu_seconds(), time.perf_counter()
        image = mi.render(loaded, spp=spp, seed=seed + 2)
        dr.eval(image)
        dr.sync_thread()
        w = time.perf_counter() - start
        cpu, wall = cpu + cpu_seconds() - c, wall + w
        rates.append(SIZE * SIZE * spp / w / 1e6)
    print(json.dumps({"rate": statistics.median(rates), "cpu_over_wall": cpu / wall}))


def mitsuba_rate(variant, scene_name, spp, threads, renders):
    """Mitsuba's samples per second (millions) and CPU over wall time, measured in a child
    process on `threads` cores: a variant run earlier in the same process, or a thread count
    the variant does not honour (scalar_rgb's, in Mitsuba 3.6), would change the figure."""
    cmd = pinned(threads) + [sys.executable, os.path.abspath(__file__), "--child", variant, scene_name, str(spp),
                             str(threads), str(renders)]
    out = subprocess.run(cmd, check=True, capture_output=True, text=True).stdout
    r = json.loads(out.strip().splitlines()[-1])
    return r["rate"], r["cpu_over_wall"]


def relume_rate(binary, scene_name, spp, threads, renders):
    """relume's samples per second (millions): the PathTrace node's time in the run report, the
    median of `renders` runs on `threads` cores, and CPU over wall time of the whole runs."""
    rates, cpu, wall = [], 0.0, 0.0
    for _ in range(renders):
        with tempfile.TemporaryDirectory() as out:
            report = os.path.join(out, "report.json")
            c, start = cpu_seconds(resource.RUSAGE_CHILDREN), time.perf_counter()
            subprocess.run(pinned(threads) + [
                binary, "run", "graphs/reference_cornell.ron", "--set", f'scene.path="scenes/{scene_name}.ron"',
                "--set", f"reference.spp={spp}", "--set", f"scene.width={SIZE}", "--set", f"scene.height={SIZE}",
                "--output", "image", "--threads", str(threads), "--no-disk-cache", "--out", out, "--report", report,
                "-q"], check=True)
            cpu, wall = cpu + cpu_seconds(resource.RUSAGE_CHILDREN) - c, wall + time.perf_counter() - start
            node = next(n for n in json.load(open(report))["nodes"] if n["id"] == "reference")
            rates.append(SIZE * SIZE * spp / (node["wall_ms"] / 1e3) / 1e6)
    return statistics.median(rates), cpu / wall


def main():
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        variant, scene_name, spp, threads, renders = sys.argv[2:7]
        return mitsuba_child(variant, scene_name, int(spp), int(threads), int(renders))
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", choices=["cornell", "cornell-bunny-diffuse"], default="cornell")
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--renders", type=int, default=3, help="timed renders a renderer and round (the median counts)")
    ap.add_argument("--relume", default=os.path.join("target", "release", "relume"))
    ap.add_argument("--no-record", action="store_true", help=f"print only, do not append to {RESULTS}")
    a = ap.parse_args()
    rows, overused = [], []
    for threads in (1, 2):
        for r in range(1, a.rounds + 1):
            rel, rel_cpu = relume_rate(a.relume, a.scene, a.spp, threads, a.renders)
            scalar, scalar_cpu = mitsuba_rate("scalar_rgb", a.scene, a.spp, threads, a.renders)
            llvm, llvm_cpu = mitsuba_rate("llvm_ad_rgb", a.scene, a.spp, threads, a.renders)
            print(f"{threads} thread(s), round {r}: relume {rel:.3f}, scalar_rgb {scalar:.3f}, llvm_ad_rgb {llvm:.3f} "
                  f"M samples/s; relume / scalar_rgb {rel / scalar:.2f}, relume / llvm_ad_rgb {rel / llvm:.2f}; "
                  f"CPU / wall {rel_cpu:.2f}, {scalar_cpu:.2f}, {llvm_cpu:.2f}", flush=True)
            overused += [name for name, c in [("relume", rel_cpu), ("scalar_rgb", scalar_cpu), ("llvm_ad_rgb", llvm_cpu)]
                         if c > threads + 0.25]
            rows.append([a.scene, SIZE, a.spp, threads, r, f"{rel:.4f}", f"{scalar:.4f}", f"{llvm:.4f}",
                         f"{rel / scalar:.3f}", f"{rel / llvm:.3f}", *cells(threads)])
    if overused:
        sys.exit(f"more CPU than the thread count allows ({', '.join(sorted(set(overused)))}): nothing recorded; "
                 "install taskset (util-linux) to pin each renderer to its cores")
    if a.no_record:
        return
    append_rows(RESULTS, HEADER, rows)


if __name__ == "__main__":
    main()
