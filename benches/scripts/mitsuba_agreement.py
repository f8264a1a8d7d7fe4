#!/usr/bin/env python3
"""The reference path tracer's agreement with Mitsuba 3, kept as data: relume's `PathTrace`
(graphs/reference_cornell.ron, node `reference`, on the scene chosen) and Mitsuba's scalar_rgb
`path` integrator render the scene at the same samples per pixel, maximum depth (-1: unlimited;
2: direct light only) and seed, box filter, and the image means of each are appended, one row a
render, with the date, machine, threads and commit, to
- docs/results/table_mitsuba_agreement.csv for `cornell` (256², Mitsuba's own Cornell box),
- docs/results/table_mitsuba_envlit.csv for `envlit` (128², the scene rebuilt for Mitsuba by
  mitsuba_envlit.py: relume's normals, its Blinn-Phong as a Python BSDF), over seeds.
`relume results` draws the reference page's tables from them.

Not needed by the tests. Needs `pip install mitsuba numpy` and the release binary:

    python3 benches/scripts/mitsuba_agreement.py [--scene cornell|envlit] [--spp 128] [--seeds 0,1]
        [--relume target/release/relume] [--no-record] [--picture docs/reference_cornell.png]

With --picture, the unlimited-depth images of the first seed are also written side by side as
one PNG: relume, Mitsuba 3, and their absolute difference scaled by --diff-gain (sRGB, 8 bit).
"""
import argparse
import os
import subprocess
import tempfile

import mitsuba as mi
import numpy as np

from provenance import COLUMNS, append_rows, cells

RESULTS = {
    "cornell": os.path.join("docs", "results", "table_mitsuba_agreement.csv"),
    "envlit": os.path.join("docs", "results", "table_mitsuba_envlit.csv"),
}
SIZE = {"cornell": 256, "envlit": 128}


def header(scene):
    seed = ["seed"] if scene == "envlit" else []
    return ["scene", "size", "spp", "max_depth", *seed, "renderer", "mean_r", "mean_g", "mean_b", *COLUMNS]


def to_array(image):
    image = np.array(image, dtype=np.float64)
    return image.reshape(image.shape[0], image.shape[1], -1)[:, :, :3]


def means(image):
    image = np.array(image, dtype=np.float64)
    return image.reshape(-1, image.shape[-1])[:, :3].mean(axis=0)


def mitsuba_image(scene_name, spp, depth, seed):
    mi.set_variant("scalar_rgb")
    size = SIZE[scene_name]
    if scene_name == "envlit":
        import mitsuba_envlit
        with tempfile.TemporaryDirectory() as tmp:
            return to_array(mi.render(mi.load_dict(mitsuba_envlit.scene_dict(spp, size, depth, seed, tmp)), spp=spp, seed=seed))
    scene = mi.cornell_box()
    scene["integrator"] = {"type": "path", "max_depth": depth}
    scene["sensor"]["film"] = {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"},
                               "pixel_format": "rgb"}
    scene["sensor"]["sampler"] = {"type": "independent", "sample_count": spp}
    return to_array(mi.render(mi.load_dict(scene), spp=spp, seed=seed))


def relume_image(binary, scene_name, spp, depth, seed):
    size = SIZE[scene_name]
    with tempfile.TemporaryDirectory() as out:
        subprocess.run([binary, "run", "graphs/reference_cornell.ron", "--set", f'scene.path="scenes/{scene_name}.ron"',
                        "--set", f"reference.spp={spp}", "--set", f"reference.max_depth={depth}",
                        "--set", f"reference.seed={seed}", "--set", f"scene.width={size}", "--set", f"scene.height={size}",
                        "--output", "image", "--no-disk-cache", "--out", out, "-q"],
                       check=True)
        return to_array(mi.Bitmap(os.path.join(out, "image.exr")))


def write_picture(path, relume, mitsuba, gain):
    """relume | Mitsuba 3 | |difference| x gain, 8 pixels of grey between them, as an sRGB PNG."""
    gap = np.full((relume.shape[0], 8, 3), 0.18)
    strip = np.concatenate([relume, gap, mitsuba, gap, np.abs(relume - mitsuba) * gain], axis=1)
    bitmap = mi.Bitmap(strip.astype(np.float32), mi.Bitmap.PixelFormat.RGB)
    bitmap.convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.UInt8, srgb_gamma=True).write(path)
    print(f"wrote {path} (relume | Mitsuba 3 | |difference| x {gain:g})")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", choices=sorted(RESULTS), default="cornell")
    ap.add_argument("--spp", type=int, default=128)
    ap.add_argument("--seeds", default="0", help="comma-separated seeds (a row each; envlit's table keeps them apart)")
    ap.add_argument("--relume", default=os.path.join("target", "release", "relume"))
    ap.add_argument("--no-record", action="store_true", help="print only, do not append to the table")
    ap.add_argument("--picture", help="also write the unlimited-depth images of the first seed side by side as this PNG")
    ap.add_argument("--diff-gain", type=float, default=4.0, help="scale of the difference image in --picture")
    a = ap.parse_args()
    mi.set_variant("scalar_rgb")
    rows = []
    for depth in (-1, 2):
        for seed in (int(s) for s in a.seeds.split(",")):
            ours, theirs = relume_image(a.relume, a.scene, a.spp, depth, seed), mitsuba_image(a.scene, a.spp, depth, seed)
            if a.picture and depth == -1 and not rows:
                write_picture(a.picture, ours, theirs, a.diff_gain)
            for renderer, m in (("relume", means(ours)), ("Mitsuba 3 scalar_rgb", means(theirs))):
                print(f"max_depth {depth}, seed {seed}, {renderer}: " + " / ".join(f"{v:.5f}" for v in m))
                seeded = [seed] if a.scene == "envlit" else []
                rows.append([a.scene, SIZE[a.scene], a.spp, depth, *seeded, renderer, *(f"{v:.5f}" for v in m), *cells()])
    if a.no_record:
        return
    append_rows(RESULTS[a.scene], header(a.scene), rows)


if __name__ == "__main__":
    main()
