//! Pixel relighting with dynamic BRDFs ([S] chapter 4), on the BRDF space and basis of
//! `brdf_space`: the precompute (`TransferPrecompute`, on the paths of `paths` weighted by
//! `shades`; the terms a scene needs in `terms`), the interactive combine (`Relight`), the
//! same-seed render that measures the basis error alone (`RelightReference`), material edits
//! (`ApplyMaterials`, `PaintMaterial`) and the spatially varying extension (`SvTransferPrecompute`,
//! `SvRelight`).
//!
//! The crate's nodes join a registry beside relume-base's, which they build on:
//!
//! ```
//! let mut reg = relume_base::registry();
//! relume_relight::register(&mut reg);
//! for kind in ["TransferPrecompute", "Relight"] {
//!     assert!(reg.node(kind).is_some(), "{kind}");
//! }
//! ```

pub mod apply_materials;
pub mod paint_material;
pub mod paths;
#[allow(clippy::module_inception)]
pub mod relight_pixels;
pub mod relight_reference;
pub mod shades;
pub mod sv_precompute;
pub mod sv_relight;
pub mod sv_shade;
pub mod sv_terms;
pub mod sv_transfer_precompute;
pub mod terms;
pub mod transfer_precompute;
pub mod types;

// `pub fn register(reg)`: every node kind of the crate, found by build.rs.
include!(concat!(env!("OUT_DIR"), "/register.rs"));

/// Small BRDF spaces and bases for the unit tests of this folder, made by the nodes themselves.
#[cfg(test)]
pub(crate) mod test_support {
    use relume_base::testing::{first, i, run_on};
    use relume_base::types::BrdfBasis;
    use relume_core::Value;

    /// The spheres scene made for relighting, `size`² pixels: spheres a and b one dynamic object
    /// ("glossy"), sphere c another (coloured), a fixed reddish floor, a point light and a
    /// small emitting quad of the same colour (so specular-only images are grey).
    pub fn scene(size: usize) -> relume_base::types::Scene {
        use glam::Vec3;
        use relume_base::scene::builder::SceneBuilder;
        use relume_base::types::{Light, Material};
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
    pub fn sv_scene(size: usize) -> relume_base::types::Scene {
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
        scene: &relume_base::types::Scene,
        basis: &BrdfBasis,
        counts: [i64; 4],
    ) -> (Value, relume_base::types::ObjectMaterials, crate::types::Transfer, relume_core::cache::CacheEntry) {
        use relume_base::types::accel::BuildQuality;
        let accel = Value::new(relume_base::types::Accel::build(scene, BuildQuality::Fast));
        let m: relume_base::types::ObjectMaterials =
            first(&run_on::<relume_base::brdf_space::scene_materials::SceneMaterials>(&[], vec![Value::new(scene.clone())]).unwrap());
        let m = first(
            &run_on::<relume_base::brdf_space::material_project::MaterialProject>(&[], vec![Value::new(basis.clone()), Value::new(m)])
                .unwrap(),
        );
        let p = [
            ("spp", i(counts[0])),
            ("light_samples", i(counts[1])),
            ("bounce_rays", i(counts[2])),
            ("bounce_light_samples", i(counts[3])),
            ("seed", i(3)),
        ];
        let inputs = vec![Value::new(scene.clone()), accel.clone(), Value::new(basis.clone())];
        let e = relume_base::testing::run_full::<super::transfer_precompute::TransferPrecompute>(&p, std::path::Path::new("."), inputs)
            .unwrap();
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
            kd_maps: vec![None],
            stride: 8,
            class: vec![0, 1],
            data,
        }
    }
}
