#!/usr/bin/env python3
"""The reference path tracer's agreement with Mitsuba 3 on `cornell` (256², box filter), kept as
data: relume's `PathTrace` (graphs/reference_cornell.ron, node `reference`) and Mitsuba's
scalar_rgb `path` integrator render the scene at the same samples per pixel and maximum depth
(-1: unlimited; 2: direct light only), and the image means of each are appended, one row a
render, to docs/results/table_mitsuba_agreement.csv with the date, machine, threads and commit.
`relume results` draws the reference page's table from it.

Not needed by the tests. Needs `pip install mitsuba numpy` and the release binary:

    python3 benches/scripts/mitsuba_agreement.py [--spp 128] [--relume target/release/relume] [--no-record]
"""
import argparse
import os
import subprocess
import tempfile

import mitsuba as mi
import numpy as np

from provenance import COLUMNS, append_rows, cells

RESULTS = os.path.join("docs", "results", "table_mitsuba_agreement.csv")
HEADER = ["scene", "size", "spp", "max_depth", "renderer", "mean_r", "mean_g", "mean_b", *COLUMNS]
SIZE = 256


def mitsuba_means(spp, depth):
    mi.set_variant("scalar_rgb")
    scene = mi.cornell_box()
    scene["integrator"] = {"type": "path", "max_depth": depth}
    scene["sensor"]["film"] = {"type": "hdrfilm", "width": SIZE, "height": SIZE, "rfilter": {"type": "box"},
                               "pixel_format": "rgb"}
    scene["sensor"]["sampler"] = {"type": "independent", "sample_count": spp}
    image = np.array(mi.render(mi.load_dict(scene), spp=spp))
    return image.reshape(-1, image.shape[-1])[:, :3].mean(axis=0)


def relume_means(binary, spp, depth):
    with tempfile.TemporaryDirectory() as out:
        subprocess.run([binary, "run", "graphs/reference_cornell.ron", "--set", f"reference.spp={spp}",
                        "--set", f"reference.max_depth={depth}", "--set", f"scene.width={SIZE}",
                        "--set", f"scene.height={SIZE}", "--output", "image", "--no-disk-cache", "--out", out, "-q"],
                       check=True)
        image = np.array(mi.Bitmap(os.path.join(out, "image.exr")))
    return image.reshape(-1, image.shape[-1])[:, :3].mean(axis=0)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spp", type=int, default=128)
    ap.add_argument("--relume", default=os.path.join("target", "release", "relume"))
    ap.add_argument("--no-record", action="store_true", help=f"print only, do not append to {RESULTS}")
    a = ap.parse_args()
    mi.set_variant("scalar_rgb")
    rows = []
    for depth in (-1, 2):
        for renderer, means in (("relume", relume_means(a.relume, a.spp, depth)), ("Mitsuba 3 scalar_rgb", mitsuba_means(a.spp, depth))):
            print(f"max_depth {depth}, {renderer}: " + " / ".join(f"{m:.5f}" for m in means))
            rows.append(["cornell", SIZE, a.spp, depth, renderer, *(f"{m:.5f}" for m in means), *cells()])
    if a.no_record:
        return
    append_rows(RESULTS, HEADER, rows)


if __name__ == "__main__":
    main()
