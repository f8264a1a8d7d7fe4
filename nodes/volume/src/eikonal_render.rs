use super::optics::{box_interval, lamp_segment, luminance, optical_depth, photon_lights, Clearance, PhotonLight};
use crate::types::view_paths::Gather;
use crate::types::{CausticMap, ViewPaths, Volume};
use glam::Vec3;
use relume_base::brdf;
use relume_base::math::frame::Frame;
use relume_base::math::rng::uniform;
use relume_base::render::film::per_pixel;
use relume_base::render::integrator::Counts;
use relume_base::render::lights::delta_sample;
use relume_base::render::surface::Surface;
use relume_base::types::{Accel, Image, Material, Scene};
use relume_core::{inputs, node, outputs, params, NodeError, RunCtx};
use std::f32::consts::PI;

params! {
    /// The picture of a medium and its surroundings ([S] 6.3.5), shaded along the camera's curved
    /// rays `EikonalPaths` traced (so that a light edit re-shades them and does not trace them
    /// again): per camera sample, a surface in front of the medium's box is shaded directly;
    /// otherwise the path gathers the in-scattered light at its samples, σ × fluence × phase ×
    /// transmittance (the fluence and mean light direction `MarchPhotons` stored; phase
    /// Henyey–Greenstein of `g` about that direction, blended toward isotropic as the stored light
    /// is less directed; `g` = 0 is isotropic), and takes the light from where it leaves: a surface
    /// it meets is shaded by its BSDF under each light (the pipeline's lights, shadowed by the
    /// scene and by the medium's transmittance along straight shadow rays, `lamp_samples` of them
    /// spread over the disk of a light of some size, seeded by the point; a shadow ray crossing
    /// voxels where rays bend gets nothing, that light arriving as photons), plus the caustic map's
    /// irradiance × its diffuse albedo; with no surface, the environment. Pixels average their
    /// samples. The surfaces inside the medium's box must be those the paths met (`accel` with
    /// the same triangles there), else an error says so. Biases by construction: no reflection at
    /// the object's interface (no Fresnel split), an interface blurred over the voxelisation's
    /// Gaussian, single scattering only. Rows in parallel, the same bytes on any thread count.
    pub struct EikonalRender {
        /// Henyey–Greenstein asymmetry of the medium (0: isotropic)
        pub g: f32 = 0.0, range = -0.99..=0.99;
        /// shadow rays a shaded point sends toward a light of some size (an emissive object),
        /// spread over the disk it shows: its penumbra
        pub lamp_samples: u32 = 4, range = 1..=256, test = 1;
    }
}

inputs!(pub EikonalRenderIn { scene: Scene, accel: Accel, medium: Volume, octree: Volume, radiance: Volume, caustics: CausticMap, paths: ViewPaths });
outputs!(pub EikonalRenderOut { image: Image });

/// The Henyey–Greenstein phase function at scattering cosine `cos`.
pub fn henyey_greenstein(g: f32, cos: f32) -> f32 {
    let d = 1.0 + g * g - 2.0 * g * cos;
    (1.0 - g * g) / (4.0 * PI * d * d.sqrt().max(1e-12))
}

/// The golden ratio's fraction: successive shadow rays turn by it around the lamp's disk.
const GOLDEN: f32 = 0.618_034;

/// A number that names a surface point (the bits of its coordinates, mixed), to seed its
/// shadow rays: the same point gets the same rays on any thread and in any order.
fn point_id(p: Vec3) -> u64 {
    let [x, y, z] = p.to_array().map(|c| c.to_bits() as u64);
    x ^ y.rotate_left(21) ^ z.rotate_left(42)
}

/// Everything the pixels share.
struct Render<'a> {
    scene: &'a Scene,
    accel: &'a Accel,
    m: &'a Volume,
    /// The octree's clearance, for shadow rays.
    clearance: std::sync::Arc<Clearance>,
    radiance: &'a Volume,
    caustics: &'a CausticMap,
    lights: Vec<PhotonLight>,
    p: &'a EikonalRender,
    has_kappa: bool,
    eps: f32,
}

impl Render<'_> {
    fn environment(&self, d: Vec3) -> Vec3 {
        self.scene.environment_radiance(d)
    }

    /// Transmittance of the medium along the straight segment `o + t u`, t ∈ [0, len].
    fn transmittance(&self, o: Vec3, u: Vec3, len: f32) -> f32 {
        if !self.has_kappa {
            return 1.0;
        }
        match box_interval(o, u, self.m.min, self.m.max) {
            Some((t0, t1)) if t0 < len => (-optical_depth(self.m, o + u * t0, u, t1.min(len) - t0)).exp(),
            _ => 1.0,
        }
    }

    /// Light leaving surface point `s` toward `wo`.
    fn shade(&self, s: &Surface, wo: Vec3, counts: &mut Counts) -> Vec3 {
        let obj = &self.scene.objects[s.object as usize];
        if s.ng.dot(wo) <= 0.0 {
            return Vec3::ZERO;
        }
        let material = s.material(self.scene);
        let mut out = obj.emission;
        if matches!(material, Material::Dielectric { .. }) {
            return out;
        }
        let frame = Frame::from_normal(s.ns);
        let lwo = frame.to_local(wo);
        for (k, l) in self.lights.iter().enumerate() {
            let Some((wi, dist, li)) = delta_sample(&l.light, s.p) else { continue };
            if wi.dot(s.ng) <= 0.0 {
                continue;
            }
            let lwi = frame.to_local(wi);
            let f = brdf::eval(&material, lwo, lwi) * lwi.z.abs();
            if f == Vec3::ZERO {
                continue;
            }
            // Off the surface by a size relative to the scene and to |p| (Surface::spawn's
            // offset grows with the square of the scene's size).
            let side = if wi.dot(s.ng) >= 0.0 { 1.0 } else { -1.0 };
            let origin = s.p + s.ng * (side * (self.eps + 1e-6 * s.p.abs().max_element()));
            let n = if l.radius > 0.0 && dist.is_finite() { self.p.lamp_samples.max(1) } else { 1 };
            let (mut seen, id) = (0.0, if n > 1 { point_id(s.p) } else { 0 });
            for j in 0..n {
                counts.rays += 1;
                let (dir, tmax) = if n == 1 {
                    (wi, if dist.is_finite() { (dist - l.radius * 1.001) * (1.0 - 1e-4) } else { f32::INFINITY })
                } else {
                    // Stratified over the disk's area, seeded by the point and the light.
                    let u = ((j as f32 + uniform(k as u64, id, 0)) / n as f32, (uniform(k as u64, id, 1) + j as f32 * GOLDEN).fract());
                    lamp_segment(origin, s.p + wi * dist, l.radius, -wi, u)
                };
                // Light whose straight line crosses voxels where rays bend arrives as photons
                // (the caustic map), never here.
                if tmax > 0.0 && !self.clearance.crosses_bends(origin, dir, tmax) && !self.accel.occluded(origin, dir, 0.0, tmax) {
                    seen += self.transmittance(origin, dir, tmax);
                }
            }
            out += f * li * (seen / n as f32);
        }
        out + brdf::diffuse_albedo(&material) / PI * self.caustics.irradiance(s.object, s.p, s.ng)
    }

    /// The light along the straight segment `o + t u`, t ∈ (0, tmax) (starting a hair behind
    /// `o`): the first surface's, or the environment's when nothing is met on an unbounded one.
    fn along(&self, o: Vec3, u: Vec3, tmax: f32, counts: &mut Counts) -> Option<Vec3> {
        counts.rays += 1;
        let start = o - u * self.eps;
        match self.accel.intersect(start, u, 0.0, tmax + self.eps) {
            Some(h) => Some(self.shade(&Surface::at(self.scene, &h, start, u), -u, counts)),
            None => (tmax == f32::INFINITY).then(|| self.environment(u)),
        }
    }

    /// The in-scattered light at gather `g`.
    fn gather(&self, g: &Gather) -> Vec3 {
        let [r, gr, b, mx, my, mz] = self.radiance.sample_n::<6>(g.p, 0);
        let fluence = Vec3::new(r, gr, b);
        let md = Vec3::new(mx, my, mz);
        let lum = luminance(fluence);
        let phase = if self.p.g == 0.0 || lum <= 0.0 {
            1.0 / (4.0 * PI)
        } else {
            let a = (md.length() / lum).clamp(0.0, 1.0);
            let cos = md.try_normalize().map_or(0.0, |m| m.dot(-g.u));
            (1.0 - a) / (4.0 * PI) + a * henyey_greenstein(self.p.g, cos)
        };
        fluence * (phase * g.w)
    }

    /// Radiance reaching the camera along sample `k` of `paths`.
    fn sample(&self, paths: &ViewPaths, k: usize, counts: &mut Counts) -> Vec3 {
        let (o, d, entry) = (paths.origin[k], paths.dir[k], paths.entry[k]);
        if entry.is_finite() {
            // A surface in front of the box hides the medium.
            counts.rays += 1;
            if let Some(h) = self.accel.intersect(o, d, 0.0, entry) {
                return self.shade(&Surface::at(self.scene, &h, o, d), -d, counts);
            }
        }
        let gathered: Vec3 = paths.gathers[paths.offsets[k] as usize..paths.offsets[k + 1] as usize].iter().map(|g| self.gather(g)).sum();
        let e = paths.ends[k];
        if e.tr <= 0.0 {
            return gathered;
        }
        if !entry.is_finite() {
            // The camera ray never meets the box: it starts at the camera, not a hair behind.
            counts.rays += 1;
            return match self.accel.intersect(o, d, 0.0, f32::INFINITY) {
                Some(h) => self.shade(&Surface::at(self.scene, &h, o, d), -d, counts),
                None => self.environment(d),
            };
        }
        gathered + self.along(e.o, e.d, e.tmax, counts).unwrap_or(Vec3::ZERO) * e.tr
    }
}

/// The image of the medium along `paths` (see the node's doc).
pub fn render(i: &EikonalRenderIn, p: &EikonalRender, cx: &RunCtx) -> Result<(Image, u64), NodeError> {
    let (m, o, paths) = (i.medium, i.octree, i.paths);
    if o.dims != m.dims || o.channels != super::octree_layout::CHANNELS || o.min != m.min || o.max != m.max {
        return Err(NodeError::failed(format!(
            "the octree ({:?}, {} channels) was not built on the medium's grid ({:?})",
            o.dims, o.channels, m.dims
        )));
    }
    if i.radiance.channels != 6 || (i.radiance.voxels() > 1 && i.radiance.dims != m.dims) {
        return Err(NodeError::failed(format!(
            "the radiance ({:?}, {} channels) is not MarchPhotons' on this medium's grid ({:?})",
            i.radiance.dims, i.radiance.channels, m.dims
        )));
    }
    if paths.min != m.min || paths.max != m.max {
        return Err(NodeError::failed(format!(
            "the paths were traced through a medium over {} … {}, not this one's {} … {}: wire the same medium into EikonalPaths",
            paths.min, paths.max, m.min, m.max
        )));
    }
    let here = i.accel.bounds_within(m.min, m.max);
    if here != paths.obstacles {
        return Err(NodeError::failed(format!(
            "the surfaces inside the medium's box ({here:?}) are not those the paths stopped at ({:?}): give EikonalPaths a BVH with the same triangles there",
            paths.obstacles
        )));
    }
    let r = Render {
        scene: i.scene,
        accel: i.accel,
        m,
        clearance: Clearance::shared(o),
        radiance: i.radiance,
        caustics: i.caustics,
        lights: photon_lights(i.scene),
        p,
        has_kappa: m.absorbs(),
        eps: 1e-5 * i.scene.extent().max((m.max - m.min).length()),
    };
    let s2 = (paths.samples as usize).pow(2);
    let inv = 1.0 / s2 as f32;
    per_pixel(cx, paths.width as usize, paths.height as usize, |x, y, counts| {
        let first = (y * paths.width as usize + x) * s2;
        let sum: Vec3 = (first..first + s2).map(|k| r.sample(paths, k, counts)).sum();
        (sum * inv).to_array()
    })
}

#[node(category = "volume", version = 9, metrics = ["rays"])]
impl EikonalRender {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The image at the paths' pixels, the octree's clearance as a byte a voxel (its 8
        // channels hold 32).
        let image = inputs[6].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize::image(w, h));
        relume_core::MemoryEstimate { outputs: vec![image], working: inputs[3].map_or(0, |s| s.bytes / 32) }
    }

    fn run(&self, i: EikonalRenderIn, cx: &RunCtx) -> Result<EikonalRenderOut, NodeError> {
        let (image, rays) = render(&i, self, cx)?;
        cx.metric("rays", rays as f64);
        Ok(EikonalRenderOut { image })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::eikonal_paths::EikonalPaths;
    use crate::emit_photons::Proxy;
    use crate::test_support::*;
    use relume_base::render::camera::CameraRays;

    /// The glass scene at `size`² seen through `medium` (photons marched at 48²).
    fn picture(s: &Scene, m: &Volume, size: usize, p: &EikonalPaths) -> Image {
        let oct = octree_of(m);
        let a = accel_without(s, "glass");
        let ph = photons(s, &a, m, 48, Proxy::Active);
        let (rad, map) = march(s, &a, m, &oct, &ph, &march_params(64));
        let mut cam = s.camera.clone();
        (cam.width, cam.height) = (size, size);
        render_image(s, &a, m, &oct, &rad, &map, &cam, p)
    }

    #[test]
    fn paths_traced_past_other_surfaces_in_the_box_are_an_error() {
        // The paths stopped at the floor only; a BVH holding the sphere too sees other
        // surfaces inside the medium's box: shading would miss them, so it says so.
        let s = glass();
        let m = voxelize(&s, "glass", 16);
        let oct = octree_of(&m);
        let (without, with) = (accel_without(&s, "glass"), accel_without(&s, ""));
        let mut cam = s.camera.clone();
        (cam.width, cam.height) = (8, 8);
        let paths = view_paths(&without, &m, &oct, &cam, &paths_params());
        let (rad, map) = (Volume::try_new([1; 3], 6, m.min, m.max, 0.0, u64::MAX).unwrap(), CausticMap::none());
        let i = EikonalRenderIn { scene: &s, accel: &with, medium: &m, octree: &oct, radiance: &rad, caustics: &map, paths: &paths };
        let e = with_cx(|cx| render(&i, &EikonalRender { g: 0.0, lamp_samples: 4 }, cx)).unwrap_err();
        assert!(e.to_string().contains("not those the paths stopped at"), "{e}");
        let i = EikonalRenderIn { accel: &without, ..i };
        assert!(with_cx(|cx| render(&i, &EikonalRender { g: 0.0, lamp_samples: 4 }, cx)).is_ok());
    }

    #[test]
    fn a_lamp_of_some_size_casts_a_penumbra_and_lights_the_open_floor_as_a_point() {
        // The glass sphere as an opaque occluder (in the BVH, the medium far away) under the
        // scene's spherical lamp: one shadow ray toward the lamp's centre gives each floor
        // point all or none of its light; rays spread over the lamp's disk give the points at
        // the shadow's edge a part of it, and the open floor exactly what the centre gives.
        let s = glass();
        let mut m = voxelize(&s, "glass", 8);
        m.data.chunks_mut(3).for_each(|c| c.copy_from_slice(&[1.0, 0.0, 0.0]));
        (m.min, m.max) = (m.min + Vec3::splat(100.0), m.max + Vec3::splat(100.0));
        let oct = octree_of(&m);
        let (rad, map) = (Volume::try_new([1; 3], 6, m.min, m.max, 0.0, u64::MAX).unwrap(), CausticMap::none());
        let mut cam = s.camera.clone();
        (cam.width, cam.height) = (48, 48);
        let shot = |accel: &Accel, lamp_samples| {
            let paths = view_paths(accel, &m, &oct, &cam, &paths_params());
            let i = EikonalRenderIn { scene: &s, accel, medium: &m, octree: &oct, radiance: &rad, caustics: &map, paths: &paths };
            with_cx(|cx| render(&i, &EikonalRender { g: 0.0, lamp_samples }, cx)).unwrap().0
        };
        let (open, with) = (accel_without(&s, "glass"), accel_without(&s, ""));
        let lit = shot(&open, 1);
        let fractions = |img: &Image| -> Vec<f32> {
            let floor = (0..img.pixels.len()).filter(|&k| k >= 24 * 48 && lit.pixels[k][0] > 0.0);
            floor.map(|k| img.pixels[k][0] / lit.pixels[k][0]).collect()
        };
        let partial = |f: &[f32]| f.iter().filter(|&&x| x > 0.05 && x < 0.95).count();
        let (hard, soft) = (fractions(&shot(&with, 1)), fractions(&shot(&with, 16)));
        assert_eq!(partial(&hard), 0, "a point lamp's shadow is all or nothing");
        assert!(partial(&soft) > 5, "{} floor points in the penumbra", partial(&soft));
        let open_floor = soft.iter().zip(&hard).filter(|(_, h)| **h >= 0.999).filter(|(s, _)| (**s - 1.0).abs() > 1e-5).count();
        assert!(open_floor < soft.len() / 10, "{open_floor} of the fully lit points changed");
    }

    #[test]
    fn index_one_gives_the_unrefracted_image() {
        // The glass scene's box reaches down to the floor's plane: camera rays leaving the box
        // there must still find the floor (they did not when traced from the exit point), and
        // an index of 1 everywhere must give the picture of the scene without the object.
        let s = glass();
        let mut m = voxelize(&s, "glass", 24);
        m.data.chunks_mut(3).for_each(|c| c.copy_from_slice(&[1.0, 0.0, 0.0]));
        let through = picture(&s, &m, 40, &paths_params());
        // The same box far away: no ray meets it.
        let (lo, hi) = (m.min, m.max);
        (m.min, m.max) = (lo + Vec3::splat(100.0), hi + Vec3::splat(100.0));
        let without = picture(&s, &m, 40, &paths_params());
        let worst = through.pixels.iter().zip(&without.pixels).map(|(a, b)| (a[0] - b[0]).abs()).fold(0.0f32, f32::max);
        assert!(worst < 1e-4, "{worst}");
        let lit = (20 * 40..40 * 40).filter(|&k| through.pixels[k][0] > 0.0).count();
        assert_eq!(lit, 20 * 40, "the floor, lit everywhere");
    }

    #[test]
    fn a_scattering_slab_under_a_directional_light_matches_single_scattering() {
        // A cube of homogeneous medium (n = 1, κ = 1, σ = 0.5 per unit, side 1) lit straight
        // down with irradiance E, seen from above at angle θ: single scattering gives
        // L = σ E / 4π · (1 − e^{−κ d (1 + μ) / μ}) / (κ (1 + μ)), μ = cos θ, for a view ray
        // leaving through the bottom face.
        use relume_base::scene::builder::SceneBuilder;
        use relume_base::testing::f;
        use relume_base::types::Light;
        let (e, kappa, sigma) = (3.0f32, 1.0f32, 0.5f32);
        let m =
            source("Constant", 32, Vec3::ZERO, 1.0, &[("index", f(1.0)), ("extinction", f(kappa as f64)), ("scattering", f(sigma as f64))]);
        let theta = 20f32.to_radians();
        let eye = Vec3::new(0.0, 3.0 * theta.cos(), 3.0 * theta.sin());
        let s = SceneBuilder::new(eye, Vec3::ZERO, 8.0, 21, 21)
            .light(Light::Directional { direction: -Vec3::Y, irradiance: Vec3::splat(e) })
            .build();
        let a = accel_without(&s, "");
        let oct = octree_of(&m);
        let ph = photons(&s, &a, &m, 128, Proxy::Active);
        let p = crate::march_photons::MarchPhotons { receiver: "".into(), ..march_params(8) };
        let (rad, map) = march(&s, &a, &m, &oct, &ph, &p);
        let img = render_image(&s, &a, &m, &oct, &rad, &map, &s.camera, &EikonalPaths { step: 0.5, ..paths_params() });
        let cam = CameraRays::new(&s.camera);
        let (mut got, mut want) = (0.0f64, 0.0f64);
        for y in 8..13 {
            for x in 8..13 {
                let (o, d) = cam.ray(x as f32 + 0.5, y as f32 + 0.5);
                let (t0, t1) = box_interval(o, d, m.min, m.max).unwrap();
                assert!((o + d * t1).y < -0.4999, "the view ray leaves through the bottom");
                let mu = -d.y;
                let depth = 1.0f32;
                let l = sigma * e / (4.0 * PI) * (1.0 - (-kappa * depth * (1.0 + mu) / mu).exp()) / (kappa * (1.0 + mu));
                assert!(t1 > t0);
                want += l as f64;
                got += img.pixels[y * 21 + x][0] as f64;
            }
        }
        assert!((got / want - 1.0).abs() < 0.03, "rendered {got} against single scattering {want}");
    }
}
