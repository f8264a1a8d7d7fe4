#!/usr/bin/env python3
"""The ring's basis truncation error over framings: `graphs/relight_basis_ring.ron`'s
`truncation` output (the relit image against the same paths with each material's lobe
tabulated on the basis' grid and uncompressed, the thesis' reference) for four cameras by four
places of the point light, each at the four exponent settings of the thesis' figure 4-4 (ring s
/ plane s: 5/5, 5/180, 180/5, 180/180) and once with the plane's specular term off (ring 180).

Each framing is a copy of graphs/scenes/ring.ron (same meshes, materials and light intensity)
written to a temporary folder and read with --read-from; the runs share one disk cache there,
so the four exponent settings of a framing reuse its precompute. Prints one line a framing
(relative L2 in %). Not needed by the tests. The figures in docs/lab/relighting.md
(2026-12-01) came from

    python3 benches/scripts/ring_framings.py --relume target/release/relume --size 128

which takes about six minutes on two cores.
"""
import argparse
import itertools
import json
import os
import subprocess
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CAMERAS = {
    "shipped": ((0, 2.6, 2.2), (0, 0, 0.1)),
    "nearer": ((0, 1.75, 1.5), (0, 0, 0.1)),
    "down": ((0, 3.6, 0.01), (0, 0, 0)),
    "low": ((0, 1.0, 3.2), (0, 0.2, 0)),
}
LIGHTS = {
    "side": (-3, 1.2, 0),
    "over": (0, 3, 0),
    "facing": (0, 1.2, -3),
    "behind": (0, 2.5, 3),
}
EXPONENTS = [(5, 5), (5, 180), (180, 5), (180, 180)]


def scene_file(folder, camera, light, size):
    origin, target = CAMERAS[camera]
    assets = os.path.join(ROOT, "graphs", "assets", "ring")
    path = os.path.join(folder, f"{camera}_{light}.ron")
    with open(path, "w") as f:
        f.write(f"""Scene(
    camera: (origin: {origin}, target: {target}, up: (0, 1, 0), fov: 45, width: {size}, height: {size}),
    materials: {{
        "ring": BlinnPhong(kd: (0.2, 0.2, 0), ks: (0.2, 0.2, 0), exponent: 180),
        "plane": BlinnPhong(kd: 0.2, ks: 0.2, exponent: 5),
    }},
    shapes: [
        Obj(path: "{assets}/ring.obj", material: "ring", dynamic: true),
        Obj(path: "{assets}/plane.obj", material: "plane", dynamic: true),
    ],
    lights: [
        Point(position: {LIGHTS[light]}, intensity: 40),
    ],
)
""")
    return path


def truncation(relume, folder, scene, sets):
    report = os.path.join(folder, "report.json")
    args = [relume, "run", os.path.join(ROOT, "graphs", "relight_basis_ring.ron"), "-q", "--out", os.path.join(folder, "out"),
            "--report", report, "--cache", os.path.join(folder, "cache"), "--read-from", folder,
            "--read-from", os.path.join(ROOT, "graphs", "assets"), "--output", "truncation", "--set", f"scene.path={scene}"]
    for s in sets:
        args += ["--set", s]
    subprocess.run(args, check=True, stdout=subprocess.DEVNULL)
    for node in json.load(open(report))["nodes"]:
        if node["id"] == "truncation":
            return dict(node["metrics"])["l2_percent"]
    raise SystemExit("the run reported no truncation metrics")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--relume", default=os.path.join(ROOT, "target", "release", "relume"))
    ap.add_argument("--size", type=int, default=128, help="image side in pixels")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        print("camera light " + " ".join(f"{r}/{p}" for r, p in EXPONENTS) + " 180/5,plane_Ks=0")
        for camera, light in itertools.product(CAMERAS, LIGHTS):
            scene = scene_file(folder, camera, light, a.size)
            row = [truncation(a.relume, folder, scene, [f"project_ring.s={r}", f"project_plane.s={p}"]) for r, p in EXPONENTS]
            row.append(truncation(a.relume, folder, scene, ["project_plane.ks=(0.0,0.0,0.0)", "project_ring.s=180", "project_plane.s=5"]))
            print(camera, light, " ".join(f"{e:.3f}" for e in row), flush=True)


if __name__ == "__main__":
    main()
