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
    /// Per dynamic group, whether a diffuse texture map colours it: its diffuse basis then
    /// takes three channels (r, g, b), each holding the map's colour at the hits, weighted
    /// by that colour of Kd.
    pub textured: Vec<bool>,
}

/// Channels of each dynamic group with `bases` basis BRDFs: two more where a diffuse map
/// colours it (its diffuse basis in r, g and b).
pub fn group_channels(bases: usize, textured: &[bool]) -> impl Iterator<Item = usize> + '_ {
    textured.iter().map(move |&t| bases + if t { 2 } else { 0 })
}

/// A dynamic group's channel weights from its basis coefficients `c` (RGB, one per basis):
/// each coefficient; textured, the diffuse one split into its three colours.
pub fn group_weights(c: &[Vec3], textured: bool) -> Vec<Vec3> {
    match (textured, c.split_first()) {
        (true, Some((d, rest))) => {
            [Vec3::new(d.x, 0.0, 0.0), Vec3::new(0.0, d.y, 0.0), Vec3::new(0.0, 0.0, d.z)].into_iter().chain(rest.iter().copied()).collect()
        }
        _ => c.to_vec(),
    }
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
        let mut textured = Vec::with_capacity(groups.len());
        for (name, members) in &groups {
            let maps: Vec<&Object> = members.iter().map(|&m| &scene.objects[m as usize]).collect();
            if maps.iter().any(|o| o.maps.ks.is_some() || o.maps.exponent.is_some()) {
                return Err(format!(
                    "dynamic object \"{name}\" has a specular texture map: the transfer's basis channels carry one Ks and exponent per object (a diffuse map is taken)"
                ));
            }
            textured.push(!scene.uvs.is_empty() && maps.iter().any(|o| o.maps.kd.is_some()));
        }
        Ok(Channels { fixed, groups: groups.into_iter().map(|g| g.0).collect(), bases, object_group, textured })
    }

    /// Channels in all.
    pub fn count(&self) -> usize {
        self.fixed + group_channels(self.bases, &self.textured).sum::<usize>()
    }

    /// The channels light reflected by scene object `o` lands in.
    pub fn of_object(&self, o: usize) -> Range<usize> {
        match self.object_group[o] {
            Some(g) => {
                let start = self.fixed + group_channels(self.bases, &self.textured[..g]).sum::<usize>();
                start..start + group_channels(self.bases, &self.textured[g..=g]).sum::<usize>()
            }
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
        for (g, &textured) in self.textured.iter().enumerate() {
            let c: Vec<Vec3> = (0..self.bases).map(|p| h.get(g).and_then(|c| c.get(p)).copied().unwrap_or(Vec3::ZERO)).collect();
            w.extend(group_weights(&c, textured));
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
        textured.objects[0].maps = Box::new(relume_base::types::MaterialMaps { kd: tex.clone(), ..Default::default() });
        assert_eq!(Channels::new(&textured, 5).expect("layout").fixed, 3);
        // A dynamic box a diffuse map colours: its diffuse basis in three channels, weighed by
        // Kd's colours; the next objects' channels after them. Without UVs the map is unread.
        let mut dynamic = scene(Vec3::splat(0.6), true);
        dynamic.objects[1].maps = Box::new(relume_base::types::MaterialMaps { kd: tex, ..Default::default() });
        let untextured = Channels::new(&dynamic, 5).expect("layout");
        assert_eq!(untextured.count(), 6, "no UVs");
        dynamic.uvs = vec![glam::Vec2::ZERO; dynamic.positions.len()];
        let c = Channels::new(&dynamic, 3).expect("layout");
        assert_eq!((c.textured.clone(), c.count(), c.of_object(1)), (vec![true], 6, 1..6));
        let kd = Vec3::new(0.5, 0.25, 0.125);
        assert_eq!(
            c.weights(&[vec![kd, Vec3::ONE, Vec3::Y]]),
            vec![Vec3::ONE, kd * Vec3::X, kd * Vec3::Y, kd * Vec3::Z, Vec3::ONE, Vec3::Y]
        );
        dynamic.objects[1].maps.ks = dynamic.objects[1].maps.kd.clone();
        assert!(Channels::new(&dynamic, 3).expect_err("a specular map").contains("specular texture map"));
        let w = Channels::new(&scene(Vec3::splat(0.6), true), 2).expect("layout").weights(&[vec![Vec3::X, Vec3::Y]]);
        assert_eq!(w, vec![Vec3::ONE, Vec3::X, Vec3::Y]);
        let mut s = scene(Vec3::ONE, true);
        s.objects[0].emission = Vec3::ONE;
        assert!(Channels::new(&s, 5).expect_err("emitter").contains("emits"));
    }
}
