use super::blur::{blur, kernel};
use super::caustic_blur::{blur_caustics, working_bytes};
use super::octree_layout::{CLEARANCE, LEVEL, MAX_STEP};
use super::optics::{
    box_interval, for_each_voxel, leaf_exit, luminance, photon_lights, planar_frame, ray_step, voxel_of, Clearance, Integrator, Ray,
};
use crate::types::{CausticMap, Landing, PhotonDeposits, Photons, Sampler, SurfacePhotons, Volume};
use glam::Vec3;
use rayon::prelude::*;
use relume_base::math::morton::morton3;
use relume_base::types::{Accel, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, params, NodeError, RunCtx, ShardSpec};
use std::ops::Range;
use std::sync::atomic::{AtomicI64, Ordering};
use std::sync::{Mutex, OnceLock};

params! {
    /// Photons through a refractive, absorbing and scattering medium ([S] 6.3.4, 6-1 … 6-6):
    /// each photon follows the ray equation v = n dx/ds, dv/ds = ∇n, with |v| = n restored every
    /// step — by Störmer–Verlet steps (`integrator`; the thesis' Euler step x += Δs v / n,
    /// v += Δs ∇n is the other choice: it lets totally reflected light leak, see
    /// `optics::Integrator`; steps longer than Δs_min, through leaves flat within ε′, are
    /// explicit midpoint steps either way); its power falls as e^{−κΔs}. The step
    /// Δs is the distance to the boundary of the photon's octree leaf along its direction,
    /// at least `min_step` (Δs_min) and at most the leaf's Δs_max (`Octree`); in a uniform leaf
    /// (Δs_max unbounded) where no ray bends, the photon flies straight on across leaves to the
    /// first voxel that may bend it, in one step (the octree's clearance: the trilinear gradient
    /// is below 10⁻⁶ per voxel all the way, so the stepped ray would go as straight). Along every step the
    /// photon deposits its power × the length it travels in each voxel it crosses (where σ > 0)
    /// and its luminance × length × direction; those sums over the voxel's volume are the fluence
    /// (W/unit²) and the mean light direction `EikonalRender` reads, after a 3³ Gaussian
    /// (`blur_sigma`). Photons leave the box (then fly straight on), fall below `cutoff` of their
    /// power, or hit a surface; marching stops when fewer than `stop_fraction` of a chunk's photons
    /// remain ([S]: 1/1000; counted every 8 steps: photons in Morton order of their first voxel,
    /// in groups of 64 neighbours that take 8 steps in turn, a step of each photon of the group
    /// after the other — independent work the processor overlaps, on voxels in cache) or after
    /// `max_steps` steps. Caustics: the light is split by straight
    /// lines. A photon whose straight line crosses no voxel where rays may bend (`Octree`'s
    /// clearance 0) would go exactly straight: its light reaches surfaces as the render's direct light
    /// (straight, attenuated by the medium's transmittance), so it adds nothing to the map (and
    /// is not marched at all where nothing absorbs or scatters). Every other photon is marched
    /// and adds its power where it lands on the planar `receiver`, where the render's shadow rays
    /// — crossing the same voxels — give no direct light. The map is in W/unit²,
    /// blurred by a Gaussian of `map_blur` texels that keeps to its side of the shadow's edge
    /// (a texel's photons go to neighbours as dark as it under the shadow-ray test, the map's
    /// power kept). Sums are fixed-point integers (2⁻⁴⁰ of the
    /// largest deposit), so threads and shards give the same bytes in any order. Sharded over
    /// photons in chunks of 2¹⁸; the 1/1000 rule applies per chunk. Output `radiance`: 6 channels
    /// (fluence RGB, light direction xyz) on the medium's grid, or one empty voxel when nothing
    /// scatters (σ = 0 everywhere: nothing to store).
    pub struct MarchPhotons {
        /// Δs_min, the smallest step
        pub min_step: f32 = 1.0, range = 0.05..=16.0, unit = "voxels";
        /// how the ray equation is stepped
        pub integrator: Integrator = Verlet;
        /// a photon is dropped below this fraction of its initial power
        pub cutoff: f32 = 0.001, range = 0.0..=1.0;
        /// marching stops when fewer than this fraction of a chunk's photons remain
        pub stop_fraction: f32 = 0.001, range = 0.0..=1.0;
        /// the most steps a photon takes
        pub max_steps: u32 = 20000, range = 1..=10000000;
        /// the planar object whose caustics go into a texel map ("": none; the photons landing
        /// on every other surface are kept as points)
        pub receiver: String = "floor";
        /// caustic-map texels along the receiver's longer side
        pub map_resolution: u32 = 256, range = 1..=8192, unit = "texels";
        /// standard deviation of the 3³ Gaussian on the stored radiance (0: none)
        pub blur_sigma: f32 = 1.0, range = 0.0..=4.0, unit = "voxels";
        /// radius of the Gaussian on the caustic map (σ = radius; 0: none), not crossing the
        /// shadow's edge
        pub map_blur: u32 = 1, range = 0..=8, unit = "texels";
        /// radius of the density estimate of the photons landed off the receiver
        pub surface_radius: f32 = 4.0, range = 0.05..=64.0, unit = "voxels";
    }
}

inputs!(pub MarchPhotonsIn { scene: Scene, accel: Accel, medium: Volume, octree: Volume, photons: Photons });
outputs!(pub MarchPhotonsOut { radiance: Volume, caustics: CausticMap });

/// Steps a photon takes between two counts of the photons still marching.
const BATCH: u32 = 8;

/// Photons per chunk.
pub const CHUNK: u64 = 1 << 18;

/// Counter slots of a partial.
const PHOTONS: usize = 0;
const STEPS: usize = 1;
const LANDED: usize = 2;
const LEFT: usize = 3;
const ABSORBED: usize = 4;
const STOPPED: usize = 5;
const BLOCKED: usize = 6;
const STRAIGHT: usize = 7;
const COUNTERS: usize = 8;

/// What happened to a photon in a step.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Fate {
    Alive,
    Landed,
    Left,
    Absorbed,
    Blocked,
}

/// What a photon's straight segment meets: nothing, a surface from behind (or the receiver
/// off its map), a texel of the receiver's map, or another surface (point, normal, object).
#[derive(Clone, Copy)]
enum Spot {
    Away,
    Back,
    Texel(usize),
    Surface(Vec3, Vec3, u32),
}

#[derive(Clone, Copy)]
struct Photon {
    /// Its number among the node's photons.
    id: u32,
    ray: Ray,
    power: Vec3,
    floor: f32,
    bent: bool,
    /// How far the photon goes straight from `ray.x` before a voxel that may bend it, where
    /// already known (the first step: found when the photon was sorted), else negative.
    run: f32,
    fate: Fate,
}

/// Everything a chunk and the gather share, derived from the inputs and parameters only.
struct Setup<'a> {
    scene: &'a Scene,
    accel: &'a Accel,
    m: &'a Volume,
    oct: &'a Volume,
    /// Lookups of n and ∇n in `oct`.
    oct_s: Sampler<'a>,
    /// Its clearance, for straight runs (built when photons march, not for the gather).
    clearance: OnceLock<std::sync::Arc<Clearance>>,
    photons: &'a Photons,
    p: &'a MarchPhotons,
    slots: Vec<u32>,
    n_slots: usize,
    has_kappa: bool,
    map: CausticMap,
    obstacles: Option<(Vec3, Vec3)>,
    vol_scale: f64,
    map_scale: f64,
    eps: f32,
}

impl<'a> Setup<'a> {
    /// The octree's clearance bricks, on first use (shared with the other nodes reading the
    /// octree, see `Clearance::shared`; set outside any lock, for the reason given there).
    fn clearance(&self) -> &Clearance {
        if let Some(c) = self.clearance.get() {
            return c;
        }
        let _ = self.clearance.set(Clearance::shared(self.oct));
        self.clearance.get().expect("set above or by another thread")
    }

    fn new(i: &MarchPhotonsIn<'a>, p: &'a MarchPhotons, budget: u64) -> Result<Setup<'a>, NodeError> {
        let (m, oct) = (i.medium, i.octree);
        if oct.dims != m.dims || oct.channels != super::octree_layout::CHANNELS || oct.min != m.min || oct.max != m.max {
            return Err(NodeError::failed(format!(
                "the octree ({:?}, {} channels) was not built on the medium's grid ({:?}): wire the same medium into Octree",
                oct.dims, oct.channels, m.dims
            )));
        }
        let ch = m.channels as usize;
        // Whether anything absorbs, and the voxels that scatter: found once per medium.
        let (has_kappa, n_slots) = (m.absorbs(), m.scatterers());
        let map = match p.receiver.as_str() {
            "" => CausticMap::none(),
            name => {
                let Some(o) = i.scene.objects.iter().position(|o| o.name == name) else {
                    let names: Vec<_> = i.scene.objects.iter().map(|o| o.name.as_str()).collect();
                    return Err(NodeError::param("receiver", format!("no object \"{name}\" (objects: {})", names.join(", "))));
                };
                let (origin, u, v) = planar_frame(i.scene, o)?;
                let r = p.map_resolution as f32;
                let (lu, lv) = (u.length(), v.length());
                let (w, h) = if lu >= lv { (r, (r * lv / lu).ceil()) } else { ((r * lu / lv).ceil(), r) };
                let (w, h) = (w.max(1.0) as u32, h.max(1.0) as u32);
                CausticMap { object: o as u32, origin, u, v, width: w, height: h, texels: Vec::new(), surface: SurfacePhotons::default() }
            }
        };
        let chunk = CHUNK.min(i.photons.len() as u64);
        let need = (n_slots as u64 * 6 + map.width as u64 * map.height as u64 * 3) * 8 * 2
            + working_bytes(map.width as u64 * map.height as u64)
            + crate::types::surface_photons::bytes_for(i.photons.len() as u64)
            + chunk * std::mem::size_of::<Photon>() as u64
            + if n_slots > 0 { Volume::bytes_for(m.dims, 6) * 2 } else { 0 }
            + m.voxels() as u64 * 5;
        if need > budget {
            return Err(NodeError::OverLimit {
                param: Some("map_resolution".into()),
                msg: format!("marching needs {} (deposits, caustic map, photons), over the {} budget", fmt_bytes(need), fmt_bytes(budget)),
            });
        }
        let mut slots = vec![u32::MAX; if n_slots > 0 { m.voxels() } else { 0 }];
        let mut k = 0u32;
        for (s, c) in slots.iter_mut().zip(m.data.chunks(ch)) {
            if c[2] > 0.0 {
                *s = k;
                k += 1;
            }
        }
        let obstacles = i.accel.bounds_within(m.min, m.max);
        let pmax = i.photons.power.iter().fold(0.0f32, |a, p| a.max(p.max_element())).max(f32::MIN_POSITIVE) as f64;
        let diag = m.voxel().length() as f64;
        // Relative to the box and to the coordinates' magnitude, never absolute: the same
        // picture for a scene 10⁻³ or 10³ across.
        let eps = 1e-5 * (m.max - m.min).length() + 1e-6 * m.max.abs().max(m.min.abs()).max_element();
        Ok(Setup {
            scene: i.scene,
            accel: i.accel,
            m,
            oct,
            oct_s: Sampler::new(oct),
            clearance: OnceLock::new(),
            photons: i.photons,
            p,
            slots,
            n_slots,
            has_kappa,
            map,
            obstacles,
            vol_scale: (1u64 << 40) as f64 / (pmax * diag),
            map_scale: (1u64 << 40) as f64 / pmax,
            eps,
        })
    }

    fn texels(&self) -> usize {
        if self.map.object == u32::MAX {
            0
        } else {
            (self.map.width * self.map.height) as usize
        }
    }

    /// Where the ray `o + t u`, t > 0, first meets the scene (the distance, or none), and
    /// what it meets there. Starts a hair behind `o` (the box face may lie in the receiver's
    /// plane).
    fn land(&self, o: Vec3, u: Vec3, tmax: f32) -> (Option<f32>, Spot) {
        let o = o - u * self.eps;
        let Some(hit) = self.accel.intersect(o, u, 0.0, tmax + self.eps) else { return (None, Spot::Away) };
        let t = (hit.t - self.eps).max(0.0);
        let (object, ng, at) = (self.scene.tri_object[hit.tri as usize], hit.ng, o + u * hit.t);
        if ng.dot(u) >= 0.0 {
            return (Some(t), Spot::Back);
        }
        if object == self.map.object && self.texels() > 0 {
            return (Some(t), self.map.texel(at).map_or(Spot::Back, Spot::Texel));
        }
        (Some(t), Spot::Surface(at, ng, object))
    }

    fn add_map(&self, acc: &[AtomicI64], texel: usize, power: Vec3) {
        for c in 0..3 {
            let q = (power[c] as f64 * self.map_scale).round() as i64;
            if q != 0 {
                acc[texel * 3 + c].fetch_add(q, Ordering::Relaxed);
            }
        }
    }

    /// One step of photon `ph` (see the node's doc); deposits into `vol`, `map` and `landed`
    /// (with the photon's number).
    fn advance(&self, ph: &mut Photon, vol: &[AtomicI64], map: &[AtomicI64], landed: &Mutex<Vec<(u32, Landing)>>) -> Fate {
        let (m, oct) = (self.m, self.oct);
        let h = m.voxel();
        let hmin = h.min_element();
        let x = ph.ray.x;
        let q = self.oct_s.to_grid(x);
        let c = voxel_of(m, q);
        let oi = oct.index(c[0], c[1], c[2]);
        let (level, smax) = (oct.data[oi + LEVEL].max(0.0) as u32, oct.data[oi + MAX_STEP]);
        let u = ph.ray.dir();
        let lo = self.p.min_step * hmin;
        let hi = smax.max(self.p.min_step) * hmin;
        // In a uniform leaf where no ray bends the photon flies straight on to the first voxel
        // that may bend it (a thousandth of a voxel into it, so that the next step starts
        // there): the octree's unbounded step, taken across leaves.
        let run = if smax == f32::INFINITY && oct.data[oi + CLEARANCE] > 0.0 {
            if ph.run >= 0.0 {
                ph.run
            } else {
                self.clearance().straight_run(x, u, f32::INFINITY)
            }
        } else {
            0.0
        };
        // (A run of 0: `x` on the face of a voxel that bends, which the lookup put in its
        // neighbour.)
        let straight = run > 0.0;
        let mut ds = if straight {
            run
        } else if hi > lo {
            leaf_exit(q, u / h, c, level).max(lo).min(hi)
        } else {
            lo
        };
        // A step that ends inside the box does not leave it (the box is convex); one that does
        // not is cut at the box's face.
        let end = x + u * ds;
        let leaving = !(end.cmpgt(m.min).all() && end.cmplt(m.max).all());
        if leaving {
            ds = box_interval(x, u, m.min, m.max).map_or(0.0, |(_, t1)| t1);
        }
        // Where it meets a surface: beyond the box when leaving (traced from the step's start,
        // never from the exit point, which may lie in a floor's plane), or inside the box where
        // a surface reaches into it.
        // A surface up to half a voxel past the step's end is taken now: the next step would
        // start too close to it to be found.
        let reach = ds + 0.5 * hmin;
        let near = self.obstacles.is_some_and(|(olo, ohi)| {
            let end = x + u * reach;
            x.min(end).cmple(ohi + self.eps).all() && x.max(end).cmpge(olo - self.eps).all()
        });
        let mut end = None;
        if leaving || near {
            let (t, spot) = self.land(x, u, if leaving { f32::INFINITY } else { reach });
            match t {
                Some(t) if t < reach => {
                    ds = t;
                    end = Some(spot);
                }
                _ if leaving => end = Some(spot),
                _ => {}
            }
        }
        if self.has_kappa || self.n_slots > 0 {
            let ch = m.channels as usize;
            let mut power = ph.power;
            for_each_voxel(m, x, u, ds, |vi, t0, t1| {
                let l = t1 - t0;
                let kappa = if ch > 1 { m.data[vi * ch + 1].max(0.0) } else { 0.0 };
                let att = (-kappa * l).exp();
                if let Some(&s) = self.slots.get(vi).filter(|s| **s != u32::MAX) {
                    let w = if kappa * l > 1e-6 { (1.0 - att) / kappa } else { l };
                    let dep = power * w;
                    let dir = u * (luminance(power) * w);
                    for (k, val) in dep.to_array().into_iter().chain(dir.to_array()).enumerate() {
                        let qv = (val as f64 * self.vol_scale).round() as i64;
                        if qv != 0 {
                            vol[s as usize * 6 + k].fetch_add(qv, Ordering::Relaxed);
                        }
                    }
                }
                power *= att;
                true
            });
            ph.power = power;
        }
        if let Some(spot) = end {
            match spot {
                Spot::Texel(texel) if ph.bent => self.add_map(map, texel, ph.power),
                Spot::Surface(position, normal, object) if ph.bent => {
                    let l = Landing { position, normal, power: ph.power, object };
                    landed.lock().expect("no panics while held").push((ph.id, l));
                }
                _ => {}
            }
            return match (spot, leaving) {
                (Spot::Texel(_) | Spot::Surface(..), _) => Fate::Landed,
                (_, true) => Fate::Left,
                (_, false) => Fate::Blocked,
            };
        }
        if ph.power.max_element() < ph.floor {
            return Fate::Absorbed;
        }
        // Steps longer than Δs_min cross leaves flat within ε′: Verlet's closing kick would apply
        // the gradient at the far end (the next region's) over the whole step, and Euler's
        // the start's; the midpoint's lies inside the leaf. Measured on the glass scene
        // (benches/refract.rs): the caustic map 3.5 % from a quarter-voxel march with midpoint
        // long steps, 4.8 % with Euler ones, 6.8 % with Verlet ones (one-voxel steps
        // everywhere: 4.1 %).
        ph.run = -1.0;
        ph.ray = if straight {
            Ray::new(&self.oct_s, x + u * ds, u)
        } else {
            let integrator = if ds > lo * 1.0001 { Integrator::Midpoint } else { self.p.integrator };
            ray_step(&self.oct_s, &ph.ray, ds, integrator)
        };
        Fate::Alive
    }

    /// Marches photons `items` (one chunk) into a partial.
    fn march(&self, items: Range<u64>, cx: &RunCtx) -> Result<PhotonDeposits, NodeError> {
        let vol: Vec<AtomicI64> = (0..self.n_slots * 6).map(|_| AtomicI64::new(0)).collect();
        let map: Vec<AtomicI64> = (0..self.texels() * 3).map(|_| AtomicI64::new(0)).collect();
        let landed = Mutex::new(Vec::new());
        let keep_straight = self.has_kappa || self.n_slots > 0;
        let start: Vec<Option<Photon>> = items
            .clone()
            .into_par_iter()
            .map(|k| {
                let k = k as usize;
                let (x, d, power) = (self.photons.position[k], self.photons.direction[k].normalize(), self.photons.power[k]);
                if !(power.max_element() > 0.0 && d.is_finite() && x.is_finite()) {
                    return None;
                }
                // Where the straight line first meets a voxel that may bend it, if it does.
                let run = box_interval(x, d, self.m.min, self.m.max)
                    .map_or(f32::INFINITY, |(t0, t1)| t0 + self.clearance().straight_run(x + d * t0, d, t1 - t0));
                let bent = run.is_finite();
                (bent || keep_straight).then(|| Photon {
                    id: k as u32,
                    ray: Ray::new(&self.oct_s, x, d),
                    power,
                    floor: power.max_element() * self.p.cutoff,
                    bent,
                    run: if bent { run } else { -1.0 },
                    fate: Fate::Alive,
                })
            })
            .collect();
        let mut counters = vec![0u64; COUNTERS];
        counters[PHOTONS] = items.end - items.start;
        counters[STRAIGHT] = start.iter().filter(|p| p.is_none()).count() as u64;
        let mut alive: Vec<Photon> = start.into_iter().flatten().collect();
        // Neighbours in space next to each other in memory (Morton order of the starting
        // voxel): a thread's photons read the same octree voxels while they stay together.
        // Sums and counts do not depend on the order.
        alive.sort_by_cached_key(|p| {
            let q = self.oct_s.to_grid(p.ray.x);
            morton3(voxel_of(self.m, q))
        });
        let total = alive.len();
        let mut steps = 0u32;
        while !alive.is_empty() && alive.len() as f64 >= self.p.stop_fraction as f64 * total as f64 && steps < self.p.max_steps {
            cx.check()?;
            let batch = BATCH.min(self.p.max_steps - steps);
            counters[STEPS] += alive
                .par_chunks_mut(64)
                .map(|c| {
                    let mut n = 0u64;
                    for _ in 0..batch {
                        for ph in c.iter_mut().filter(|p| p.fate == Fate::Alive) {
                            ph.fate = self.advance(ph, &vol, &map, &landed);
                            n += 1;
                        }
                    }
                    n
                })
                .sum::<u64>();
            for ph in &alive {
                match ph.fate {
                    Fate::Alive => {}
                    Fate::Landed => counters[LANDED] += 1,
                    Fate::Left => counters[LEFT] += 1,
                    Fate::Absorbed => counters[ABSORBED] += 1,
                    Fate::Blocked => counters[BLOCKED] += 1,
                }
            }
            alive.retain(|p| p.fate == Fate::Alive);
            steps += batch;
            cx.progress((total - alive.len()) as u64, total as u64);
        }
        // Photons still marching when the 1/1000 rule (or the step limit) stops the chunk.
        counters[STOPPED] = alive.len() as u64;
        let take = |v: Vec<AtomicI64>| v.into_iter().map(AtomicI64::into_inner).collect();
        // In the photons' order, whatever the threads' (each photon lands once at most).
        let mut landed = landed.into_inner().expect("no panics while held");
        landed.sort_unstable_by_key(|(id, _)| *id);
        Ok(PhotonDeposits {
            volume: take(vol),
            map: take(map),
            counters,
            landed_position: landed.iter().map(|(_, l)| l.position).collect(),
            landed_normal: landed.iter().map(|(_, l)| l.normal).collect(),
            landed_power: landed.iter().map(|(_, l)| l.power).collect(),
            landed_object: landed.iter().map(|(_, l)| l.object).collect(),
        })
    }

    /// The outputs from the chunks' sums.
    fn finish(&self, parts: &[&PhotonDeposits], cx: &RunCtx) -> Result<(Volume, CausticMap, Vec<u64>), NodeError> {
        let mut vol = vec![0i64; self.n_slots * 6];
        let mut map = vec![0i64; self.texels() * 3];
        let mut counters = vec![0u64; COUNTERS];
        for part in parts {
            if part.volume.len() != vol.len() || part.map.len() != map.len() || part.counters.len() != COUNTERS {
                return Err(NodeError::failed("a partial result does not fit these inputs (sizes differ)"));
            }
            vol.iter_mut().zip(&part.volume).for_each(|(a, b)| *a = a.wrapping_add(*b));
            map.iter_mut().zip(&part.map).for_each(|(a, b)| *a = a.wrapping_add(*b));
            counters.iter_mut().zip(&part.counters).for_each(|(a, b)| *a += b);
        }
        let m = self.m;
        let radiance = if self.n_slots == 0 {
            Volume::try_new([1; 3], 6, m.min, m.max, 0.0, cx.memory_budget())?
        } else {
            let mut r = Volume::try_new(m.dims, 6, m.min, m.max, 0.0, cx.memory_budget())?;
            let inv = 1.0 / (self.vol_scale * m.voxel().to_array().iter().map(|&x| x as f64).product::<f64>());
            for (v, &s) in self.slots.iter().enumerate() {
                if s != u32::MAX {
                    for k in 0..6 {
                        r.data[v * 6 + k] = (vol[s as usize * 6 + k] as f64 * inv) as f32;
                    }
                }
            }
            blur(&r, &kernel(1, self.p.blur_sigma), cx)?
        };
        let mut caustics = self.map.clone();
        if caustics.object == u32::MAX {
            caustics = CausticMap::none();
        } else {
            let inv = 1.0 / (self.map_scale * caustics.texel_area() as f64);
            let at = |q: &i64| (*q as f64 * inv) as f32;
            let raw: Vec<Vec3> = map.chunks(3).map(|c| Vec3::new(at(&c[0]), at(&c[1]), at(&c[2]))).collect();
            let lights = photon_lights(self.scene);
            caustics.texels = blur_caustics(&raw, &caustics, &lights, self.clearance(), self.p.map_blur as usize, cx)?;
        }
        let landed: Vec<Landing> = parts.iter().flat_map(|p| p.landings()).collect();
        caustics.surface = SurfacePhotons::new(&landed, self.p.surface_radius * m.voxel().min_element());
        Ok((radiance, caustics, counters))
    }
}

#[node(category = "volume", version = 7, sharded, metrics = ["photons", "photon_steps", "steps_per_photon", "landed_pct", "left_pct", "absorbed_pct", "stopped_pct", "straight_pct"])]
impl MarchPhotons {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The radiance on the medium's grid (6 channels where it has 3) and its blur.
        let r = inputs[2].map(|s| relume_core::PortSize::bytes(s.bytes * 2));
        let map = (self.map_resolution as u64).pow(2) * 12;
        relume_core::MemoryEstimate {
            // The landed photons: at most one a photon.
            outputs: vec![
                r,
                Some(relume_core::PortSize::bytes(map + inputs[4].map_or(0, |s| crate::types::surface_photons::bytes_for(s.bytes / 36)))),
            ],
            working: inputs[2].map_or(0, |s| s.bytes * 4) + working_bytes((self.map_resolution as u64).pow(2)),
        }
    }

    fn shard(&self, i: &MarchPhotonsIn) -> Result<ShardSpec, NodeError> {
        Ok(ShardSpec::new(i.photons.len() as u64, CHUNK))
    }

    fn run_items(&self, i: &MarchPhotonsIn, items: Range<u64>, cx: &RunCtx) -> Result<PhotonDeposits, NodeError> {
        Setup::new(i, self, cx.memory_budget())?.march(items, cx)
    }

    fn gather(&self, i: &MarchPhotonsIn, parts: &[&PhotonDeposits], cx: &RunCtx) -> Result<MarchPhotonsOut, NodeError> {
        let setup = Setup::new(i, self, cx.memory_budget())?;
        let (radiance, caustics, c) = setup.finish(parts, cx)?;
        let n = c[PHOTONS].max(1) as f64;
        cx.metric("photons", c[PHOTONS] as f64);
        cx.metric("photon_steps", c[STEPS] as f64);
        cx.metric("steps_per_photon", c[STEPS] as f64 / n);
        cx.metric("landed_pct", 100.0 * c[LANDED] as f64 / n);
        cx.metric("left_pct", 100.0 * (c[LEFT] + c[BLOCKED]) as f64 / n);
        cx.metric("absorbed_pct", 100.0 * c[ABSORBED] as f64 / n);
        cx.metric("stopped_pct", 100.0 * c[STOPPED] as f64 / n);
        cx.metric("straight_pct", 100.0 * c[STRAIGHT] as f64 / n);
        if setup.n_slots == 0 {
            cx.note("nothing scatters (σ = 0 everywhere): no radiance stored in the volume");
        }
        Ok(MarchPhotonsOut { radiance, caustics })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::emit_photons::Proxy;
    use crate::test_support::*;
    use relume_base::scene::builder::SceneBuilder;
    use relume_base::testing::f;
    use relume_base::types::{Light, Material};
    use relume_core::Value;

    /// A floor at height `y` (4 × 4, facing up) under `light`.
    fn floor_scene(y: f32, light: Light) -> Scene {
        let grey = Material::Lambert { albedo: Vec3::splat(0.5) };
        SceneBuilder::new(Vec3::new(0.0, 2.0, 3.0), Vec3::ZERO, 40.0, 16, 16)
            .quad("floor", Vec3::new(-2.0, y, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), grey, Vec3::ZERO)
            .light(light)
            .build()
    }

    fn down(e: f32) -> Light {
        Light::Directional { direction: -Vec3::Y, irradiance: Vec3::splat(e) }
    }

    #[test]
    fn an_empty_volume_under_a_directional_light_holds_fluence_e() {
        // n = 1 and a vanishing medium (κ = σ = 10⁻⁶, so that fluence is stored at all).
        let s = floor_scene(-5.0, down(2.0));
        let m = source("Constant", 16, Vec3::ZERO, 2.0, &[("index", f(1.0)), ("extinction", f(1e-6)), ("scattering", f(1e-6))]);
        let a = accel_without(&s, "");
        let ph = photons(&s, &a, &m, 256, Proxy::Box);
        let p = MarchPhotons { receiver: "".into(), blur_sigma: 0.0, ..march_params(16) };
        let (r, map) = march(&s, &a, &m, &octree_of(&m), &ph, &p);
        assert_eq!(r.dims, [16; 3]);
        assert_eq!(map, CausticMap::none());
        let (mut sum, mut n) = (0.0f64, 0);
        for z in 1..15 {
            for y in 1..15 {
                for x in 1..15 {
                    let v = r.get(x, y, z, 0);
                    assert!((v / 2.0 - 1.0).abs() < 0.35, "voxel ({x}, {y}, {z}): {v}");
                    // The light direction: luminance-weighted, straight down.
                    assert!(r.get(x, y, z, 4) < 0.0 && r.get(x, y, z, 3).abs() < 1e-6 * v.abs().max(1.0));
                    sum += v as f64;
                    n += 1;
                }
            }
        }
        let mean = sum / n as f64;
        assert!((mean / 2.0 - 1.0).abs() < 0.01, "mean fluence {mean} vs E = 2");
    }

    #[test]
    fn index_one_bends_nothing_and_leaves_the_caustic_map_empty() {
        let s = floor_scene(-1.5, Light::Point { position: Vec3::new(0.5, 3.0, 0.2), intensity: Vec3::splat(5.0) });
        let m = source("Constant", 16, Vec3::ZERO, 2.0, &[("index", f(1.0))]);
        let a = accel_without(&s, "");
        let ph = photons(&s, &a, &m, 64, Proxy::Box);
        assert!(ph.len() > 1000);
        let (_, map) = march(&s, &a, &m, &octree_of(&m), &ph, &march_params(32));
        assert!(map.texels.iter().all(|t| *t == Vec3::ZERO), "straight photons cancel exactly");
    }

    #[test]
    fn the_caustic_map_holds_what_the_glass_intercepts_and_creates_no_light() {
        // The glass scene at 64³: photons whose straight line crosses bending voxels land on
        // the floor's map. Their power is at least what the sphere (radius 0.5, 2.874 from
        // the lamp's centre, intensity π r² L = 8.04) intercepts, I Ω = 0.771 (the blurred
        // shell around it bends light too), and at most what entered the medium's box.
        use crate::test_support::*;
        let (s, m, oct, a, ph) = glass_stages(64, 192);
        let (_, map) = march(&s, &a, &m, &oct, &ph, &march_params(128));
        let landed: f64 = map.texels.iter().map(|t| t.x as f64).sum::<f64>() * map.texel_area() as f64;
        let entered: f64 = ph.power.iter().map(|p| p.x as f64).sum();
        let intensity = 400.0 * std::f64::consts::PI * 0.08f64.powi(2);
        let omega = std::f64::consts::TAU * (1.0 - (1.0 - (0.5f64 / 8.26f64.sqrt()).powi(2)).sqrt());
        assert!(
            landed > 0.98 * intensity * omega && landed < entered,
            "{landed} landed, {} intercepted, {entered} entered",
            intensity * omega
        );
    }

    #[test]
    fn photons_off_the_receiver_bring_the_floor_the_light_its_map_would() {
        // The glass scene at 48³ with no receiver named: the photons that land on the floor
        // are kept as points. The power they hold is the map's, and the irradiance they give
        // over the floor under the sphere sums to the map's within the two estimates' blur.
        use crate::test_support::*;
        let (s, m, oct, a, ph) = glass_stages(48, 128);
        let (_, with_map) = march(&s, &a, &m, &oct, &ph, &march_params(96));
        let (_, points) = march(&s, &a, &m, &oct, &ph, &MarchPhotons { receiver: "".into(), ..march_params(96) });
        assert!(with_map.surface.is_empty(), "every landed photon on the receiver's map");
        assert_eq!(points.object, u32::MAX);
        let floor = s.objects.iter().position(|o| o.name == "floor").unwrap() as u32;
        assert!(points.surface.len() > 1000 && points.surface.object.iter().all(|&o| o == floor), "{}", points.surface.len());
        let map_power: f64 = with_map.texels.iter().map(|t| t.x as f64).sum::<f64>() * with_map.texel_area() as f64;
        let point_power = points.surface.total_power().x as f64;
        assert!((point_power / map_power - 1.0).abs() < 0.02, "{point_power} W as points, {map_power} W on the map");
        // Riemann sums over a 0.02 grid of the floor's square under the sphere (y = 0).
        let (mut a_sum, mut b_sum) = (0.0f64, 0.0f64);
        for i in 0..100 {
            for j in 0..100 {
                let p = Vec3::new(-1.0 + 0.02 * (i as f32 + 0.5), 0.0, -1.0 + 0.02 * (j as f32 + 0.5));
                a_sum += with_map.irradiance(floor, p, Vec3::Y).x as f64 * 4e-4;
                b_sum += points.irradiance(floor, p, Vec3::Y).x as f64 * 4e-4;
            }
        }
        assert!(a_sum > 0.3 * map_power, "the square holds most of the caustic: {a_sum} of {map_power}");
        assert!((b_sum / a_sum - 1.0).abs() < 0.02, "points {b_sum}, map {a_sum}");
        assert_eq!(points.irradiance(floor, Vec3::new(0.0, 0.0, 0.0), -Vec3::Y), Vec3::ZERO, "the floor's underside");
    }

    #[test]
    fn a_luneburg_lens_focuses_a_parallel_beam_on_its_far_side() {
        // n = √(2 − r²/R²): a parallel beam along −y meets at the sphere's bottom point
        // (0, −R, 0) (Luneburg 1944); the floor touches it there.
        let r = 0.5;
        let s = floor_scene(-r, down(1.0));
        let m = source("Luneburg", 48, Vec3::ZERO, 1.3, &[("radius", f(r as f64))]);
        let a = accel_without(&s, "");
        let ph = photons(&s, &a, &m, 160, Proxy::Active);
        let p = MarchPhotons { map_blur: 0, map_resolution: 400, ..march_params(400) };
        let (_, map) = march(&s, &a, &m, &octree_of(&m), &ph, &p);
        // Power (irradiance × texel area) within a radius ρ of the focus, against the power
        // that entered the lens (E π R²) less what the straight rays would have brought there.
        let ta = map.texel_area();
        let within = |rho: f32| -> f32 {
            let mut sum = 0.0;
            for (k, t) in map.texels.iter().enumerate() {
                let c = map.origin + map.u * ((k % 400) as f32 + 0.5) / 400.0 + map.v * ((k / 400) as f32 + 0.5) / 400.0;
                if c.x.hypot(c.z) < rho {
                    sum += t.x * ta;
                }
            }
            sum
        };
        let beam = std::f32::consts::PI * r * r;
        let (near, all) = (within(0.08 * r), within(2.0 * r));
        // What entered the lens lands (n = 1 at its rim: no loss at its surface), with the
        // light just outside the rim whose voxels still bend it (within 3 voxels: the central
        // differences and their neighbours), a large share within 0.08 R of the focus.
        let h = m.voxel().x;
        let rim = std::f32::consts::PI * (r + 3.0 * h).powi(2);
        assert!(all > 0.99 * beam && all < rim, "{beam} < {all} < {rim}");
        assert!(near > 0.5 * beam, "{near} of {beam} within 0.08 R of the focus");
    }

    #[test]
    fn extinction_zero_and_ten_thousand_give_finite_results() {
        let s = floor_scene(-1.5, down(1.0));
        for kappa in [0.0, 1e4] {
            let m = source("GrinSphere", 24, Vec3::ZERO, 2.0, &[("extinction", f(kappa)), ("scattering", f(kappa / 2.0))]);
            let a = accel_without(&s, "");
            let ph = photons(&s, &a, &m, 48, Proxy::Active);
            let (r, map) = march(&s, &a, &m, &octree_of(&m), &ph, &march_params(32));
            assert!(r.data.iter().all(|v| v.is_finite()) && map.texels.iter().all(|t| t.is_finite()), "κ = {kappa}");
            if kappa > 0.0 {
                // A photon entering loses all but 1/1000 within 7/κ: little gets deep.
                let centre = r.get(12, 12, 12, 0);
                assert!(centre.abs() < 1e-6, "{centre}");
                assert!(r.data.iter().step_by(6).any(|v| *v > 0.0), "fluence near the surface");
            }
        }
    }

    #[test]
    fn the_same_bytes_on_one_thread_and_many() {
        let (s, m, oct, a, ph) = glass_stages(24, 48);
        let run = || march(&s, &a, &m, &oct, &ph, &march_params(48));
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(run);
        let many = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap().install(run);
        assert_eq!(one.0.data, many.0.data);
        assert_eq!(one.1.texels, many.1.texels);
        assert!(one.1.texels.iter().any(|t| t.x > 0.0), "a caustic");
        let run = || march(&s, &a, &m, &oct, &ph, &MarchPhotons { receiver: "".into(), ..march_params(48) }).1.surface;
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().unwrap().install(run);
        let many = rayon::ThreadPoolBuilder::new().num_threads(4).build().unwrap().install(run);
        assert!(!one.is_empty());
        assert_eq!(one, many, "the landed photons, in any thread count");
    }

    #[test]
    fn it_reports_progress_and_stops_when_cancelled() {
        let (s, m, oct, a, ph) = glass_stages(16, 32);
        let inputs = vec![Value::new(s), Value::new(a), Value::new(m), Value::new(oct), Value::new(ph)];
        assert!(relume_base::testing::cancels_midway::<MarchPhotons>(&[], inputs) < 4);
    }
}
