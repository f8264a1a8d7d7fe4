# ---
# jupyter:
#   jupytext:
#     formats: py:percent
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

# %% [markdown]
# # Sweeping the bunny's exponent
#
# Pixel relighting ([S] chapter 4) on `graphs/relight_cornell_bunny.ron`: the precompute stores
# the scene's transfer once, and a material edit re-runs only the projection onto the BRDF
# basis and the combination. This notebook sweeps the bunny's Blinn-Phong exponent, shows the
# relit images beside the path tracer's, and plots the relit image's error against the path
# tracer and what each edit cost.
#
# It is a jupytext notebook: open it in Jupyter (with jupytext installed) or run it as a script
# (`python docs/notebooks/relight_sweep.py`). `RELUME_TEST_SIZE=1` runs the graph at its test
# size at 96 × 96 pixels, in seconds, as CI does (the figures are then noisy); without it the
# first run computes the full-size precompute and one 4,096-samples-per-pixel reference per
# exponent, minutes on two cores, which the disk cache keeps for later runs.

# %%
import os
import pathlib
import time

import matplotlib
import numpy as np

try:
    get_ipython  # noqa: F821 (defined inside Jupyter)
except NameError:
    matplotlib.use("Agg")  # run as a script: the figures go to files
import matplotlib.pyplot as plt

import relume

ROOT = next(p for p in [pathlib.Path.cwd(), *pathlib.Path.cwd().parents] if (p / "graphs").is_dir())
TEST_SIZE = os.environ.get("RELUME_TEST_SIZE") == "1"
OUT = pathlib.Path(os.environ.get("RELUME_NOTEBOOK_OUT", ROOT / "out"))
OUT.mkdir(parents=True, exist_ok=True)

g = relume.Graph.load(ROOT / "graphs" / "relight_cornell_bunny.ron")
if TEST_SIZE:
    g.shrink_to_test_size()
    g["scene"]["width"] = 96
    g["scene"]["height"] = 96
g["project"]["object"] = "bunny"
print(g)

# %% [markdown]
# Each exponent is one edit of `project.s`. The first run computes everything the image
# needs (or reads it from the disk cache); each later edit re-runs `project` and `relight`
# for the image, and the path tracer for its reference (the material changed).

# %%
exponents = [5, 12, 30, 70, 180]
rows = []
for s in exponents:
    g["project"]["s"] = s
    t0 = time.perf_counter()
    image = g.run(["image"], progress=False)
    edit_ms = (time.perf_counter() - t0) * 1e3
    checked = g.run(["reference", "error"], progress=False)
    rows.append(
        {
            "s": s,
            "edit_ms": edit_ms,
            "ran": image.ran,
            "rel_mse": checked.metrics["error"]["rel_mse"],
            "image": image.images["image"],
            "reference": checked.images["reference"],
        }
    )
    print(f"s = {s:4}: the edit re-ran {', '.join(image.ran)} in {edit_ms:.1f} ms; "
          f"relative MSE against the path tracer {rows[-1]['rel_mse']:.4f}")

# %% [markdown]
# The relit images (top) and the path tracer's (bottom), tone-mapped for display.

# %%
def display(img, exposure=1.5):
    x = np.clip(img * exposure, 0, None)
    return np.clip((x / (1 + x)) ** (1 / 2.2), 0, 1)


fig, axes = plt.subplots(2, len(rows), figsize=(2.2 * len(rows), 4.6))
for col, r in enumerate(rows):
    for row, key in enumerate(["image", "reference"]):
        ax = axes[row, col]
        ax.imshow(display(r[key]))
        ax.set_xticks([])
        ax.set_yticks([])
        if row == 0:
            ax.set_title(f"s = {r['s']}")
    axes[0, 0].set_ylabel("relit")
    axes[1, 0].set_ylabel("path traced")
fig.tight_layout()
fig.savefig(OUT / "relight_sweep_images.png", dpi=100)

# %% [markdown]
# Error against the path tracer, and what each edit cost (the relit image alone).

# %%
fig, (a, b) = plt.subplots(1, 2, figsize=(9, 3.4))
a.semilogx([r["s"] for r in rows], [r["rel_mse"] for r in rows], "o-")
a.set_xlabel("Blinn-Phong exponent s")
a.set_ylabel("relative MSE against the path tracer")
b.semilogx([r["s"] for r in rows[1:]], [r["edit_ms"] for r in rows[1:]], "o-")  # the first run is not an edit
b.set_xlabel("Blinn-Phong exponent s")
b.set_ylabel("edit to image (ms)")
b.set_ylim(bottom=0)
fig.tight_layout()
fig.savefig(OUT / "relight_sweep_error.png", dpi=100)

# The sweep ran: every edit after the first re-ran the projection and the combination only.
assert all(set(r["ran"]) <= {"project", "relight"} for r in rows[1:]), [r["ran"] for r in rows]
assert all(np.isfinite(r["rel_mse"]) for r in rows)
print(f"figures in {OUT}")
