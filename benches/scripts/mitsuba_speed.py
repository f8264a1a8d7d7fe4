#!/usr/bin/env python3
"""The reference path tracer's throughput against Mitsuba 3 on the same machine, in one run:
`cornell` (or `cornell-bunny-diffuse`: the walls and light of Mitsuba's Cornell box and the
69 K-triangle Stanford bunny, every surface diffuse) at 256², max_depth -1, box filter, on 1
and 2 threads, relume's PathTrace (the
`reference` node of graphs/reference_cornell.ron, timed by its run report, the BVH built by its
own node and not counted) against Mitsuba's scalar_rgb and llvm_ad_rgb (`mi.render` timed after
one untimed render, so the LLVM variant's JIT compilation is not counted; the scene is loaded
and its BVH built before the clock starts). The three alternate in rounds, and each round's
ratios are of figures measured minutes apart at most.

Appends one row a round to docs/results/table_path_tracer_vs_mitsuba.csv (with the date,
machine, threads and commit; `relume results` draws the reference page's table from it).
Not needed by the tests. Needs `pip install mitsuba numpy` and the release binary. Dr.Jit's
LLVM variant loads the system's libLLVM, and LLVM 14 and 15 fail on the code it generates
("Cannot select: fminimum"); with LLVM 19 (Debian's libllvm19) it runs:

    DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM-19.so \

        python3 benches/scripts/mitsuba_speed.py [--scene cornell|cornell-bunny-diffuse] [--spp 32] [--rounds 3]
            [--relume target/release/relume] [--no-record]
"""
import argparse
import json
import os
import subprocess
import tempfile
import time

import drjit as dr
import mitsuba as mi

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
    scene = mi.cornell_box()
    if name == "cornell-bunny-diffuse":
        del scene["small-box"], scene["large-box"]
        to_world = mi.ScalarTransform4f().translate([0.101, -1.198, -0.09]).scale(6.0)
        scene["bunny"] = {"type": "obj", "filename": BUNNY, "to_world": to_world, "bsdf": {"type": "ref", "id": "white"}}
    return scene


def mitsuba_rate(variant, scene_name, spp, threads):
    """Mitsuba's samples per second (millions)."""
    mi.set_variant(variant)
    dr.set_thread_count(threads)
    scene = mitsuba_scene(scene_name)
    scene["integrator"] = {"type": "path", "max_depth": -1}
    scene["sensor"]["film"] = {"type": "hdrfilm", "width": SIZE, "height": SIZE, "rfilter": {"type": "box"},
                               "pixel_format": "rgb"}
    scene["sensor"]["sampler"] = {"type": "independent", "sample_count": spp}
    loaded = mi.load_dict(scene)
    dr.eval(mi.render(loaded, spp=spp, seed=1))
    start = time.perf_counter()
    image = mi.render(loaded, spp=spp, seed=0)
    dr.eval(image)
    dr.sync_thread()
    return SIZE * SIZE * spp / (time.perf_counter() - start) / 1e6


def relume_rate(binary, scene_name, spp, threads):
    """relume's samples per second (millions): the PathTrace node's time in the run report."""
    with tempfile.TemporaryDirectory() as out:
        report = os.path.join(out, "report.json")
        subprocess.run([binary, "run", "graphs/reference_cornell.ron", "--set", f'scene.path="scenes/{scene_name}.ron"',
                        "--set", f"reference.spp={spp}",
                        "--set", f"scene.width={SIZE}", "--set", f"scene.height={SIZE}", "--output", "image",
                        "--threads", str(threads), "--no-disk-cache", "--out", out, "--report", report, "-q"], check=True)
        node = next(n for n in json.load(open(report))["nodes"] if n["id"] == "reference")
        return SIZE * SIZE * spp / (node["wall_ms"] / 1e3) / 1e6


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", choices=["cornell", "cornell-bunny-diffuse"], default="cornell")
    ap.add_argument("--spp", type=int, default=32)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--relume", default=os.path.join("target", "release", "relume"))
    ap.add_argument("--no-record", action="store_true", help=f"print only, do not append to {RESULTS}")
    a = ap.parse_args()
    rows = []
    for threads in (1, 2):
        for r in range(1, a.rounds + 1):
            rel = relume_rate(a.relume, a.scene, a.spp, threads)
            scalar = mitsuba_rate("scalar_rgb", a.scene, a.spp, threads)
            llvm = mitsuba_rate("llvm_ad_rgb", a.scene, a.spp, threads)
            print(f"{threads} thread(s), round {r}: relume {rel:.3f}, scalar_rgb {scalar:.3f}, llvm_ad_rgb {llvm:.3f} "
                  f"M samples/s; relume / scalar_rgb {rel / scalar:.2f}, relume / llvm_ad_rgb {rel / llvm:.2f}")
            rows.append([a.scene, SIZE, a.spp, threads, r, f"{rel:.4f}", f"{scalar:.4f}", f"{llvm:.4f}",
                         f"{rel / scalar:.3f}", f"{rel / llvm:.3f}", *cells(threads)])
    if a.no_record:
        return
    append_rows(RESULTS, HEADER, rows)


if __name__ == "__main__":
    main()
