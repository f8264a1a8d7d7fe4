use super::bounce::SH;
use super::screen_hits::ScreenHits;
use super::types::brdf::{Blend, BrdfFamily, MaterialParam, SpecularLobes, TuckerBrdf, MAX_LOBES};
use super::types::LobeVisibility;
use super::types::VertexIncident;
use super::types::{EnvLight, VertexColors, Visibility};
use super::types::{ShColumns, NO_OWNER, NO_SLOT};
use super::vertices::vertex_frame;
use glam::Vec3;
use relume_base::math::cubemap::{CubeAt, CubeView, Taps};
use relume_base::math::sh::sh_basis_into;
use relume_base::types::{Camera, Material, ObjectMaterial, ObjectMaterials, Scene};
use relume_core::{inputs, node, outputs, NodeError, Params, RunCtx};
use std::f32::consts::PI;

/// Shades the vertices the camera sees (`hits`, from `CameraHits`; the others stay black,
/// as no pixel reads them) toward the camera from the light that reaches them ([S] 5-5,
/// 5-6; the view-dependent half of the relighting): a fixed object's vertex (Lambertian) as
/// ρ/π · E; a dynamic object's as Kd/π · E (the diffuse term, shaded outside the tensor,
/// [S] 5.3.3.1) plus Ks times the specular part: the Tucker-decomposed residual
/// f_r, u_o(ωo) · (D ×_h u_h(s)) · U^I with ωo the view direction in the vertex frame
/// (`vertex_frame`), plus each separated lobe k of width σ_k ([S] 5.3.1) as its amplitude
/// a_k(s, ωo) times the light around the mirror direction m: the environment prefiltered
/// with σ_k (`EnvLighting`; the 0° lobe reads the map itself) times the vertex's visible
/// fraction of the lobe there (`TransferT0`'s maps; the 0° lobe reads the visibility bit of
/// m's texel), plus the one-bounce SH convolved with the lobe (zonal factors
/// exp(−l(l + 1)σ²/2), the spherical Gaussian's) at m; two-bounce light reaches the
/// specular part through U^I only ([S] 5.3.3.5: no lobe). Where a diffuse texture map
/// multiplies an object's ρ or Kd, the diffuse term goes to the colours' `textured` part and
/// `RasterizeVertexColors` multiplies the map in at each pixel; specular maps are refused. The dynamic objects' (Kd, Ks, s),
/// or (Kd, Ks, m, F0) for Cook-Torrance, come from `materials` (`MaterialProject`, the BRDF
/// edit); u_h and the lobes' amplitudes are taken at the material's position on the
/// tensor's h axis: linear in s between Blinn-Phong samples, bilinear on a Cook-Torrance
/// tensor's (m, F0) grid. A material of the other model than the tensor's family, or outside
/// its sampled range, is refused. Re-runs on every view, material
/// or lighting change; the view is `camera` (`OrbitCamera`), so that orbiting reaches this
/// node and not what reads the scene.
///
/// Metrics: vertices, vertices seen, vertices shaded with the tensor, the mean luminance of the diffuse and
/// specular parts over the shaded vertices.
#[derive(Params)]
pub struct PttRelight {}

inputs!(pub PttRelightIn {
    scene: Scene,
    camera: Camera,
    hits: ScreenHits,
    visibility: Visibility,
    projection: ShColumns,
    incident: VertexIncident,
    brdf: TuckerBrdf,
    lobes: SpecularLobes,
    lobe_visibility: LobeVisibility,
    env: EnvLight,
    materials: ObjectMaterials,
});
outputs!(pub PttRelightOut { colors: VertexColors });

/// SH bands of the one-bounce light (SH = BANDS²) and the band of each coefficient.
const BANDS: usize = 4;
const _: () = assert!(SH == BANDS * BANDS);
const BAND_OF: [usize; SH] = [0, 1, 1, 1, 2, 2, 2, 2, 2, 3, 3, 3, 3, 3, 3, 3];

/// Seen vertices per block: their views are found (and their visibility reads fetched)
/// before any of them is shaded.
const BLOCK: usize = 32;

/// What the view makes of a seen vertex: nothing (no object shades it), a fixed object's
/// (Lambertian), a dynamic object's diffuse term alone (no specular part toward the eye),
/// or its glossy shading with slot `t`, ωo in the vertex frame (`local`), the mirror
/// direction `m` and where it lies on the cube.
enum Seen {
    Dark,
    Fixed(u32),
    Diffuse(u32),
    Glossy { o: u32, t: u32, local: Vec3, m: Vec3, at: CubeAt },
}

/// Where lobe k's light comes from: the map itself with the visibility bits (0°), or a
/// prefiltered map with a visible-fraction map.
enum LobeSource<'a> {
    Sharp,
    Wide { env: CubeView<'a>, vis: usize, zonal: [f32; BANDS] },
}

/// A dynamic object's shading: Kd, Ks, and its material's BRDF at every sample of the disks
/// of view directions, for the vertices to blend at their ωo: the tensor's U^ωo · M (n_ωi
/// a sample, `TuckerBrdf::view_table`) and the lobes' amplitudes (K a sample,
/// `SpecularLobes::table_at`).
struct Shading {
    kd: Vec3,
    ks: Vec3,
    view: Vec<f32>,
    amps: Vec<f32>,
}

/// `m`'s position on the tensor's h axis: its exponent s (Blinn-Phong) or its (m, F0)
/// (Cook-Torrance); an input error when the material's model is not the tensor's family or
/// its parameter lies outside the sampled range.
fn material_position(family: &BrdfFamily, m: &ObjectMaterial) -> Result<Blend, NodeError> {
    let p = MaterialParam::of_object(m);
    if p.model() != family.model() {
        return Err(NodeError::input(
            "materials",
            format!(
                "\"{}\" is {} but the BRDF tensor samples {}: set the material edit's model (MaterialProject) and BrdfTensor's model alike",
                m.name,
                p.model(),
                family.model()
            ),
        ));
    }
    family.position(p).map_err(|e| NodeError::input("materials", format!("\"{}\": {e} of the BRDF tensor", m.name)))
}

fn lum(v: Vec3) -> f64 {
    v.dot(Vec3::new(0.2126, 0.7152, 0.0722)) as f64
}

impl PttRelight {
    fn sources<'a>(&self, i: &PttRelightIn<'a>) -> Result<Vec<LobeSource<'a>>, NodeError> {
        if !i.lobe_visibility.covers(i.scene.positions.len()) {
            return Err(NodeError::input(
                "lobe_visibility",
                format!("lacks maps for the scene's {} vertices: it must come from the same scene", i.scene.positions.len()),
            ));
        }
        if i.lobe_visibility.sigmas.len() > MAX_LOBES {
            return Err(NodeError::input(
                "lobe_visibility",
                format!("{} lobe maps: at most {MAX_LOBES} lobes are separated", i.lobe_visibility.sigmas.len()),
            ));
        }
        i.lobes
            .sigmas
            .iter()
            .map(|&sigma| {
                if sigma == 0.0 {
                    return Ok(LobeSource::Sharp);
                }
                let deg = sigma.to_degrees();
                let pre = i.env.lobes.iter().find(|l| (l.sigma_deg as f64 - deg).abs() < 1e-3).ok_or_else(|| {
                    let have: Vec<String> = i.env.lobes.iter().map(|l| format!("{}°", l.sigma_deg)).collect();
                    NodeError::input("env", format!("no environment prefiltered for the {deg:.3}° lobe (it has {})", have.join(", ")))
                })?;
                let vis = i
                    .lobe_visibility
                    .map_for(sigma)
                    .ok_or_else(|| NodeError::input("lobe_visibility", format!("no visible-fraction map for the {deg:.3}° lobe")))?;
                let zonal = std::array::from_fn(|l| (-((l * (l + 1)) as f64) * sigma * sigma / 2.0).exp() as f32);
                Ok(LobeSource::Wide { env: CubeView { n: pre.n as usize, texels: &pre.texels }, vis, zonal })
            })
            .collect()
    }

    /// Per scene object, its shading when dynamic; fixed objects must be Lambertian.
    fn shadings(&self, i: &PttRelightIn) -> Result<Vec<Option<Shading>>, NodeError> {
        let scene = i.scene;
        if i.lobes.family != i.brdf.family {
            return Err(NodeError::input("lobes", "the lobes and the Tucker tensor come from different BRDF families"));
        }
        let mut out: Vec<Option<Shading>> = scene.objects.iter().map(|_| None).collect();
        for o in scene.objects.iter().filter(|o| !o.dynamic) {
            if !matches!(o.material, Material::Lambert { .. }) {
                return Err(NodeError::input(
                    "scene",
                    format!(
                        "fixed object \"{}\" is not Lambertian: the transfer shades fixed objects by their irradiance (make it dynamic, or pass the scene through GlossyAsDynamic)",
                        o.name
                    ),
                ));
            }
        }
        for (name, members) in scene.dynamic_groups() {
            let m = i
                .materials
                .0
                .iter()
                .find(|m| m.name == name)
                .ok_or_else(|| NodeError::input("materials", format!("no material for the dynamic object \"{name}\"")))?;
            if m.maps.ks.is_some() || m.maps.exponent.is_some() {
                return Err(NodeError::input(
                    "materials",
                    format!("\"{name}\" has a specular texture map: a dynamic object reflects one Ks and exponent through its basis channels (a diffuse map is taken)"),
                ));
            }
            let h = material_position(&i.brdf.family, m)?;
            let view = i.brdf.view_table(&i.brdf.core_for(&i.brdf.u_h_at(&h)));
            let amps = i.lobes.table_at(&h);
            for &o in &members {
                let (view, amps) = (view.clone(), amps.clone());
                out[o as usize] = Some(Shading { kd: Vec3::from(m.kd), ks: Vec3::from(m.ks), view, amps });
            }
        }
        Ok(out)
    }
}

#[node(category = "ptt", caching = Keyed, version = 3, metrics = ["vertices", "seen", "shaded", "diffuse_mean", "specular_mean"])]
impl PttRelight {
    fn run(&self, i: PttRelightIn, cx: &RunCtx) -> Result<PttRelightOut, NodeError> {
        let scene = i.scene;
        let n = scene.positions.len();
        let (p, inc) = (i.projection, i.incident);
        if p.normals.len() != n || inc.irradiance.len() != n || i.visibility.vertices() != n || i.hits.vertices as usize != n {
            return Err(NodeError::input(
                "incident",
                format!(
                    "the scene has {n} vertices, the projection {}, the incident light {}, the visibility {} and the camera's hits {}: they must come from the same scene",
                    p.normals.len(),
                    inc.irradiance.len(),
                    i.visibility.vertices(),
                    i.hits.vertices
                ),
            ));
        }
        if inc.columns != p.columns || inc.columns != i.brdf.ranks[2] || inc.bounce.len() != p.slots() * SH {
            return Err(NodeError::input(
                "incident",
                "the incident light, the projection and the BRDF tensor disagree on columns or slots",
            ));
        }
        VertexColors::check_budget(n, cx.memory_budget())?;
        let sources = self.sources(&i)?;
        let shadings = self.shadings(&i)?;
        // Objects whose diffuse reflectance a texture map multiplies: their diffuse light goes to the
        // rasteriser, which applies the map per pixel.
        let textured: Vec<bool> = scene.objects.iter().map(|o| o.maps.kd.is_some() && !scene.uvs.is_empty()).collect();
        if p.owner.iter().any(|&o| o != NO_OWNER && o as usize >= scene.objects.len()) {
            return Err(NodeError::input(
                "projection",
                format!("names objects the scene's {} do not hold: they must come from the same scene", scene.objects.len()),
            ));
        }
        let owner = |v: usize| p.owner_of(v);
        let env = CubeView { n: i.env.n as usize, texels: &i.env.map };
        let bits_side = i.visibility.n as usize;
        let (eye, cols) = (i.camera.origin, p.columns as usize);
        // A dynamic object's diffuse term at vertex v, shaded outside the tensor.
        let diffuse_of = |o: u32, v: usize| shadings[o as usize].as_ref().map_or(Vec3::ZERO, |sh| sh.kd / PI * inc.irradiance[v]);
        cx.check()?;
        let seen = &i.hits.seen;
        let (lobe_count, same_disk) = (i.lobes.lobes(), i.lobes.disk == i.brdf.disk);
        let wide = sources.iter().any(|s| matches!(s, LobeSource::Wide { .. }));
        // What a seen vertex needs of the view, found for a block of vertices before any is
        // shaded, so that the block's visibility and incident-light reads (far apart in
        // memory) are fetched while the others are found and shaded.
        let view_of = |v: usize| -> Seen {
            let Some(o) = owner(v) else { return Seen::Dark };
            // Every shaded vertex reads its irradiance, 12 bytes of an array the seen vertices
            // are sparse in.
            relume_base::math::prefetch(&inc.irradiance[v]);
            let Some(sh) = &shadings[o as usize] else { return Seen::Fixed(o) };
            let (t, nv) = (p.slot[v], p.normals[v]);
            let wo = (eye - scene.positions[v]).normalize_or_zero();
            if t == NO_SLOT || sh.ks == Vec3::ZERO || nv.dot(wo) <= 0.0 {
                return Seen::Diffuse(o);
            }
            let m = (2.0 * nv.dot(wo) * nv - wo).normalize_or_zero();
            let at = CubeAt::of(m);
            relume_base::math::prefetch(&i.visibility.of(v)[at.texel(bits_side) / 32]);
            if wide {
                i.lobe_visibility.prefetch(v, &at);
            }
            // And the slot's rows of the incident light, far apart too once the seen vertices
            // are sparse: its one-bounce SH (192 bytes) and the tensor's columns, every
            // fourth colour (48 bytes apart, so each cache line the rows span is fetched).
            for row in [&inc.bounce[t as usize * SH..][..SH], &inc.tensor[t as usize * cols..][..cols]] {
                row.iter().step_by(4).chain(row.last()).for_each(relume_base::math::prefetch);
            }
            Seen::Glossy { o, t, local: vertex_frame(nv).to_local(wo), m, at }
        };
        // Per thread: the block's views, and the row U^ωo · M at a vertex's ωo.
        let scratch = || (Vec::with_capacity(BLOCK), vec![0.0f32; cols]);
        let blocks = cx.par_map_init(seen.len().div_ceil(BLOCK), scratch, |(views, w), b| {
            let block = &seen[b * BLOCK..((b + 1) * BLOCK).min(seen.len())];
            views.clear();
            views.extend(block.iter().map(|&v| view_of(v as usize)));
            let shade = |v: usize, view: &Seen, w: &mut [f32]| -> (Vec3, Vec3) {
                let (o, t, local, m, at) = match *view {
                    Seen::Dark => return (Vec3::ZERO, Vec3::ZERO),
                    Seen::Fixed(o) => {
                        let albedo = match scene.objects[o as usize].material {
                            Material::Lambert { albedo } => albedo,
                            _ => Vec3::ZERO,
                        };
                        return (albedo / PI * inc.irradiance[v], Vec3::ZERO);
                    }
                    Seen::Diffuse(o) => return (diffuse_of(o, v), Vec3::ZERO),
                    Seen::Glossy { o, t, local, m, at } => (o, t as usize, local, m, at),
                };
                let sh = shadings[o as usize].as_ref().expect("a glossy vertex's object is dynamic");
                let diffuse = diffuse_of(o, v);
                // ωo's place on the disks (below the horizon or not finite: no specular part).
                let Some(bo) = i.brdf.disk.bilinear(local) else { return (diffuse, Vec3::ZERO) };
                let bl = if same_disk { Some(bo) } else { i.lobes.disk.bilinear(local) };
                // The tensor term u_o · M · U^I, as (U^ωo · M blended at ωo) · U^I.
                w.fill(0.0);
                for (&o, &bw) in bo.idx.iter().zip(&bo.w) {
                    if bw != 0.0 {
                        let bw = bw as f32;
                        w.iter_mut().zip(&sh.view[o as usize * cols..][..cols]).for_each(|(x, g)| *x += bw * g);
                    }
                }
                let u = &inc.tensor[t * cols..(t + 1) * cols];
                let mut spec: Vec3 = u.iter().zip(w.iter()).map(|(u, w)| *u * *w).sum();
                // The lobes' amplitudes at ωo, and the light around the mirror direction.
                let mut a = [0.0f32; MAX_LOBES];
                for (&o, &bw) in bl.iter().flat_map(|b| b.idx.iter().zip(&b.w)) {
                    if bw != 0.0 {
                        let bw = bw as f32;
                        a.iter_mut().zip(&sh.amps[o as usize * lobe_count..][..lobe_count]).for_each(|(x, g)| *x += bw * g);
                    }
                }
                let mut y = [0.0f32; SH];
                sh_basis_into(m, &mut y);
                let c1 = &inc.bounce[t * SH..(t + 1) * SH];
                // The one-bounce light at m, band by band: a lobe weighs each band by its
                // zonal factor.
                let mut band = [Vec3::ZERO; BANDS];
                for (q, (c, y)) in c1.iter().zip(&y).enumerate() {
                    band[BAND_OF[q]] += *c * *y;
                }
                // The visible fractions of the wide lobes at m, all from the same texels.
                let mut fraction = [0.0f32; MAX_LOBES];
                if wide {
                    i.lobe_visibility.lobe_visibilities_at(v, &at, &mut fraction);
                }
                // The taps at m on the last side read (the wide lobes' maps share sides).
                let mut taps: Option<(usize, Taps)> = None;
                let mut lookup = |map: &CubeView| -> Vec3 {
                    let t = match taps {
                        Some((n, t)) if n == map.n => t,
                        _ => taps.insert((map.n, at.taps(map.n))).1,
                    };
                    map.lookup_taps(t)
                };
                for (k, src) in sources.iter().enumerate() {
                    if a[k] == 0.0 {
                        continue;
                    }
                    let light = match src {
                        LobeSource::Sharp => {
                            let seen = if i.visibility.visible(v, at.texel(bits_side)) { 1.0 } else { 0.0 };
                            lookup(&env) * seen + band.iter().sum::<Vec3>()
                        }
                        LobeSource::Wide { env, vis, zonal } => {
                            lookup(env) * fraction[*vis] + band.iter().zip(zonal).map(|(b, z)| *b * *z).sum::<Vec3>()
                        }
                    };
                    spec += light * a[k];
                }
                (diffuse, sh.ks * spec.max(Vec3::ZERO))
            };
            // The block's colours, and its shaded vertices' count and luminance sums (summed
            // over the blocks in order: the same on any thread count).
            let mut sums = (0usize, 0.0, 0.0);
            // (colour, the part the object's texture map multiplies at each pixel).
            let colors: Vec<(Vec3, Vec3)> = block
                .iter()
                .zip(views.iter())
                .map(|(&v, view)| {
                    let (d, s) = shade(v as usize, view, w);
                    if p.slot[v as usize] != NO_SLOT {
                        sums = (sums.0 + 1, sums.1 + lum(d), sums.2 + lum(s));
                    }
                    let owner = match view {
                        Seen::Fixed(o) | Seen::Diffuse(o) | Seen::Glossy { o, .. } => Some(*o as usize),
                        Seen::Dark => None,
                    };
                    match owner {
                        Some(o) if textured[o] => (s, d),
                        _ => (d + s, Vec3::ZERO),
                    }
                })
                .collect();
            (colors, sums)
        })?;
        let (mut dsum, mut ssum, mut shaded) = (0.0, 0.0, 0usize);
        let mut out = VertexColors::plain(vec![Vec3::ZERO; n]);
        if textured.iter().any(|t| *t) {
            out.textured = vec![Vec3::ZERO; n];
        }
        for (b, (block, sums)) in blocks.iter().enumerate() {
            for (&v, (c, t)) in seen[b * BLOCK..].iter().zip(block) {
                out.colors[v as usize] = *c;
                if let Some(x) = out.textured.get_mut(v as usize) {
                    *x = *t;
                }
            }
            (shaded, dsum, ssum) = (shaded + sums.0, dsum + sums.1, ssum + sums.2);
        }
        cx.metric("vertices", n as f64);
        cx.metric("seen", seen.len() as f64);
        cx.metric("shaded", shaded as f64);
        cx.metric("diffuse_mean", dsum / shaded.max(1) as f64);
        cx.metric("specular_mean", ssum / shaded.max(1) as f64);
        Ok(PttRelightOut { colors: out })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf_factors::test_support::{small_brdf, small_ct_brdf};
    use crate::test_support::{blob_sky, plane, Chain, GLOSSY};
    use crate::types::brdf::gaussian_norm;
    use relume_base::brdf;
    use relume_base::math::cubemap::CubeMap;
    use relume_base::testing::{f, first, id, rgb, run_on, t};
    use relume_base::types::{Environment, Specular};
    use relume_core::Value;

    fn lum(v: Vec3) -> f32 {
        v.dot(Vec3::new(0.2126, 0.7152, 0.0722))
    }

    /// Radiance toward the camera of an open vertex of `s`'s plane (normal +y, material
    /// `GLOSSY`) by quadrature on a cube map of side 48 over the hemisphere: with the true
    /// BRDF, and with the BRDF as the test tensor represents it (Kd/π + Ks (f_r + Σ a_k
    /// lobe_k), the 0° lobe the environment at the mirror direction).
    fn reference(s: &Scene, v: usize) -> (Vec3, Vec3) {
        reference_of(s, v, &GLOSSY, crate::brdf_factors::test_support::small_brdf())
    }

    /// [`reference`] for the plane's `material` as the tensor and lobes `tensor` represent it.
    fn reference_of(s: &Scene, v: usize, material: &Material, tensor: &(TuckerBrdf, SpecularLobes)) -> (Vec3, Vec3) {
        let (brdf, lobes) = tensor;
        let cube = CubeMap::constant(48, Vec3::ZERO);
        let f = vertex_frame(Vec3::Y);
        let wo_w = (s.camera.origin - s.positions[v]).normalize();
        let (wo, m) = (f.to_local(wo_w), 2.0 * wo_w.y * Vec3::Y - wo_w);
        let h = brdf.family.position(MaterialParam::of(material).expect("glossy")).expect("in range");
        let (core, a, u_o) = (brdf.core_for(&brdf.u_h_at(&h)), lobes.amplitudes(&h, wo), brdf.u_o(wo));
        let (Material::BlinnPhong { kd, ks, .. } | Material::CookTorrance { kd, ks, .. }) = *material else { unreachable!() };
        let (mut truth, mut rep) = (Vec3::ZERO, s.environment_radiance(m) * ks * a[0]);
        // Each lobe's normalisation once, not per texel (a quadrature of its own).
        let norms: Vec<f64> = lobes.sigmas.iter().map(|&s| if s > 0.0 { gaussian_norm(s) } else { 1.0 }).collect();
        for k in 0..cube.texels.len() {
            let d = cube.direction(k);
            let wi = f.to_local(d);
            if wi.z <= 0.0 {
                continue;
            }
            let l = s.environment_radiance(d) * cube.solid_angle(k);
            truth += l * brdf::eval(material, wo, wi) * wi.z;
            let th = d.dot(m).clamp(-1.0, 1.0).acos() as f64;
            let g: f64 = lobes
                .sigmas
                .iter()
                .zip(a)
                .zip(&norms)
                .filter(|((s, _), _)| **s > 0.0 && th <= 4.0 * **s)
                .map(|((s, a), norm)| a as f64 * (-(th * th) / (2.0 * s * s)).exp() / norm)
                .sum();
            rep += l * (kd / PI * wi.z + ks * (brdf.contract(&core, &u_o, &brdf.u_i(wi)) as f32 * wi.z + g as f32));
        }
        (truth, rep)
    }

    /// Asserts that the brightest reference vertex is `contrast` times the dimmest (the
    /// highlight is on the plane) and that `got`'s mean and worst relative luminance errors
    /// are below `represented` against the represented BRDF and below `truth` against the true
    /// one.
    fn assert_matches(got: &[Vec3], refs: &[(Vec3, Vec3)], contrast: f32, represented: (f32, f32), truth: (f32, f32)) {
        let l: Vec<f32> = refs.iter().map(|r| lum(r.0)).collect();
        assert!(l.iter().fold(0.0f32, |a, b| a.max(*b)) > contrast * l.iter().fold(f32::MAX, |a, b| a.min(*b)), "{l:?}");
        for (k, (what, bound)) in [("the true BRDF", truth), ("the represented BRDF", represented)].into_iter().enumerate() {
            let e: Vec<f32> = got
                .iter()
                .zip(refs)
                .map(|(g, r)| {
                    let w = if k == 0 { r.0 } else { r.1 };
                    (lum(*g) - lum(w)).abs() / lum(w)
                })
                .collect();
            let (mean, worst) = (e.iter().sum::<f32>() / e.len() as f32, e.iter().fold(0.0f32, |a, b| a.max(*b)));
            assert!(mean < bound.0 && worst < bound.1, "against {what}: mean {mean}, worst {worst}");
        }
    }

    #[test]
    fn a_lambert_plane_under_a_constant_sky_shows_its_albedo_and_under_a_zero_sky_black() {
        let c = Chain::new(plane(Material::Lambert { albedo: Vec3::splat(0.6) }, false, Environment::Constant(Vec3::ONE)));
        for col in c.colors(2, &[]) {
            assert!((col - Vec3::splat(0.6)).abs().max_element() < 0.006, "{col}");
        }
        let dark = Chain::new(plane(GLOSSY, true, Environment::Constant(Vec3::ZERO)));
        assert!(dark.colors(2, &[]).iter().all(|c| *c == Vec3::ZERO));
    }

    #[test]
    fn a_glossy_plane_matches_a_quadrature_of_its_brdf_against_the_sky() {
        // The blob sits at the mirror direction of the camera seen from the plane's centre.
        let eye = Vec3::new(0.0, 2.0, 2.0).normalize();
        let s = plane(GLOSSY, true, blob_sky(Vec3::new(0.0, eye.y, -eye.z)));
        let c = Chain::new(s.clone());
        let got = c.colors(2, &[]);
        let refs: Vec<(Vec3, Vec3)> = (0..got.len()).map(|v| reference(&s, v)).collect();
        // The highlight is part of the test: the brightest vertex is well over the dimmest.
        // Against the represented BRDF the node's approximations are the prefiltered lobes'
        // per-vertex visible fraction and the 96 kept terms: measured mean 1.2 %, worst 3.5 %.
        // Against the true BRDF the small test tensor (disk 16, 12 exponents) adds its own
        // error, up to a quarter of the specular part where the sky's blob lies 11° off the
        // mirror direction: measured mean 5.6 %, worst 21.6 %.
        assert_matches(&got, &refs, 2.5, (0.02, 0.05), (0.07, 0.25));
        // Without Ks only the diffuse term is left, exactly Kd/π E.
        let mut m = c.materials();
        m.0[0].ks = [0.0; 3];
        let inc = c.incident(&c.env, &m, 2);
        let plain: VertexColors = first(&run_on::<PttRelight>(&[], c.relight_inputs(&s, &inc, &c.env, &m)).expect("runs"));
        for (v, col) in plain.colors.iter().enumerate() {
            assert_eq!(*col, Vec3::from(m.0[0].kd) / PI * inc.irradiance[v]);
        }
    }

    #[test]
    fn the_view_moves_the_highlight_and_fixed_glossy_objects_or_missing_materials_are_refused() {
        let eye = Vec3::new(0.0, 2.0, 2.0).normalize();
        let s = plane(GLOSSY, true, blob_sky(Vec3::new(0.0, eye.y, -eye.z)));
        let c = Chain::new(s.clone());
        let m = c.materials();
        let inc = c.incident(&c.env, &m, 2);
        let at = |scene: &Scene| -> Vec<Vec3> {
            first::<VertexColors>(&run_on::<PttRelight>(&[], c.relight_inputs(scene, &inc, &c.env, &m)).expect("runs")).colors
        };
        let mut turned = s.clone();
        turned.camera.origin = Vec3::new(2.0, 2.0, 0.0);
        let (a, b) = (at(&s), at(&turned));
        let brightest = |c: &[Vec3]| (0..c.len()).max_by(|&x, &y| lum(c[x]).total_cmp(&lum(c[y]))).expect("vertices");
        assert_ne!(brightest(&a), brightest(&b), "the highlight follows the mirror direction");
        let mut fixed = s.clone();
        fixed.objects[0].dynamic = false;
        let e = run_on::<PttRelight>(&[], c.relight_inputs(&fixed, &inc, &c.env, &m)).expect_err("fixed glossy");
        assert!(e.to_string().contains("not Lambertian"), "{e}");
        let e = run_on::<PttRelight>(&[], c.relight_inputs(&s, &inc, &c.env, &ObjectMaterials(vec![]))).expect_err("no material");
        assert!(e.to_string().contains("no material"), "{e}");
        // A projection of another scene, naming objects this one lacks.
        let mut fewer = s.clone();
        fewer.objects.clear();
        let e = run_on::<PttRelight>(&[], c.relight_inputs(&fewer, &inc, &c.env, &m)).expect_err("objects the scene lacks");
        assert!(e.to_string().contains("do not hold"), "{e}");
        // Lobe maps of a scene with fewer vertices (the input after the lobes).
        let mut inputs = c.relight_inputs(&s, &inc, &c.env, &m);
        let mut lv = inputs[8].get::<LobeVisibility>().expect("the lobe maps").clone();
        lv.maps.truncate(lv.maps.len() / 2);
        inputs[8] = Value::new(lv);
        let e = run_on::<PttRelight>(&[], inputs).expect_err("lobe maps of another scene");
        assert!(e.to_string().contains("lacks maps"), "{e}");
    }

    /// The glossy plane under the blob sky, its material edited to Cook-Torrance (m, F0) on
    /// the test's Cook-Torrance tensor, with the material the reference shades.
    fn ct_plane(m: f32, f0: f32) -> (Scene, Chain, Material) {
        let eye = Vec3::new(0.0, 2.0, 2.0).normalize();
        let s = plane(GLOSSY, true, blob_sky(Vec3::new(0.0, eye.y, -eye.z)));
        let Material::BlinnPhong { kd, ks, .. } = GLOSSY else { unreachable!() };
        let edit = [
            ("object", t("plane")),
            ("kd", rgb(kd.as_dvec3().to_array())),
            ("ks", rgb(ks.as_dvec3().to_array())),
            ("model", id("CookTorrance")),
            ("m", f(m as f64)),
            ("f0", f(f0 as f64)),
        ];
        let c = Chain::with(s.clone(), small_ct_brdf(), &edit);
        (s, c, Material::CookTorrance { kd, ks, roughness: m, f0 })
    }

    /// The Cook-Torrance chain at (m 0.25, F0 0.4), between the test tensor's grid points;
    /// built once.
    fn ct_chain() -> &'static (Scene, Chain, Material) {
        static C: std::sync::OnceLock<(Scene, Chain, Material)> = std::sync::OnceLock::new();
        C.get_or_init(|| ct_plane(0.25, 0.4))
    }

    #[test]
    fn a_glossy_cook_torrance_plane_matches_a_quadrature_of_its_brdf_against_the_sky() {
        let (s, c, material) = ct_chain();
        let got = c.colors(2, &[]);
        let refs: Vec<(Vec3, Vec3)> = (0..got.len()).map(|v| reference_of(s, v, material, small_ct_brdf())).collect();
        // Against the represented BRDF (u_h and the lobes' amplitudes bilinear on the
        // (m, F0) grid): measured mean 1.5 %, worst 4.0 %. Against the true Cook-Torrance BRDF
        // the coarse 3 × 3 grid adds its own error (m 0.25 blends the lobes of m 0.1 and 0.3,
        // the first twice as sharp): measured mean 8.5 %, worst 30 %, at the highlight's edge.
        assert_matches(&got, &refs, 1.5, (0.02, 0.05), (0.1, 0.35));
    }

    #[test]
    fn a_material_of_the_other_model_or_outside_the_grid_is_refused() {
        let (s, c, _) = ct_chain();
        let m = c.materials();
        assert_eq!(m.0[0].specular, Specular::CookTorrance { m: 0.25, f0: 0.4 });
        let inc = c.incident(&c.env, &m, 1);
        let relight = |m: &ObjectMaterials| run_on::<PttRelight>(&[], c.relight_inputs(s, &inc, &c.env, m));
        let mut bp = m.clone();
        bp.0[0].specular = Specular::BlinnPhong;
        let e = relight(&bp).expect_err("Blinn-Phong on a Cook-Torrance tensor").to_string();
        assert!(e.contains("\"plane\" is Blinn-Phong but the BRDF tensor samples Cook-Torrance"), "{e}");
        let mut rough = m.clone();
        rough.0[0].specular = Specular::CookTorrance { m: 0.55, f0: 0.4 };
        let e = relight(&rough).expect_err("rougher than the grid").to_string();
        assert!(e.contains("roughness m = 0.55") && e.contains("outside the sampled range"), "{e}");
        // A Cook-Torrance material on the Blinn-Phong tensor of the other tests.
        let mut other = c.clone();
        let (brdf, lobes) = small_brdf();
        other.values.retain(|(n, _)| *n != "brdf" && *n != "lobes");
        other.values.extend([("brdf", Value::new(brdf.clone())), ("lobes", Value::new(lobes.clone()))]);
        let e = run_on::<PttRelight>(&[], other.relight_inputs(s, &inc, &c.env, &m)).expect_err("mismatch").to_string();
        assert!(e.contains("is Cook-Torrance but the BRDF tensor samples Blinn-Phong"), "{e}");
    }

    #[test]
    fn roughness_at_the_grid_edges_and_a_grazing_view_stay_finite_and_continuous() {
        let (s, c, _) = ct_chain();
        let m = c.materials();
        let inc = c.incident(&c.env, &m, 2);
        let mut grazing = s.clone();
        grazing.camera.origin = Vec3::new(0.0, 0.02, 3.0);
        for scene in [s, &grazing] {
            let shade = |rough: f32, f0: f32| -> Vec<Vec3> {
                let mut e = m.clone();
                e.0[0].specular = Specular::CookTorrance { m: rough, f0 };
                first::<VertexColors>(&run_on::<PttRelight>(&[], c.relight_inputs(scene, &inc, &c.env, &e)).expect("runs")).colors
            };
            for (rough, f0) in [(0.1, 0.2), (0.5, 0.8), (0.1, 0.8), (0.5, 0.2)] {
                let at = shade(rough, f0);
                assert!(at.iter().all(|c| c.is_finite() && c.min_element() >= 0.0), "m {rough} F0 {f0}: {at:?}");
                // Just inside the edge the colours hardly move.
                let inside = shade(rough + if rough < 0.3 { 1e-4 } else { -1e-4 }, f0);
                for (a, b) in at.iter().zip(&inside) {
                    assert!((*a - *b).abs().max_element() <= 1e-2 * a.max_element().max(1e-3), "m {rough} F0 {f0}: {a} vs {b}");
                }
            }
        }
    }
}
