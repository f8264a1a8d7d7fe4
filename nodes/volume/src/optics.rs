//! The optics photon marching and eikonal rendering share ([S] 6.3.3–6.3.5): the lights as
//! the pipeline sees them, the ray equation's Euler step with |v| = n kept, the distance to
//! an octree leaf's boundary, voxel traversal of a segment, straight-line transmittance, and
//! the frame of a planar receiver.

use super::octree_layout::{CLEARANCE, INDEX};
use crate::types::{Sampler, Volume};
use glam::Vec3;
use relume_base::render::lights::delta_sample;
use relume_base::types::{Light, Scene};
use relume_core::{NodeError, ParamEnum};

/// A light as pipeline 3 uses it: a delta light, and the radius of the emitter it stands for
/// (0 for the scene's own delta lights) so that shadow rays stop short of the emitter.
#[derive(Clone, Debug, PartialEq)]
pub struct PhotonLight {
    pub light: Light,
    pub radius: f32,
}

/// The scene's delta lights, then each emissive object as a light at its area centroid
/// emitting its power Φ = π L A uniformly (intensity Φ / 4π = L A / 4 per channel, L the mean
/// emitted radiance), of the radius of the object's farthest vertex: exact for a sphere, whose
/// intensity is π r² L in every direction and whose light in any direction leaves the disk
/// across it (`lamp_point`).
pub fn photon_lights(scene: &Scene) -> Vec<PhotonLight> {
    let mut out: Vec<PhotonLight> = scene.lights.iter().map(|l| PhotonLight { light: l.clone(), radius: 0.0 }).collect();
    for (k, o) in scene.objects.iter().enumerate() {
        if o.emission.max_element() <= 0.0 {
            continue;
        }
        let (mut area, mut centroid) = (0.0f64, glam::DVec3::ZERO);
        for t in o.triangles.clone() {
            let (_, a) = scene.normal_area(t as usize);
            let [p, q, r] = scene.corners(t as usize);
            area += a as f64;
            centroid += ((p + q + r) / 3.0).as_dvec3() * a as f64;
        }
        if area <= 0.0 {
            continue;
        }
        let c = (centroid / area).as_vec3();
        let radius = o.triangles.clone().flat_map(|t| scene.corners(t as usize)).map(|p| p.distance(c)).fold(0.0f32, f32::max);
        debug_assert_eq!(scene.objects[k].name, o.name);
        out.push(PhotonLight { light: Light::Point { position: c, intensity: o.emission * (area as f32 / 4.0) }, radius });
    }
    out
}

/// A point of the disk a light of radius `radius` centred at `centre` shows along unit
/// direction `w` (the disk through its centre, across `w`), at uniform numbers `u` (area
/// uniform): where light leaving a uniformly bright sphere in direction `w` starts, and where
/// a shadow ray from a point it lights may aim. `centre` itself for a light of radius 0.
pub fn lamp_point(centre: Vec3, radius: f32, w: Vec3, u: (f32, f32)) -> Vec3 {
    if radius <= 0.0 {
        return centre;
    }
    let (e1, e2) = across(w);
    let (r, phi) = (radius * u.0.sqrt(), std::f32::consts::TAU * u.1);
    centre + e1 * (r * phi.cos()) + e2 * (r * phi.sin())
}

/// The shadow segment from `from` to the point of the lamp (centre `centre`, radius `radius`,
/// seen along `w`) at uniform numbers `u`: its unit direction and a length that stops short
/// of the lamp's disk.
pub fn lamp_segment(from: Vec3, centre: Vec3, radius: f32, w: Vec3, u: (f32, f32)) -> (Vec3, f32) {
    let to = lamp_point(centre, radius, w, u) - from;
    let len = to.length();
    (to / len, (len - radius * 1.001) * (1.0 - 1e-4))
}

/// Two unit vectors completing unit `w` to an orthonormal frame.
pub fn across(w: Vec3) -> (Vec3, Vec3) {
    let a = if w.x.abs() < 0.9 { Vec3::X } else { Vec3::Y };
    let e1 = w.cross(a).normalize();
    (e1, w.cross(e1))
}

/// Radiant intensity of a point or spot light along unit direction `d` (zero for directional).
pub fn intensity_along(l: &Light, d: Vec3) -> Vec3 {
    match l {
        Light::Point { position, .. } | Light::Spot { position, .. } => delta_sample(l, *position + d).map_or(Vec3::ZERO, |s| s.2),
        Light::Directional { .. } => Vec3::ZERO,
    }
}

/// The parameter interval where `o + t d` lies in the box `lo … hi`, clipped to t ≥ 0.
pub fn box_interval(o: Vec3, d: Vec3, lo: Vec3, hi: Vec3) -> Option<(f32, f32)> {
    let inv = d.recip();
    let (a, b) = ((lo - o) * inv, (hi - o) * inv);
    // 0 × ∞ (a ray in a face's plane) gives NaN: min/max drop it.
    let t0 = a.min(b).max_element().max(0.0);
    let t1 = a.max(b).min_element();
    (t0 <= t1 && t1.is_finite()).then_some((t0, t1))
}

/// Distance in voxels from grid point `q` (voxel units) along unit `u` to the boundary of the
/// aligned cell of side 2^`level` voxels holding voxel `cell` ([S] 6.3.4: the octree leaf).
pub fn leaf_exit(q: Vec3, u: Vec3, cell: [usize; 3], level: u32) -> f32 {
    let side = (1usize << level.min(30)) as f32;
    let mut t = f32::INFINITY;
    for a in 0..3 {
        let lo = (cell[a] >> level.min(30)) as f32 * side;
        let edge = if u[a] > 0.0 {
            lo + side
        } else if u[a] < 0.0 {
            lo
        } else {
            continue;
        };
        t = t.min(((edge - q[a]) / u[a]).max(0.0));
    }
    t
}

/// The voxel holding grid point `q`, clamped to the grid.
pub fn voxel_of(v: &Volume, q: Vec3) -> [usize; 3] {
    let q = if q.is_finite() { q } else { Vec3::ZERO };
    let at = |a: usize| (q[a].max(0.0) as usize).min(v.dims[a] as usize - 1);
    [at(0), at(1), at(2)]
}

/// How the ray equation ([S] 6-1 … 6-3: v = n dx/ds, dv/ds = ∇n) is stepped.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum Integrator {
    /// Störmer–Verlet in the optical length τ (dx/dτ = v, dv/dτ = n∇n): half a kick, a drift,
    /// half a kick; it keeps a ray's angular momentum about a spherical index's centre, so
    /// total internal reflection holds at one-voxel steps
    Verlet,
    /// the thesis' explicit step x += Δs v / n, v += Δs ∇n(x): with |v| = n restored it drains
    /// angular momentum at each bounce (measured: a ray at 70° inside an n = 2.4 sphere
    /// escapes after 110 one-voxel steps)
    Euler,
    /// explicit midpoint: the kick is ∇n halfway along the straight step (second order; the
    /// long steps through flat leaves take it whatever the choice, see `MarchPhotons`)
    Midpoint,
}

/// A ray in the medium: position `x`, `v` = n dx/ds (so |v| = n), and the index and its
/// gradient at `x` as the octree's trilinear lookup gives them (carried from one step's end to
/// the next step's start, so that a step reads the octree once).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub x: Vec3,
    pub v: Vec3,
    pub n: f32,
    pub g: Vec3,
}

/// n and ∇n at `p`, one trilinear lookup of the octree's `INDEX` and `GRADIENT` channels.
#[inline]
pub fn index_at(octree: &Sampler, p: Vec3) -> (f32, Vec3) {
    let v = octree.sample4(p, INDEX);
    (v.x.max(1e-3), Vec3::new(v.y, v.z, v.w))
}

impl Ray {
    /// A ray at `x` along unit `d`, with |v| = n(x).
    pub fn new(octree: &Sampler, x: Vec3, d: Vec3) -> Ray {
        let (n, g) = index_at(octree, x);
        Ray { x, v: d * n, n, g }
    }

    /// The unit direction.
    pub fn dir(&self) -> Vec3 {
        self.v / self.v.length()
    }
}

/// One step of arc length `ds` of the ray equation through the index n (`octree`'s `INDEX`
/// and `GRADIENT` channels, trilinearly), by `integrator`, then |v′| = n(x′) restored. Where
/// the index is locally constant (∇n = 0 at both ends) the step is x′ = x + Δs v / n with v
/// kept bit for bit: index 1 gives exactly straight rays.
pub fn ray_step(octree: &Sampler, r: &Ray, ds: f32, integrator: Integrator) -> Ray {
    let (x, v, n0, g0) = (r.x, r.v, r.n, r.g);
    let dt = ds / n0;
    let (x1, v1, n1, g1) = match integrator {
        Integrator::Euler => {
            let x1 = x + v * dt;
            let (n1, g1) = index_at(octree, x1);
            (x1, v + g0 * ds, n1, g1)
        }
        Integrator::Midpoint => {
            let (_, gm) = index_at(octree, x + v * (0.5 * dt));
            let x1 = if gm == Vec3::ZERO { x + v * dt } else { x + (v + gm * (0.5 * ds)) * dt };
            let (n1, g1) = index_at(octree, x1);
            (x1, v + gm * ds, n1, g1)
        }
        Integrator::Verlet => {
            // |v| = n at x (kept every step): n∇n = |v| ∇n there.
            let half = if g0 == Vec3::ZERO { v } else { v + g0 * (0.5 * dt * n0) };
            let x1 = x + half * dt;
            let (n1, g1) = index_at(octree, x1);
            (x1, if g1 == Vec3::ZERO { half } else { half + g1 * (0.5 * dt * n1) }, n1, g1)
        }
    };
    let v1 = if v1 == v {
        if n1 == n0 {
            v
        } else {
            v * (n1 / n0)
        }
    } else {
        v1.try_normalize().unwrap_or(v / n0) * n1
    };
    Ray { x: x1, v: v1, n: n1, g: g1 }
}

/// A 4 × 4 × 4 block of voxels' bytes, one cache line.
#[derive(Clone, Copy, PartialEq, Debug)]
#[repr(align(64))]
struct Brick([u8; 64]);

/// The octree's clearance channel as one byte a voxel (2 MiB at 128³, where the octree holds
/// 64 MiB), in 4³ bricks of one cache line each: straight runs read a voxel's byte from a grid
/// that stays in cache, and a walk's next voxels mostly from the line it already has.
#[derive(PartialEq, Debug)]
pub struct Clearance {
    bricks: Vec<Brick>,
    /// Bricks along each axis.
    bdims: [usize; 3],
    dims: [usize; 3],
    min: Vec3,
    max: Vec3,
    /// Voxels per world unit along each axis.
    scale: Vec3,
    /// The smallest side of a voxel (world units).
    hmin: f32,
}

impl Clearance {
    /// The clearance of `octree` (`Octree`'s output).
    pub fn of(octree: &Volume) -> Clearance {
        let ch = octree.channels as usize;
        Clearance::from_rows(octree, |i| octree.data[i * ch + CLEARANCE].clamp(0.0, 255.0) as u8)
    }

    /// The clearance of `octree` from each voxel's clearance byte, `byte(voxel index)` (what
    /// `Octree` computes before it writes the channel, so that it need not read it back).
    pub fn from_rows(octree: &Volume, byte: impl Fn(usize) -> u8 + Sync) -> Clearance {
        use rayon::prelude::*;
        let dims = octree.dims.map(|d| d as usize);
        let bdims = dims.map(|d| d.div_ceil(4));
        let mut bricks = vec![Brick([0; 64]); bdims.iter().product()];
        // A slab of bricks (4 slices of voxels, read in order) a task.
        bricks.par_chunks_mut(bdims[0] * bdims[1]).enumerate().for_each(|(bz, slab)| {
            for z in bz * 4..(bz * 4 + 4).min(dims[2]) {
                for y in 0..dims[1] {
                    let row = (z * dims[1] + y) * dims[0];
                    for x in 0..dims[0] {
                        slab[(y >> 2) * bdims[0] + (x >> 2)].0[(z & 3) << 4 | (y & 3) << 2 | (x & 3)] = byte(row + x);
                    }
                }
            }
        });
        let s = Sampler::new(octree);
        Clearance { bricks, bdims, dims, min: octree.min, max: octree.max, scale: s.scale, hmin: octree.voxel().min_element() }
    }

    /// The clearance of `octree`, built once per octree value and shared by the nodes that
    /// read it (an orbit re-runs the paths and the render, not the octree).
    pub fn shared(octree: &Volume) -> std::sync::Arc<Clearance> {
        octree.derived.get("clearance", || Clearance::of(octree))
    }

    /// The bytes its bricks hold.
    pub fn bytes(&self) -> u64 {
        (self.bricks.len() * std::mem::size_of::<Brick>()) as u64
    }

    /// The clearance of voxel `c` (inside the grid).
    #[inline]
    fn at(&self, c: [usize; 3]) -> u8 {
        let b = ((c[2] >> 2) * self.bdims[1] + (c[1] >> 2)) * self.bdims[0] + (c[0] >> 2);
        self.bricks[b].0[(c[2] & 3) << 4 | (c[1] & 3) << 2 | (c[0] & 3)]
    }

    /// Whether the straight segment `a + t u`, t ∈ [0, len], crosses a voxel where rays may
    /// bend (clearance 0): if not, the medium leaves it exactly straight.
    pub fn crosses_bends(&self, a: Vec3, u: Vec3, len: f32) -> bool {
        let Some((t0, t1)) = box_interval(a, u, self.min, self.max) else { return false };
        let t1 = t1.min(len);
        t0 < t1 && self.straight_run(a + u * t0, u, t1 - t0) < t1 - t0
    }

    /// How far the straight line `a + t u` (`a` in the grid, `u` unit) goes, up to `len`,
    /// before it is in a voxel where rays may bend (clearance 0), a thousandth of a voxel into
    /// it; ∞ if it leaves the grid or passes `len` first. Through the voxels before it the
    /// trilinear gradient is below 10⁻⁶ per voxel (every centre a lookup there blends is a
    /// voxel or neighbour without a measurable gradient): a ray goes straight whatever the
    /// steps, so one step can cross them all. From a voxel of clearance c ≥ 2 the line jumps
    /// (a thousandth short of) c − 1 voxels along the axis it moves fastest along, so c − 1 at
    /// most along every axis (no voxel within c − 1 bends); from one of clearance 1 to the next
    /// voxel it enters (what a voxel walk would do).
    pub fn straight_run(&self, a: Vec3, u: Vec3, len: f32) -> f32 {
        let du = u * self.scale;
        let dims = Vec3::new(self.dims[0] as f32, self.dims[1] as f32, self.dims[2] as f32);
        // Moving `jump` along `u` moves one voxel along the fastest axis.
        let jump = 1.0 / du.abs().max_element();
        let mut t = 0.0f32;
        // Each pass enters a new voxel at least, and a line crosses at most the sum of the
        // sides (+ 3) voxels.
        for _ in 0..4 * (self.dims.iter().sum::<usize>() + 3) {
            let q = (a + u * t - self.min) * self.scale;
            // (A ten-thousandth of a voxel of slack: `a` may lie on the grid's face.)
            if !(q.cmpge(Vec3::splat(-1e-4)).all() && q.cmplt(dims + 1e-4).all()) || t > len {
                return f32::INFINITY;
            }
            let at = |k: usize| (q[k].max(0.0) as usize).min(self.dims[k] - 1);
            let c = [at(0), at(1), at(2)];
            let clearance = self.at(c);
            if clearance == 0 {
                return t;
            }
            // From clearance 3 on the jump (≥ 1.999 voxels along the fastest axis) is always the
            // longer: the voxel's exit lies at most a voxel (and a ten-thousandth) along it.
            let jumped = (clearance as f32 - 1.001) * jump;
            t += if clearance >= 3 { jumped } else { jumped.max(leaf_exit(q, du, c, 0) + 1e-3 * self.hmin) };
        }
        t
    }
}

/// Calls `f(voxel index, t0, t1)` for each voxel the segment `a + t u`, t ∈ [0, len], crosses
/// (u a unit vector in world space), in order (Amanatides–Woo in voxel units), until `f`
/// returns false.
pub fn for_each_voxel(v: &Volume, a: Vec3, u: Vec3, len: f32, mut f: impl FnMut(usize, f32, f32) -> bool) {
    let h = v.voxel();
    let q = v.to_grid(a);
    let du = u / h; // voxel units per world unit
    let mut cell = voxel_of(v, q).map(|c| c as i64);
    let dims = v.dims.map(|d| d as i64);
    let mut t_next = [0f32; 3];
    let mut t_delta = [0f32; 3];
    let mut stepv = [0i64; 3];
    for k in 0..3 {
        if du[k] > 0.0 {
            stepv[k] = 1;
            t_next[k] = ((cell[k] + 1) as f32 - q[k]) / du[k];
            t_delta[k] = 1.0 / du[k];
        } else if du[k] < 0.0 {
            stepv[k] = -1;
            t_next[k] = (cell[k] as f32 - q[k]) / du[k];
            t_delta[k] = -1.0 / du[k];
        } else {
            t_next[k] = f32::INFINITY;
            t_delta[k] = f32::INFINITY;
        }
        t_next[k] = t_next[k].max(0.0);
    }
    let mut t = 0.0f32;
    let mut guard = (dims[0] + dims[1] + dims[2] + 3) as usize;
    while t < len && guard > 0 {
        guard -= 1;
        let k = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
            0
        } else if t_next[1] <= t_next[2] {
            1
        } else {
            2
        };
        let t1 = t_next[k].min(len);
        if t1 > t && !f(v.index(cell[0] as usize, cell[1] as usize, cell[2] as usize) / v.channels as usize, t, t1) {
            return;
        }
        t = t1;
        cell[k] += stepv[k];
        t_next[k] += t_delta[k];
        if cell[k] < 0 || cell[k] >= dims[k] {
            break;
        }
    }
}

/// Optical depth ∫ κ along the straight segment `a + t u`, t ∈ [0, len] (κ in channel 1 of
/// `medium`), by the midpoint rule on steps of at most one voxel.
pub fn optical_depth(medium: &Volume, a: Vec3, u: Vec3, len: f32) -> f32 {
    let h = medium.voxel().min_element();
    let n = (len / h).ceil().clamp(1.0, 1e6) as usize;
    let dt = len / n as f32;
    (0..n).map(|i| medium.sample(a + u * ((i as f32 + 0.5) * dt), 1).max(0.0) * dt).sum()
}

/// The frame of a planar receiver: `(origin, u, v)` spanning the object's bounding rectangle
/// in its plane with `u × v` along its front normal. An object off a plane (by more than
/// 10⁻⁴ of its size) or without area is an error naming it.
pub fn planar_frame(scene: &Scene, object: usize) -> Result<(Vec3, Vec3, Vec3), NodeError> {
    let o = &scene.objects[object];
    let (mut nsum, mut pts) = (Vec3::ZERO, Vec::new());
    for t in o.triangles.clone() {
        let (n, a) = scene.normal_area(t as usize);
        nsum += n * a;
        pts.extend(scene.corners(t as usize));
    }
    let Some(n) = nsum.try_normalize() else {
        return Err(NodeError::param("receiver", format!("object \"{}\" has no area to receive caustics", o.name)));
    };
    let c = pts[0];
    let size = pts.iter().map(|p| p.distance(c)).fold(0.0f32, f32::max).max(f32::MIN_POSITIVE);
    if pts.iter().any(|p| (*p - c).dot(n).abs() > 1e-4 * size) {
        return Err(NodeError::param("receiver", format!("object \"{}\" is not planar: caustic maps need a planar receiver", o.name)));
    }
    // u along the world axis most perpendicular to n, v = n × u.
    let axis = [Vec3::X, Vec3::Y, Vec3::Z].into_iter().min_by(|a, b| a.dot(n).abs().total_cmp(&b.dot(n).abs())).unwrap_or(Vec3::X);
    let eu = (axis - n * axis.dot(n)).normalize();
    let ev = n.cross(eu);
    let (mut lo, mut hi) = ([f32::INFINITY; 2], [f32::NEG_INFINITY; 2]);
    for p in &pts {
        let s = [(*p - c).dot(eu), (*p - c).dot(ev)];
        for k in 0..2 {
            lo[k] = lo[k].min(s[k]);
            hi[k] = hi[k].max(s[k]);
        }
    }
    let origin = c + eu * lo[0] + ev * lo[1];
    Ok((origin, eu * (hi[0] - lo[0]).max(size * 1e-6), ev * (hi[1] - lo[1]).max(size * 1e-6)))
}

/// The luminance weights of linear RGB (Rec. 709).
pub fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::testing::test_scene;

    fn grid(d: u32, value: [f32; 3]) -> Volume {
        let mut v = Volume::try_new([d; 3], 3, Vec3::ZERO, Vec3::ONE, 0.0, u64::MAX).unwrap();
        for c in v.data.chunks_mut(3) {
            c.copy_from_slice(&value);
        }
        v
    }

    fn octree(v: &Volume) -> Volume {
        let p = super::super::octree::Octree { uniform: 0.005, flat: 0.02, step: 8.0 };
        super::super::octree::build(v, &p, u64::MAX).unwrap().0
    }

    #[test]
    fn a_midpoint_step_is_closer_than_an_euler_step_to_the_finely_stepped_ray() {
        // n = 1 + (x − 0.5)² / 2 on a 32³ grid: a ray along z at x = 0.6 bends toward +x. One
        // step of 4 voxels against 400 Verlet steps over the same length.
        let mut g = grid(32, [1.0, 0.0, 0.0]);
        for z in 0..32 {
            for y in 0..32 {
                for x in 0..32 {
                    let i = g.index(x, y, z);
                    g.data[i] = 1.0 + 0.5 * (g.centre(x, y, z).x - 0.5).powi(2);
                }
            }
        }
        let ov = octree(&g);
        let o = Sampler::new(&ov);
        let start = Ray::new(&o, Vec3::new(0.6, 0.5, 0.3), Vec3::new(0.3, 0.0, 1.0).normalize());
        let ds = 4.0 / 32.0;
        let mut fine = start;
        for _ in 0..400 {
            fine = ray_step(&o, &fine, ds / 400.0, Integrator::Verlet);
        }
        let err = |i: Integrator| {
            let r = ray_step(&o, &start, ds, i);
            (r.x - fine.x).length() + (r.dir() - fine.dir()).length()
        };
        let (mid, euler) = (err(Integrator::Midpoint), err(Integrator::Euler));
        assert!(mid < 0.3 * euler, "midpoint {mid}, Euler {euler}");
    }

    #[test]
    fn index_one_keeps_the_ray_exactly_straight_and_a_gradient_bends_it_toward_higher_index() {
        let v = grid(16, [1.0, 0.0, 0.0]);
        let ov = octree(&v);
        let o = Sampler::new(&ov);
        let d = Vec3::new(0.3, 0.5, 0.2).normalize();
        let mut r = Ray::new(&o, Vec3::splat(0.2), d);
        for _ in 0..10 {
            r = ray_step(&o, &r, 0.03, Integrator::Verlet);
        }
        assert_eq!(r.v, d, "the direction bit for bit");
        assert!((r.x - (Vec3::splat(0.2) + d * 0.3)).length() < 1e-6);
        // n = 1 + x: a ray along z bends toward +x and keeps |v| = n.
        let mut g = grid(16, [1.0, 0.0, 0.0]);
        for z in 0..16 {
            for y in 0..16 {
                for xx in 0..16 {
                    let i = g.index(xx, y, z);
                    g.data[i] = 1.0 + g.centre(xx, y, z).x;
                }
            }
        }
        let ov = octree(&g);
        let o = Sampler::new(&ov);
        let r = ray_step(&o, &Ray::new(&o, Vec3::new(0.5, 0.5, 0.2), Vec3::Z), 0.05, Integrator::Euler);
        assert!(r.v.x > 0.0 && (r.v.length() - g.sample(r.x, 0)).abs() < 1e-5, "{r:?}");
        assert_eq!((r.n, r.g), index_at(&o, r.x), "the step's end carries n and ∇n there");
    }

    #[test]
    fn a_straight_run_ends_in_the_first_voxel_a_voxel_walk_finds_bending() {
        // 24 bumps of index in a 30 × 33 × 29 grid (sides that are not multiples of the
        // clearance's 4³ bricks) over a box that is not a cube; 400 seeded rays from inside it. The clearance's jumps must stop in the voxel where the walk through every
        // voxel first meets one that may bend rays, a thousandth of a voxel into it, or run
        // out of the grid where the walk finds none.
        use relume_base::math::rng::uniform;
        let dims = [30, 33, 29];
        let mut v = Volume::try_new(dims, 3, Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.0, 0.5, 3.0), 1.0, u64::MAX).unwrap();
        for k in 0..24u64 {
            let b = [0, 1, 2].map(|d| (uniform(76, k, d as u32) * dims[d] as f32) as usize);
            let i = v.index(b[0], b[1], b[2]);
            v.data[i] = 1.1 + 0.05 * k as f32;
        }
        let oct = octree(&v);
        let c = Clearance::of(&oct);
        let ch = oct.channels as usize;
        let (mut found, mut missed) = (0, 0);
        for r in 0..400u64 {
            let u3 = |d: u32| uniform(77, r, d);
            let a = v.min + (v.max - v.min) * Vec3::new(u3(0), u3(1), u3(2));
            let u = Vec3::new(u3(3) - 0.5, u3(4) - 0.5, u3(5) - 0.5).normalize();
            let mut first = None;
            for_each_voxel(&oct, a, u, 1e3, |i, t0, _| {
                if oct.data[i * ch + CLEARANCE] == 0.0 {
                    first = Some((i, t0));
                    return false;
                }
                true
            });
            let run = c.straight_run(a, u, f32::INFINITY);
            match first {
                None => {
                    assert_eq!(run, f32::INFINITY, "ray {r}: no voxel bends on its line");
                    missed += 1;
                }
                Some((i, t0)) => {
                    let h = oct.voxel().min_element();
                    assert!(run >= t0 - 1e-4 * h && run <= t0 + 2e-3 * h, "ray {r}: run {run} against the walk's {t0}");
                    let q = voxel_of(&oct, oct.to_grid(a + u * run));
                    assert_eq!(oct.index(q[0], q[1], q[2]) / ch, i, "ray {r} stops in the voxel the walk found");
                    found += 1;
                }
            }
        }
        assert!(found > 40 && missed > 40, "{found} rays meet a bump, {missed} do not");
    }

    #[test]
    fn leaf_exits_and_box_intervals() {
        // A level-2 cell (4 voxels) holding voxel (5, 1, 2) spans [4, 8) × [0, 4) × [0, 4).
        let t = leaf_exit(Vec3::new(5.5, 1.5, 2.5), Vec3::X, [5, 1, 2], 2);
        assert_eq!(t, 2.5);
        let t = leaf_exit(Vec3::new(5.5, 1.5, 2.5), -Vec3::Y, [5, 1, 2], 2);
        assert_eq!(t, 1.5);
        assert_eq!(leaf_exit(Vec3::new(5.5, 1.5, 2.5), Vec3::Z, [5, 1, 2], 0), 0.5);
        assert_eq!(box_interval(Vec3::new(-1.0, 0.5, 0.5), Vec3::X, Vec3::ZERO, Vec3::ONE), Some((1.0, 2.0)));
        assert_eq!(box_interval(Vec3::new(0.5, 0.5, 0.5), Vec3::X, Vec3::ZERO, Vec3::ONE), Some((0.0, 0.5)));
        assert_eq!(box_interval(Vec3::new(-1.0, 2.0, 0.5), Vec3::X, Vec3::ZERO, Vec3::ONE), None);
        assert_eq!(box_interval(Vec3::new(2.0, 0.5, 0.5), Vec3::X, Vec3::ZERO, Vec3::ONE), None, "behind");
    }

    #[test]
    fn voxel_traversal_covers_the_segment_once_in_order() {
        let v = grid(8, [1.0, 0.0, 0.0]);
        for (a, u, len) in [
            (Vec3::new(0.01, 0.02, 0.03), Vec3::new(1.0, 1.0, 1.0).normalize(), 1.6),
            (Vec3::new(0.9, 0.5, 0.5), -Vec3::X, 0.7),
            (Vec3::new(0.3, 0.3, 0.3), Vec3::new(0.2, -0.5, 0.9).normalize(), 0.25),
        ] {
            let mut segs = Vec::new();
            for_each_voxel(&v, a, u, len, |i, t0, t1| {
                segs.push((i, t0, t1));
                true
            });
            let covered: f32 = segs.iter().map(|s| s.2 - s.1).sum();
            let inside = box_interval(a, u, Vec3::ZERO, Vec3::ONE).map_or(0.0, |(_, t1)| t1.min(len));
            assert!((covered - inside).abs() < 1e-5, "{covered} vs {inside}");
            assert!(segs.windows(2).all(|w| w[0].2 == w[1].1 && w[0].0 != w[1].0));
            // Each piece's midpoint lies in its voxel.
            for &(i, t0, t1) in &segs {
                let q = v.to_grid(a + u * ((t0 + t1) / 2.0));
                let c = voxel_of(&v, q);
                assert_eq!(v.index(c[0], c[1], c[2]) / 3, i);
            }
        }
        let mut segs = 0;
        for_each_voxel(&v, Vec3::splat(0.5), Vec3::X, 0.01, |_, _, _| {
            segs += 1;
            true
        });
        assert_eq!(segs, 1);
        let k = grid(8, [1.0, 2.0, 0.0]);
        assert!((optical_depth(&k, Vec3::splat(0.1), Vec3::Y, 0.5) - 1.0).abs() < 1e-5);
    }

    #[test]
    fn emitters_become_point_lights_of_the_same_power_and_receivers_need_a_plane() {
        let mut s = test_scene::spheres();
        s.objects[0].emission = Vec3::splat(2.0);
        let lights = photon_lights(&s);
        let area: f32 = s.objects[0].triangles.clone().map(|t| s.normal_area(t as usize).1).sum();
        let l = lights.last().unwrap();
        let Light::Point { intensity, .. } = l.light else { panic!("{l:?}") };
        assert!((intensity.x * 4.0 * std::f32::consts::PI - std::f32::consts::PI * 2.0 * area).abs() < 1e-3 * area, "Φ = π L A");
        assert!(l.radius > 0.0);
        let floor = s.objects.iter().position(|o| o.name == "floor").unwrap();
        let (o, u, v) = planar_frame(&s, floor).unwrap();
        assert!(u.cross(v).normalize().dot(s.normal_area(s.objects[floor].triangles.start as usize).0) > 0.999);
        assert!(o.is_finite());
        let e = planar_frame(&s, 1).unwrap_err().to_string();
        assert!(e.contains("not planar"), "{e}");
        assert_eq!(intensity_along(&l.light, Vec3::X), intensity);
    }
}
