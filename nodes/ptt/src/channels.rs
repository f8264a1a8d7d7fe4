//! The reflectance channels of the bounce transfer ([S] 5.2.1: T¹(l, r, p, s), r the
//! reflecting object, p its BRDF basis): every dynamic object group (`Scene::dynamic_groups`)
//! has one channel per basis BRDF, weighted at run time by its material's coefficients
//! H(r, p); the fixed-material objects together share channels that already hold their own
//! reflectance: one grey channel when every fixed material is colourless (r = g = b, as the
//! thesis stores "单颜色通道" for paths through fixed materials, 5.4), else three (r, g, b;
//! a fixed object with texture maps counts as coloured: its maps are read at each hit);
//! none when there is no fixed object. What a scene does not need is left out.

use glam::Vec3;
use relume_base::types::{Material, Object, Scene};
use std::ops::Range;

/// The channel layout of a scene (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Channels {
    /// Channels of the fixed objects: 0, 1 (grey) or 3 (RGB).
    pub fixed: usize,
    /// Names of the dynamic groups.
    pub groups: Vec<String>,
    /// Basis BRDFs per dynamic group (n_P).
    pub bases: usize,
    /// Per scene object, its dynamic group.
    pub object_group: Vec<Option<usize>>,
}

/// Whether every colour of `m` has equal components.
fn colourless(m: &Material) -> bool {
    let grey = |v: Vec3| v.x == v.y && v.y == v.z;
    match m {
        Material::Lambert { albedo } => grey(*albedo),
        Material::BlinnPhong { kd, ks, .. } | Material::CookTorrance { kd, ks, .. } => grey(*kd) && grey(*ks),
        Material::Dielectric { .. } => true,
    }
}

impl Channels {
    /// The layout of `scene` with `bases` basis BRDFs; refuses what the transfer cannot carry
    /// (dielectrics, emitting triangles, delta lights: the pipeline lights by the environment).
    pub fn new(scene: &Scene, bases: usize) -> Result<Channels, String> {
        for o in &scene.objects {
            if matches!(o.material, Material::Dielectric { .. }) {
                return Err(format!(
                    "object \"{}\" is a dielectric: the transfer tensors reflect only (use pipeline 3 for refraction)",
                    o.name
                ));
            }
            if o.emission != Vec3::ZERO {
                return Err(format!("object \"{}\" emits light: the transfer tensors light the scene by its environment only", o.name));
            }
        }
        if !scene.lights.is_empty() {
            return Err(format!(
                "the scene has {} point/spot/directional lights: the transfer tensors light it by its environment only",
                scene.lights.len()
            ));
        }
        let groups = scene.dynamic_groups();
        let mut object_group = vec![None; scene.objects.len()];
        for (g, (_, members)) in groups.iter().enumerate() {
            for &m in members {
                object_group[m as usize] = Some(g);
            }
        }
        // A texture map may colour what its material leaves grey: such objects count as coloured.
        let fixed: Vec<&Object> = scene.objects.iter().filter(|o| !o.dynamic).collect();
        let fixed = match () {
            _ if fixed.is_empty() => 0,
            _ if fixed.iter().all(|o| colourless(&o.material) && o.maps.is_empty()) => 1,
            _ => 3,
        };
        Ok(Channels { fixed, groups: groups.into_iter().map(|g| g.0).collect(), bases, object_group })
    }

    /// Channels in all.
    pub fn count(&self) -> usize {
        self.fixed + self.groups.len() * self.bases
    }

    /// The channels light reflected by scene object `o` lands in.
    pub fn of_object(&self, o: usize) -> Range<usize> {
        match self.object_group[o] {
            Some(g) => self.fixed + g * self.bases..self.fixed + (g + 1) * self.bases,
            None => 0..self.fixed,
        }
    }

    /// The weights of the channels for the dynamic groups' basis coefficients `h[g][p]`
    /// (RGB): fixed channels weigh 1 (grey: white; RGB: the unit colours).
    pub fn weights(&self, h: &[Vec<Vec3>]) -> Vec<Vec3> {
        let mut w = match self.fixed {
            0 => vec![],
            1 => vec![Vec3::ONE],
            _ => vec![Vec3::X, Vec3::Y, Vec3::Z],
        };
        for g in 0..self.groups.len() {
            w.extend((0..self.bases).map(|p| h.get(g).and_then(|c| c.get(p)).copied().unwrap_or(Vec3::ZERO)));
        }
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::scene::builder::SceneBuilder;

    fn scene(floor: Vec3, dynamic: bool) -> Scene {
        let mut s = SceneBuilder::new(Vec3::Z, Vec3::ZERO, 40.0, 8, 8)
            .quad("floor", Vec3::ZERO, Vec3::X, Vec3::NEG_Z, Material::Lambert { albedo: floor }, Vec3::ZERO)
            .quad(
                "box",
                Vec3::Y,
                Vec3::X,
                Vec3::NEG_Z,
                Material::BlinnPhong { kd: Vec3::splat(0.5), ks: Vec3::splat(0.3), exponent: 40.0 },
                Vec3::ZERO,
            )
            .build();
        s.objects[1].dynamic = dynamic;
        s
    }

    #[test]
    fn fixed_objects_share_grey_or_rgb_channels_and_dynamic_ones_get_the_bases() {
        let c = Channels::new(&scene(Vec3::splat(0.6), true), 5).expect("layout");
        assert_eq!((c.fixed, c.count(), c.of_object(0), c.of_object(1)), (1, 6, 0..1, 1..6));
        let c = Channels::new(&scene(Vec3::new(0.6, 0.2, 0.2), true), 5).expect("layout");
        assert_eq!((c.fixed, c.count(), c.of_object(1)), (3, 8, 3..8));
        let c = Channels::new(&scene(Vec3::splat(0.6), false), 5).expect("layout");
        assert_eq!((c.fixed, c.count(), c.groups.len()), (1, 1, 0));
        // A grey floor whose albedo a texture map colours is coloured.
        let mut textured = scene(Vec3::splat(0.6), true);
        let tex = relume_base::types::Texture::new(1, 1, vec![Vec3::new(1.0, 0.5, 0.5)]);
        textured.objects[0].maps = Box::new(relume_base::types::MaterialMaps { kd: tex, ..Default::default() });
        assert_eq!(Channels::new(&textured, 5).expect("layout").fixed, 3);
        let w = Channels::new(&scene(Vec3::splat(0.6), true), 2).expect("layout").weights(&[vec![Vec3::X, Vec3::Y]]);
        assert_eq!(w, vec![Vec3::ONE, Vec3::X, Vec3::Y]);
        let mut s = scene(Vec3::ONE, true);
        s.objects[0].emission = Vec3::ONE;
        assert!(Channels::new(&s, 5).expect_err("emitter").contains("emits"));
    }
}
