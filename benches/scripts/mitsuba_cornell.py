"""Renders docs/SCENES.md's `cornell` with Mitsuba 3 (scalar_rgb, path, max_depth -1, box filter,
256 x 256) for throughput and image comparisons with relume's PathTrace.

Not needed by the tests. Install with `pip install mitsuba numpy`, then:

    python3 benches/scripts/mitsuba_cornell.py SPP THREADS OUT.exr   (THREADS 0: all cores)

Prints one line: `mitsuba spp=… threads=… seconds=… samples_per_second=…`.
"""
import sys
import time

import drjit as dr
import mitsuba as mi

spp, threads, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
mi.set_variant("scalar_rgb")
if threads > 0:
    dr.set_thread_count(threads)
scene = mi.cornell_box()
scene["integrator"] = {"type": "path", "max_depth": int(sys.argv[4]) if len(sys.argv) > 4 else -1}
scene["sensor"]["film"] = {"type": "hdrfilm", "width": 256, "height": 256, "rfilter": {"type": "box"}, "pixel_format": "rgb"}
scene["sensor"]["sampler"] = {"type": "independent", "sample_count": spp}
loaded = mi.load_dict(scene)
start = time.perf_counter()
image = mi.render(loaded, spp=spp)
seconds = time.perf_counter() - start
mi.util.write_bitmap(out, image)
print(f"mitsuba spp={spp} threads={threads} seconds={seconds:.3f} samples_per_second={256 * 256 * spp / seconds:.0f}")
