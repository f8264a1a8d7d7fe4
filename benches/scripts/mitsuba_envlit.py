"""Renders docs/SCENES.md's `envlit` (graphs/scenes/envlit.ron) with Mitsuba 3 (scalar_rgb, `path`,
box filter, `envmap` emitter) for image comparisons with relume's PathTrace.

Not needed by the tests. Install with `pip install mitsuba numpy`, then:

    python3 benches/scripts/mitsuba_envlit.py SPP SIZE OUT.exr [MAX_DEPTH [SEED]]

(SIZE × SIZE pixels, MAX_DEPTH −1 by default). Prints one line: `mitsuba spp=… size=…
max_depth=… seconds=… mean_r=… mean_g=… mean_b=…`.

The scene is rebuilt to match what relume's LoadScene makes of envlit.ron:
- the meshes are read from the same OBJ files, the bunny placed by translate · scale, with
  relume's vertex normals (angle-weighted, kept sharp across edges steeper than 30°), and
  handed to Mitsuba as PLY files with those normals;
- the ground is `diffuse` 0.6; the bunny is relume's normalised Blinn-Phong
  (kd/π + ks (s+2)/(8π) cos^s θh, one-sided; sampled as relume samples it), which Mitsuba 3
  does not ship, as a Python BSDF;
- sky.exr is Mitsuba's `envmap` (bilinear lookup, the convention relume follows);
- the camera is `perspective` with the field of view on the smaller axis.
"""
import math
import os
import struct
import sys
import tempfile
import time

import drjit as dr
import mitsuba as mi
import numpy as np

mi.set_variant("scalar_rgb")

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "graphs")
SCENE = os.path.join(ROOT, "scenes")


def read_obj(path):
    """Positions and triangles (fans) of an OBJ file, 0-based."""
    pos, tris = [], []
    with open(path) as f:
        for line in f:
            w = line.split()
            if not w:
                continue
            if w[0] == "v":
                pos.append([float(x) for x in w[1:4]])
            elif w[0] == "f":
                idx = []
                for c in w[1:]:
                    i = int(c.split("/")[0])
                    idx.append(i - 1 if i > 0 else len(pos) + i)
                for k in range(1, len(idx) - 1):
                    tris.append([idx[0], idx[k], idx[k + 1]])
    return np.array(pos, dtype=np.float32), np.array(tris, dtype=np.int64)


def crease_normals(pos, tris, crease_deg=30.0):
    """relume's scene/shapes.rs `crease_normals`: each corner averages (angle weighted) the faces
    around its vertex whose normals lie within `crease_deg` of its own face's; vertices split
    where corners end up with different normals."""
    cos_crease = math.cos(math.radians(crease_deg))
    p = pos[tris]  # (F, 3, 3)
    cr = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    ln = np.linalg.norm(cr, axis=1, keepdims=True)
    face = np.where(ln > 0, cr / np.where(ln > 0, ln, 1), 0).astype(np.float32)
    ang = np.zeros((len(tris), 3), dtype=np.float32)
    for k in range(3):
        e1 = p[:, (k + 1) % 3] - p[:, k]
        e2 = p[:, (k + 2) % 3] - p[:, k]
        n1 = np.linalg.norm(e1, axis=1, keepdims=True)
        n2 = np.linalg.norm(e2, axis=1, keepdims=True)
        e1 = np.where(n1 > 0, e1 / np.where(n1 > 0, n1, 1), 0)
        e2 = np.where(n2 > 0, e2 / np.where(n2 > 0, n2, 1), 0)
        ang[:, k] = np.arccos(np.clip((e1 * e2).sum(1), -1, 1))
    incident = [[] for _ in range(len(pos))]
    for f, t in enumerate(tris):
        for k in range(3):
            incident[t[k]].append((f, k))
    out_pos, out_nrm, out_tris = [], [], tris.copy()
    for v, inc in enumerate(incident):
        made = []
        fs = np.array([f for f, _ in inc], dtype=np.int64)
        for f, k in inc:
            nf = face[f]
            n = np.zeros(3)
            if nf.any():
                ng = face[fs]
                ok = ng @ nf >= cos_crease
                n = (ng[ok] * np.array([ang[g, kg] for g, kg in inc])[ok, None]).sum(0)
            ln = np.linalg.norm(n)
            n = n / ln if ln > 0 else (nf if nf.any() else np.array([0.0, 1.0, 0.0]))
            idx = next((i for m, i in made if m @ n > 1 - 1e-6), None)
            if idx is None:
                idx = len(out_pos)
                out_pos.append(pos[v])
                out_nrm.append(n)
                made.append((n, idx))
            out_tris[f, k] = idx
    return np.array(out_pos, np.float32), np.array(out_nrm, np.float32), out_tris


def write_ply(path, pos, nrm, tris):
    with open(path, "wb") as f:
        f.write(
            (
                "ply\nformat binary_little_endian 1.0\n"
                f"element vertex {len(pos)}\nproperty float x\nproperty float y\nproperty float z\n"
                "property float nx\nproperty float ny\nproperty float nz\n"
                f"element face {len(tris)}\nproperty list uchar int vertex_indices\nend_header\n"
            ).encode()
        )
        f.write(np.hstack([pos, nrm]).astype("<f4").tobytes())
        faces = np.zeros(len(tris), dtype=[("n", "u1"), ("i", "<i4", 3)])
        faces["n"] = 3
        faces["i"] = tris
        f.write(faces.tobytes())


def luminance(c):
    """relume's Rec. 709 luminance (brdf/mod.rs), which picks the lobe."""
    return 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]


class BlinnPhong(mi.BSDF):
    """relume's brdf/blinn_phong.rs: f = kd/π + ks (s+2)/(8π) cos^s θh; with probability
    Y(kd)/(Y(kd)+Y(ks)) a cosine-weighted direction, else the mirror of ωo about a half vector
    drawn from (s+1)/(2π) cos^s θh."""

    def __init__(self, props):
        mi.BSDF.__init__(self, props)
        self.kd = [props["kd_r"], props["kd_g"], props["kd_b"]]
        self.ks = props["ks"]
        self.s = props["exponent"]
        self.pd = luminance(self.kd) / (luminance(self.kd) + luminance([self.ks] * 3))
        self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        self.m_components = [mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide,
                             mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide]

    def _f_pdf(self, wi, wo):
        """(f, pdf) for wi toward the viewer and wo toward the light (Mitsuba's names)."""
        if wi[2] <= 0 or wo[2] <= 0:
            return None
        h = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]]
        ln = math.sqrt(h[0] ** 2 + h[1] ** 2 + h[2] ** 2)
        if ln <= 0 or h[2] <= 0:
            return None
        cos_h = h[2] / ln
        wo_h = max(0.5 * ((wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]) + (wo[0] * h[0] + wo[1] * h[1] + wo[2] * h[2])) / ln, 0.0)
        s = self.s
        spec = (s + 2) / (8 * math.pi) * cos_h ** s
        f = [k / math.pi + self.ks * spec for k in self.kd]
        spec_pdf = (s + 1) / (2 * math.pi) * cos_h ** s / (4 * wo_h) if wo_h > 0 else 0.0
        return f, self.pd * wo[2] / math.pi + (1 - self.pd) * spec_pdf

    def sample(self, ctx, si, sample1, sample2, active=True):
        bs = mi.BSDFSample3f()
        wi = si.wi
        if wi[2] <= 0:
            return bs, mi.Color3f(0)
        if sample1 < self.pd:
            wo = mi.warp.square_to_cosine_hemisphere(sample2)
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            bs.sampled_component = 0
        else:
            cos_h = sample2[0] ** (1 / (self.s + 1))
            sin_h = math.sqrt(max(0.0, 1 - cos_h * cos_h))
            phi = 2 * math.pi * sample2[1]
            h = [sin_h * math.cos(phi), sin_h * math.sin(phi), cos_h]
            d = wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]
            wo = mi.Vector3f(2 * d * h[0] - wi[0], 2 * d * h[1] - wi[1], 2 * d * h[2] - wi[2])
            wo = dr.normalize(wo)
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            bs.sampled_component = 1
        r = self._f_pdf(wi, wo)
        if r is None or not r[1] > 0:
            return bs, mi.Color3f(0)
        f, pdf = r
        bs.wo = wo
        bs.pdf = pdf
        bs.eta = 1.0
        return bs, mi.Color3f([x * wo[2] / pdf for x in f])

    def eval(self, ctx, si, wo, active=True):
        r = self._f_pdf(si.wi, wo)
        return mi.Color3f(0) if r is None else mi.Color3f([x * wo[2] for x in r[0]])

    def pdf(self, ctx, si, wo, active=True):
        r = self._f_pdf(si.wi, wo)
        return 0.0 if r is None else r[1]

    def eval_pdf(self, ctx, si, wo, active=True):
        r = self._f_pdf(si.wi, wo)
        if r is None:
            return mi.Color3f(0), 0.0
        return mi.Color3f([x * wo[2] for x in r[0]]), r[1]

    def to_string(self):
        return f"BlinnPhong[kd={self.kd}, ks={self.ks}, exponent={self.s}]"


mi.register_bsdf("relume_blinn_phong", lambda props: BlinnPhong(props))


def scene_dict(spp, size, max_depth, seed, tmp):
    meshes = {}
    for name, obj, scale, translate in [
        ("ground", "../assets/envlit/ground.obj", 1.0, (0.0, 0.0, 0.0)),
        ("bunny", "../assets/meshes/stanford-bunny.obj", 6.0, (0.101, -0.198, -0.09)),
    ]:
        pos, tris = read_obj(os.path.join(SCENE, obj))
        pos, nrm, tris = crease_normals(pos, tris)
        pos = pos * scale + np.array(translate, dtype=np.float32)
        path = os.path.join(tmp, name + ".ply")
        write_ply(path, pos, nrm, tris)
        meshes[name] = path
    return {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": max_depth, "rr_depth": 5},
        "sensor": {
            "type": "perspective",
            "fov": 35.0,
            "fov_axis": "smaller",
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 1.2, 3.2], target=[0, 0.45, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
        },
        "sky": {"type": "envmap", "filename": os.path.join(ROOT, "assets", "envlit", "sky.exr")},
        "ground": {"type": "ply", "filename": meshes["ground"], "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.6}}},
        "bunny": {
            "type": "ply",
            "filename": meshes["bunny"],
            "bsdf": {"type": "relume_blinn_phong", "kd_r": 0.5, "kd_g": 0.3, "kd_b": 0.2, "ks": 0.3, "exponent": 40.0},
        },
    }


def main():
    spp, size, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    max_depth = int(sys.argv[4]) if len(sys.argv) > 4 else -1
    seed = int(sys.argv[5]) if len(sys.argv) > 5 else 0
    with tempfile.TemporaryDirectory() as tmp:
        scene = mi.load_dict(scene_dict(spp, size, max_depth, seed, tmp))
        start = time.perf_counter()
        image = mi.render(scene, spp=spp, seed=seed)
        seconds = time.perf_counter() - start
    mi.util.write_bitmap(out, image)
    mean = np.array(image, dtype=np.float64).reshape(-1, 3).mean(axis=0)
    print(
        f"mitsuba spp={spp} size={size} max_depth={max_depth} seconds={seconds:.3f} "
        f"mean_r={mean[0]:.5f} mean_g={mean[1]:.5f} mean_b={mean[2]:.5f}"
    )


if __name__ == "__main__":
    main()
