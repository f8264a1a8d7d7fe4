//! What the relighting paths weigh with (`paths::Shade`): every basis BRDF (`BasisShade`, the
//! precompute) or one material per object (`MaterialShade`, the same-seed reference), and the
//! checks a scene must pass for either.

use super::paths::{object_classes, Shade, Slots, MAX_SLOTS};
use super::terms::{enumerate, First, SceneTraits, Second, Term, TermSet};
use glam::Vec3;
use relume_base::brdf;
use relume_base::render::surface::Surface;
use relume_base::types::{BrdfBasis, Environment, Light, Material, MaterialMaps, ObjectMaterials, Scene};
use std::f64::consts::FRAC_1_PI;

/// What an object is on a relighting path.
#[derive(Clone, Copy, Debug)]
enum Kind {
    /// Its own BRDF (with its texture maps, at the hit).
    Fixed,
    /// Dynamic object g.
    Dynamic(u32),
}

fn kinds(scene: &Scene) -> Vec<Kind> {
    object_classes(scene).iter().map(|&c| if c == 0 { Kind::Fixed } else { Kind::Dynamic(c - 1) }).collect()
}

/// Checks that pixel relighting can render `scene`: no delta (dielectric) materials, no
/// dynamic emitter, few enough bases, no dynamic object with a Ks or exponent map (the SV
/// precompute takes those: `check_scene_sv`; a Kd map is multiplied into the diffuse basis'
/// images). Errors name the object.
pub fn check_scene(scene: &Scene, bases: usize) -> Result<(), String> {
    check_scene_with(scene, bases, false)
}

/// `check_scene` for the spatially varying extension: textured dynamic objects are welcome,
/// and every dynamic object needs UVs (its sub-regions are cells of its UV square).
pub fn check_scene_sv(scene: &Scene, bases: usize) -> Result<(), String> {
    check_scene_with(scene, bases, true)?;
    for (name, members) in scene.dynamic_groups() {
        let (mut lo, mut hi) = (glam::Vec2::splat(f32::INFINITY), glam::Vec2::splat(f32::NEG_INFINITY));
        for &m in &members {
            let tris = scene.objects[m as usize].triangles.clone();
            for t in &scene.triangles[tris.start as usize..tris.end as usize] {
                for &v in t {
                    let uv = scene.uvs.get(v as usize).copied().unwrap_or(glam::Vec2::ZERO);
                    (lo, hi) = (lo.min(uv), hi.max(uv));
                }
            }
        }
        if !(hi.x > lo.x && hi.y > lo.y) {
            return Err(format!(
                "dynamic object \"{name}\" has no UVs: the spatially varying extension splits each dynamic object into cells of its UV square"
            ));
        }
    }
    Ok(())
}

/// `check_scene` with textured dynamic objects allowed (a renderer that reads the maps).
pub fn check_scene_textured(scene: &Scene, bases: usize) -> Result<(), String> {
    check_scene_with(scene, bases, true)
}

fn check_scene_with(scene: &Scene, bases: usize, maps: bool) -> Result<(), String> {
    if bases == 0 || bases > MAX_SLOTS {
        return Err(format!("the basis has {bases} BRDFs; pixel relighting takes 1 to {MAX_SLOTS}"));
    }
    for o in &scene.objects {
        if matches!(o.material, Material::Dielectric { .. }) {
            return Err(format!(
                "object \"{}\" is a dielectric: pixel relighting has no delta materials (pipeline 3 renders refraction)",
                o.name
            ));
        }
        if o.dynamic && o.emission != Vec3::ZERO {
            return Err(format!("object \"{}\" is dynamic and emits: an emitter's material cannot be edited here", o.name));
        }
        if o.dynamic && !maps && (o.maps.ks.is_some() || o.maps.exponent.is_some()) {
            return Err(format!(
                "object \"{}\" is dynamic and has a Ks or exponent map: this precompute multiplies only a Kd map into its images (the basis carries one specular lobe per object): use `SvTransferPrecompute` and `SvRelight` (the spatially varying extension, [S] 4.2), make it fixed (its textures are then rendered) or drop those maps",
                o.name
            ));
        }
    }
    Ok(())
}

/// The colour every light shares (largest component 1), or `None` when lights differ in
/// colour (or an environment map lights the scene); white without lights.
pub fn light_colour(scene: &Scene) -> Option<[f32; 3]> {
    let mut colours: Vec<Vec3> = scene.objects.iter().map(|o| o.emission).filter(|e| *e != Vec3::ZERO).collect();
    colours.extend(scene.lights.iter().map(|l| match *l {
        Light::Point { intensity, .. } | Light::Spot { intensity, .. } => intensity,
        Light::Directional { irradiance, .. } => irradiance,
    }));
    match &scene.environment {
        Some(Environment::Constant(c)) => colours.push(*c),
        Some(Environment::Map(_)) => return None,
        None => {}
    }
    let colours: Vec<Vec3> = colours.into_iter().filter(|c| c.max_element() > 0.0).map(|c| c / c.max_element()).collect();
    let Some(&first) = colours.first() else { return Some([1.0; 3]) };
    colours.iter().all(|c| (*c - first).abs().max_element() <= 1e-6).then(|| first.to_array())
}

/// The terms of `scene` on a basis of `bases` BRDFs (see `terms`).
pub fn scene_terms(scene: &Scene, bases: usize) -> TermSet {
    let class = object_classes(scene);
    enumerate(&SceneTraits {
        dynamic_objects: scene.dynamic_groups().len(),
        fixed_objects: class.contains(&0),
        one_light_colour: light_colour(scene).is_some(),
        specular_bases: bases - 1,
        emitters: has_emitters(scene),
    })
}

/// Whether light can be seen directly: an environment or an emitting object.
pub fn has_emitters(scene: &Scene) -> bool {
    scene.environment.is_some() || scene.objects.iter().any(|o| o.emission != Vec3::ZERO)
}

/// What a dynamic object's diffuse basis is multiplied by at `at`: its Kd map there ([S] 4.1's
/// textured airplane: the map times the basis, the edit's Kd the coefficient), 1 without a map
/// or without UVs (as `Scene::material_on` reads it for the path tracer).
fn diffuse_map(scene: &Scene, maps: &MaterialMaps, at: &Surface) -> Vec3 {
    match &maps.kd {
        Some(t) if !scene.uvs.is_empty() => t.lookup(at.uv),
        _ => Vec3::ONE,
    }
}

/// Every basis BRDF at dynamic objects (the diffuse one times the object's Kd map), the own
/// BRDF at fixed ones.
pub struct BasisShade<'a> {
    scene: &'a Scene,
    basis: &'a BrdfBasis,
    kinds: Vec<Kind>,
    /// Index of dynamic object 0's first second slot (1 when fixed objects exist).
    dynamic_offset: usize,
}

impl<'a> BasisShade<'a> {
    /// The shade and the slots of `set` (from `scene_terms(scene, basis.bases())`).
    pub fn new(scene: &'a Scene, basis: &'a BrdfBasis, set: &TermSet) -> (BasisShade<'a>, Slots) {
        let nb = basis.bases();
        let kinds = kinds(scene);
        let fixed = set.terms.iter().any(|t| matches!(t.0, Term::Bounce(_, Second::Fixed)));
        let dynamic_offset = fixed as usize;
        let groups = scene.dynamic_groups().len();
        let n_second = dynamic_offset + groups * nb;
        let first = |f: usize| if f == 0 { First::Merged } else { First::Specular(f as u16) };
        let second = |x: usize| {
            if x < dynamic_offset {
                return Second::Fixed;
            }
            let (g, k) = ((x - dynamic_offset) / nb, (x - dynamic_offset) % nb);
            if k == 0 {
                Second::Diffuse { object: g as u16 }
            } else {
                Second::Specular { object: g as u16, basis: k as u16 }
            }
        };
        let index = |t: Term| set.index(t).expect("every slot pair has a term") as u32;
        let direct = (0..nb).map(|f| index(Term::Direct(first(f)))).collect();
        let bounce =
            (0..nb).flat_map(|f| (0..n_second).map(move |x| (f, x))).map(|(f, x)| index(Term::Bounce(first(f), second(x)))).collect();
        let emitted = set.index(Term::Emitted).map(|i| i as u32);
        let slots = Slots { direct, bounce, n_second, emitted, accumulators: set.terms.len() };
        (BasisShade { scene, basis, kinds, dynamic_offset }, slots)
    }

    fn bases(&self, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> usize {
        let nb = self.basis.bases();
        let mut v = [0.0f32; MAX_SLOTS];
        self.basis.eval_all(wi, wo, &mut v[..nb]);
        for k in 0..nb {
            out[k] = Vec3::splat(v[k]);
        }
        nb
    }

    /// Every basis at a dynamic object's hit, the diffuse one times its Kd map.
    fn dynamic(&self, at: &Surface, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> usize {
        let n = self.bases(wi, wo, out);
        out[0] *= diffuse_map(self.scene, &self.scene.objects[at.object as usize].maps, at);
        n
    }
}

impl Shade for BasisShade<'_> {
    fn first(&self, at: &Surface, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> usize {
        match self.kinds[at.object as usize] {
            Kind::Fixed => {
                out[0] = brdf::eval(&at.material(self.scene), wo, wi);
                1
            }
            Kind::Dynamic(_) => self.dynamic(at, wi, wo, out),
        }
    }
    fn second(&self, at: &Surface, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> (usize, usize) {
        match self.kinds[at.object as usize] {
            Kind::Fixed => {
                out[0] = brdf::eval(&at.material(self.scene), wo, wi);
                (0, 1)
            }
            Kind::Dynamic(g) => (self.dynamic_offset + g as usize * self.basis.bases(), self.dynamic(at, wi, wo, out)),
        }
    }
}

/// How `MaterialShade` evaluates a dynamic object's material.
pub enum MaterialBrdf<'a> {
    /// The analytic Blinn-Phong of (Kd, Ks, s): what the basis approximates.
    Analytic,
    /// The projected material Σ_k c_k ρ̃_k on this basis (per channel; the diffuse term times
    /// the Kd map): what `Relight` shows.
    Tabulated(&'a BrdfBasis),
    /// Each dynamic object's own specular lobe (ks = 1) tabulated on the basis' grid, one table
    /// per object in `ObjectMaterials` order, interpolated as the bases are, uncompressed:
    /// Kd · map/π + Ks · lobe.
    Sampled(&'a BrdfBasis, Vec<Vec<f32>>),
}

/// One material per object: the dynamic objects' from `ObjectMaterials`, the fixed objects'
/// own. Use with `Slots::single()`.
pub struct MaterialShade<'a> {
    scene: &'a Scene,
    kinds: Vec<Kind>,
    materials: &'a ObjectMaterials,
    brdf: MaterialBrdf<'a>,
}

impl<'a> MaterialShade<'a> {
    pub fn new(scene: &'a Scene, materials: &'a ObjectMaterials, brdf: MaterialBrdf<'a>) -> Self {
        MaterialShade { scene, kinds: kinds(scene), materials, brdf }
    }

    fn eval(&self, at: &Surface, wi: Vec3, wo: Vec3) -> Vec3 {
        match self.kinds[at.object as usize] {
            Kind::Fixed => brdf::eval(&at.material(self.scene), wo, wi),
            Kind::Dynamic(g) => {
                let m = &self.materials.0[g as usize];
                match &self.brdf {
                    MaterialBrdf::Analytic => {
                        let bp = Material::BlinnPhong { kd: Vec3::from(m.kd), ks: Vec3::from(m.ks), exponent: m.s };
                        brdf::eval(&m.maps.apply(bp, at.uv), wo, wi)
                    }
                    MaterialBrdf::Tabulated(basis) => {
                        let nb = basis.bases();
                        let mut v = [0.0f32; MAX_SLOTS];
                        basis.eval_all(wi, wo, &mut v[..nb]);
                        let map = diffuse_map(self.scene, &m.maps, at).to_array();
                        let mut sum = [0.0f64; 3];
                        for (k, (c, vk)) in m.coefficients.iter().zip(&v[..nb]).enumerate() {
                            for (ch, (s, ck)) in sum.iter_mut().zip(c).enumerate() {
                                let tex = if k == 0 { map[ch] as f64 } else { 1.0 };
                                *s += ck * *vk as f64 * tex;
                            }
                        }
                        Vec3::new(sum[0] as f32, sum[1] as f32, sum[2] as f32)
                    }
                    MaterialBrdf::Sampled(basis, lobes) => match basis.grid.trilinear(wi, wo) {
                        Some(t) => {
                            let lobe = t.apply(&lobes[g as usize]);
                            let map = diffuse_map(self.scene, &m.maps, at);
                            Vec3::from_array(std::array::from_fn(|c| {
                                (m.kd[c] as f64 * map[c] as f64 * FRAC_1_PI + m.ks[c] as f64 * lobe) as f32
                            }))
                        }
                        None => Vec3::ZERO,
                    },
                }
            }
        }
    }
}

impl Shade for MaterialShade<'_> {
    fn first(&self, at: &Surface, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> usize {
        out[0] = self.eval(at, wi, wo);
        1
    }
    fn second(&self, at: &Surface, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> (usize, usize) {
        out[0] = self.eval(at, wi, wo);
        (0, 1)
    }
}
