//! Pixel relighting with dynamic BRDFs (PIPELINES.md pipeline 1; [S] chapter 4): the BRDF space
//! and its basis (`BrdfSpaceSample`, `BrdfPca`), the dynamic objects' materials and their
//! projection (`SceneMaterials`, `MaterialProject`), the precompute (`TransferPrecompute`, on
//! the paths of `paths` weighted by `shades`; the terms a scene needs in `terms`; signed basis
//! evaluation in `basis_brdf`), the interactive combine (`Relight`) and the same-seed render
//! that measures the basis error alone (`RelightReference`).

pub mod apply_materials;
pub mod basis_brdf;
pub mod brdf_pca;
pub mod brdf_space_sample;
pub mod material_project;
pub mod paint_material;
pub mod paths;
#[allow(clippy::module_inception)]
pub mod relight;
pub mod relight_reference;
pub mod scene_materials;
pub mod shades;
pub mod sv_precompute;
pub mod sv_relight;
pub mod sv_shade;
pub mod sv_terms;
pub mod sv_transfer_precompute;
pub mod terms;
pub mod transfer_precompute;

use relume_core::Registry;

/// Registers the relighting nodes.
pub fn register(reg: &mut Registry) {
    reg.add::<brdf_space_sample::BrdfSpaceSample>();
    reg.add::<brdf_pca::BrdfPca>();
    reg.add::<scene_materials::SceneMaterials>();
    reg.add::<material_project::MaterialProject>();
    reg.add::<transfer_precompute::TransferPrecompute>();
    reg.add::<relight::Relight>();
    reg.add::<relight_reference::RelightReference>();
    reg.add::<apply_materials::ApplyMaterials>();
    reg.add::<paint_material::PaintMaterial>();
    reg.add::<sv_transfer_precompute::SvTransferPrecompute>();
    reg.add::<sv_relight::SvRelight>();
}

/// Small BRDF spaces and bases for the unit tests of this folder, made by the nodes themselves.
#[cfg(test)]
pub(crate) mod test_support {
    use crate::testing::{f, first, i, run_on};
    use crate::types::{BrdfBasis, BrdfGrid, BrdfSample, BrdfSpace, Metrics};
    use relume_core::Value;

    /// A Cook-Torrance `BrdfSpaceSample` on an n × n × 2n grid: `samples` − 1 specular samples,
    /// roughnesses over [m_min, m_max] × `f0_count` F0 values over [0.02, 1].
    pub fn ct_space(n: i64, samples: i64, f0_count: i64, m_min: f64, m_max: f64) -> BrdfSpace {
        let p = [
            ("n_theta_i", i(n)),
            ("n_theta_o", i(n)),
            ("n_phi", i(2 * n)),
            ("samples", i(samples)),
            ("model", crate::testing::id("CookTorrance")),
            ("m_min", f(m_min)),
            ("m_max", f(m_max)),
            ("f0_count", i(f0_count)),
        ];
        first(&run_on::<super::brdf_space_sample::BrdfSpaceSample>(&p, vec![]).unwrap())
    }

    /// `BrdfSpaceSample` with the given grid, sample count and exponent range.
    pub fn space(n_theta_i: i64, n_theta_o: i64, n_phi: i64, samples: i64, s_min: f32, s_max: f32) -> BrdfSpace {
        let p = [
            ("n_theta_i", i(n_theta_i)),
            ("n_theta_o", i(n_theta_o)),
            ("n_phi", i(n_phi)),
            ("samples", i(samples)),
            ("s_min", f(s_min as f64)),
            ("s_max", f(s_max as f64)),
        ];
        first(&run_on::<super::brdf_space_sample::BrdfSpaceSample>(&p, vec![]).unwrap())
    }

    /// A space with the diffuse sample and specular samples of exactly the exponents `s`
    /// (repeats allowed: rank-deficient sets).
    pub fn space_of(n_theta_i: u32, n_theta_o: u32, n_phi: u32, s: &[f32]) -> BrdfSpace {
        let grid = BrdfGrid { n_theta_i, n_theta_o, n_phi };
        let samples: Vec<BrdfSample> =
            std::iter::once(BrdfSample::diffuse(1.0)).chain(s.iter().map(|&s| BrdfSample::blinn_phong(0.0, 1.0, s))).collect();
        let values = samples.iter().flat_map(|p| (0..grid.cells()).map(move |c| p.eval(grid.centre(c)) as f32)).collect();
        BrdfSpace { grid, samples, values }
    }

    /// The spheres scene made for relighting, `size`² pixels: spheres a and b one dynamic object
    /// ("glossy"), sphere c another (coloured), a fixed reddish floor, a point light and a
    /// small emitting quad of the same colour (so specular-only images are grey).
    pub fn scene(size: usize) -> crate::types::Scene {
        use crate::scene::builder::SceneBuilder;
        use crate::types::{Light, Material};
        use glam::Vec3;
        let glossy = Material::BlinnPhong { kd: Vec3::splat(0.3), ks: Vec3::splat(0.4), exponent: 20.0 };
        let coloured = Material::BlinnPhong { kd: Vec3::new(0.5, 0.2, 0.1), ks: Vec3::splat(0.3), exponent: 60.0 };
        let floor = Material::Lambert { albedo: Vec3::new(0.6, 0.4, 0.3) };
        let white = Material::Lambert { albedo: Vec3::splat(0.5) };
        let mut s = SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, size, size)
            .sphere("a", Vec3::new(-0.8, 0.0, 0.0), 0.5, glossy, Vec3::ZERO, false)
            .sphere("b", Vec3::new(0.7, 0.3, -0.5), 0.6, glossy, Vec3::ZERO, false)
            .sphere("c", Vec3::new(0.0, -0.6, 0.8), 0.3, coloured, Vec3::ZERO, false)
            .quad("floor", Vec3::new(-2.0, -1.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), floor, Vec3::ZERO)
            .quad("lamp", Vec3::new(-0.3, 1.5, 0.3), Vec3::new(0.0, 0.0, -0.6), Vec3::new(0.6, 0.0, 0.0), white, Vec3::splat(4.0))
            .light(Light::Point { position: Vec3::new(0.0, 2.0, 1.0), intensity: Vec3::splat(5.0) })
            .build();
        for o in &mut s.objects[..3] {
            o.dynamic = true;
        }
        s.objects[0].material_name = "glossy".into();
        s.objects[1].material_name = "glossy".into();
        s
    }

    /// `scene(size)` with UVs: spherical ones about each sphere's centre, planar ones on the
    /// floor and the lamp (what the SV extension's sub-regions need).
    pub fn sv_scene(size: usize) -> crate::types::Scene {
        use glam::{Vec2, Vec3};
        let mut s = scene(size);
        let mut object_of = vec![0u32; s.positions.len()];
        for (t, tri) in s.triangles.iter().enumerate() {
            tri.iter().for_each(|&v| object_of[v as usize] = s.tri_object[t]);
        }
        let mut centre = vec![(Vec3::ZERO, 0.0f32); s.objects.len()];
        for (p, &o) in s.positions.iter().zip(&object_of) {
            centre[o as usize].0 += *p;
            centre[o as usize].1 += 1.0;
        }
        s.uvs = s
            .positions
            .iter()
            .zip(&object_of)
            .map(|(p, &o)| {
                if o < 3 {
                    let d = (*p - centre[o as usize].0 / centre[o as usize].1).normalize();
                    Vec2::new(d.z.atan2(d.x) / std::f32::consts::TAU + 0.5, d.y.clamp(-1.0, 1.0).asin() / std::f32::consts::PI + 0.5)
                } else {
                    Vec2::new((p.x + 2.0) / 4.0, (p.z + 2.0) / 4.0)
                }
            })
            .collect();
        s
    }

    /// Everything `Relight` needs for `scene`: the accel, the projected scene materials, and
    /// the precompute's outputs (transfer, metrics, notes) at the given path counts.
    pub fn precompute(
        scene: &crate::types::Scene,
        basis: &BrdfBasis,
        counts: [i64; 4],
    ) -> (Value, crate::types::ObjectMaterials, crate::types::Transfer, relume_core::cache::CacheEntry) {
        use crate::types::accel::BuildQuality;
        let accel = Value::new(crate::types::Accel::build(scene, BuildQuality::Fast));
        let m: crate::types::ObjectMaterials =
            first(&run_on::<super::scene_materials::SceneMaterials>(&[], vec![Value::new(scene.clone())]).unwrap());
        let m = first(&run_on::<super::material_project::MaterialProject>(&[], vec![Value::new(basis.clone()), Value::new(m)]).unwrap());
        let p = [
            ("spp", i(counts[0])),
            ("light_samples", i(counts[1])),
            ("bounce_rays", i(counts[2])),
            ("bounce_light_samples", i(counts[3])),
            ("seed", i(3)),
        ];
        let inputs = vec![Value::new(scene.clone()), accel.clone(), Value::new(basis.clone())];
        let e = crate::testing::run_full::<super::transfer_precompute::TransferPrecompute>(&p, std::path::Path::new("."), inputs).unwrap();
        (accel, m, first(&e.outputs), e)
    }

    /// A 2 × 1 transfer by hand: one dynamic object "a", S = 1, a merged RGB direct image and a
    /// grey specular one (colour (1, 0.5, 0.25)); pixel 0 fixed, pixel 1 on "a"; `data` is
    /// the 16 floats (stride 8).
    pub fn tiny_transfer(data: Vec<f32>) -> crate::types::Transfer {
        use super::terms::{Channels, First, Term};
        crate::types::Transfer {
            width: 2,
            height: 1,
            terms: vec![(Term::Direct(First::Merged), Channels::Rgb), (Term::Direct(First::Specular(1)), Channels::Grey)],
            groups: vec!["a".into()],
            specular_bases: 1,
            colour: [1.0, 0.5, 0.25],
            counts: crate::types::PathCounts { spp: 1, light_samples: 1, bounce_rays: 1, bounce_light_samples: 1, seed: 0 },
            stride: 8,
            class: vec![0, 1],
            data,
        }
    }

    /// `BrdfPca` of `space` with `bases` bases: the basis and its metrics.
    pub fn basis(space: &BrdfSpace, bases: i64) -> (BrdfBasis, Metrics) {
        let out = run_on::<super::brdf_pca::BrdfPca>(&[("bases", i(bases))], vec![Value::new(space.clone())]).unwrap();
        (out[0].get::<BrdfBasis>().unwrap().clone(), out[1].get::<Metrics>().unwrap().clone())
    }
}
