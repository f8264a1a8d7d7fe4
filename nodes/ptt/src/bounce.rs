//! The one-bounce transfer of a vertex ([S] 5-8, 5.3.3.6), raw: T¹(l, c, s), the incident
//! radiance at the vertex after one reflection, per box lighting basis l (a texel of the
//! coarse cube map of `Visibility`), reflectance channel c (`ptt::channels`) and real SH
//! coefficient s (4 bands, 16, in world axes: neighbouring vertices' transfers can then be
//! interpolated, as the two-bounce transfer does at its hits, without their tangent frames —
//! which turn abruptly where a normal crosses z = 0 — entering; shading turns them into the
//! vertex frame with `math::sh_rotation`).
//!
//! Rays leave the vertex through the centres of the texels of a cube map of side
//! `rays_side` above its tangent plane (deterministic quadrature, each ray weighted by its
//! texel's solid angle). At a hit y on the front of a surface, y's direct light from basis
//! l is its visible cosine-weighted solid angle of coarse texel l, interpolated
//! barycentrically from the hit triangle's vertices ([S] 5.3.3.6: "the three vertices'
//! visibility interpolated"), times the BRDF at the texel's centre direction: the fixed
//! object's own BRDF, or each basis BRDF of the dynamic object's group. The light y sends
//! back along the ray is projected on the SH basis at the vertex. Missed rays carry no
//! bounce (the environment seen directly is T⁰'s); hits on a surface's back carry none
//! (one-sided surfaces, as the reference).

use super::channels::Channels;
use super::types::Visibility;
use super::vertices::{ray_offset, vertex_frame};
use glam::Vec3;
use relume_base::brdf;
use relume_base::brdf_space::basis_brdf::eval_bases;
use relume_base::math::cubemap::CubeMap;
use relume_base::math::sh::sh_basis_into;
use relume_base::types::{Accel, BrdfBasis, Scene};

/// SH coefficients of the bounce (4 bands).
pub const SH: usize = 16;

/// What the per-vertex tracing reads (see the module doc).
pub struct Bounce<'a> {
    scene: &'a Scene,
    accel: &'a Accel,
    vis: &'a Visibility,
    basis: &'a BrdfBasis,
    channels: &'a Channels,
    /// Ray directions (world) and their texels' solid angles.
    rays: Vec<(Vec3, f32)>,
    /// Centre directions of the coarse lighting texels (world).
    coarse: Vec<Vec3>,
    eps: f32,
}

impl<'a> Bounce<'a> {
    pub fn new(
        scene: &'a Scene,
        accel: &'a Accel,
        vis: &'a Visibility,
        basis: &'a BrdfBasis,
        channels: &'a Channels,
        rays_side: usize,
    ) -> Self {
        let cube = CubeMap::constant(rays_side, Vec3::ZERO);
        let rays = (0..cube.texels.len()).map(|k| (cube.direction(k), cube.solid_angle(k))).collect();
        let coarse_map = CubeMap::constant(vis.coarse as usize, Vec3::ZERO);
        let coarse = (0..coarse_map.texels.len()).map(|k| coarse_map.direction(k)).collect();
        Bounce { scene, accel, vis, basis, channels, rays, coarse, eps: ray_offset(scene) }
    }

    /// Box lighting bases (texels of the coarse map).
    pub fn lights(&self) -> usize {
        self.coarse.len()
    }

    /// Floats of one vertex's transfer: lights × channels × 16, laid out (l, c, s).
    pub fn floats(&self) -> usize {
        self.lights() * self.channels.count() * SH
    }

    /// Vertex `v`'s raw transfer into `out` (`floats()` long, overwritten); returns the rays
    /// traced.
    pub fn vertex(&self, v: usize, out: &mut [f32]) -> u64 {
        out.fill(0.0);
        let n = self.vis.normals[v];
        if n == Vec3::ZERO {
            return 0;
        }
        let o = self.scene.positions[v] + n * self.eps;
        let (lights, cc) = (self.lights(), self.channels.count());
        let mut sh = [0.0f32; SH];
        let mut direct = vec![0.0f32; lights];
        let mut f = vec![0.0f32; self.basis.bases()];
        let mut spread = vec![0.0f32; self.basis.bases() + 2];
        let mut rays = 0;
        for &(d, omega) in &self.rays {
            if d.dot(n) <= 0.0 {
                continue;
            }
            rays += 1;
            let Some(hit) = self.accel.intersect(o, d, self.eps, f32::INFINITY) else { continue };
            let tri = self.scene.triangles[hit.tri as usize];
            let b = [1.0 - hit.b1 - hit.b2, hit.b1, hit.b2];
            let ny = (0..3).map(|k| self.vis.normals[tri[k] as usize] * b[k]).sum::<Vec3>().normalize_or_zero();
            let wo = -d;
            if ny.dot(wo) <= 0.0 {
                continue;
            }
            direct.fill(0.0);
            for k in 0..3 {
                for (a, c) in direct.iter_mut().zip(self.vis.coarse_of(tri[k] as usize)) {
                    *a += b[k] * c;
                }
            }
            sh_basis_into(d, &mut sh);
            sh.iter_mut().for_each(|y| *y *= omega);
            let object = self.scene.tri_object[hit.tri as usize] as usize;
            let chans = self.channels.of_object(object);
            let fy = vertex_frame(ny);
            let group = self.channels.object_group[object];
            // Read once a hit: a fixed object's material, its texture maps applied there; a
            // textured dynamic group's diffuse map there.
            let material = group.is_none().then(|| self.scene.material_on(hit.tri as usize, b));
            let map = group.filter(|&g| self.channels.textured[g]).map(|_| self.scene.kd_map_on(hit.tri as usize, b).unwrap_or(Vec3::ONE));
            for (l, &e) in direct.iter().enumerate() {
                if e <= 0.0 {
                    continue;
                }
                let wi = self.coarse[l];
                let base = l * cc * SH;
                let rgb: [f32; 3];
                let values: &[f32] = match &material {
                    None => {
                        eval_bases(self.basis, &fy, wi, wo, &mut f);
                        // A diffuse map spreads the diffuse basis into its colours.
                        match map {
                            Some(t) => {
                                spread[..3].copy_from_slice(&(t * f[0]).to_array());
                                spread[3..].copy_from_slice(&f[1..]);
                                &spread
                            }
                            None => &f,
                        }
                    }
                    Some(m) => {
                        rgb = (brdf::eval(m, fy.to_local(wo), fy.to_local(wi))).to_array();
                        &rgb
                    }
                };
                for (c, v) in chans.clone().zip(values) {
                    let r = v * e;
                    out[base + c * SH..base + (c + 1) * SH].iter_mut().zip(&sh).for_each(|(t, y)| *t += r * y);
                }
            }
        }
        rays
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vertex_visibility::tests::visibility;
    use relume_base::math::sh::sh_clamped_cosine;
    use relume_base::scene::builder::SceneBuilder;
    use relume_base::types::accel::BuildQuality;
    use relume_base::types::{Environment, Material};

    /// A small floor under a wide roof (downward-facing) at height 0.5: the roof sees the
    /// lower sky all round, so under a uniform sky of radiance 1 its radiance is ρ, and the
    /// floor's centre, seeing only roof above, receives irradiance π ρ after one bounce.
    fn roofed(roof: Material, dynamic: bool) -> Scene {
        let mut s = SceneBuilder::new(Vec3::new(0.0, 3.0, 3.0), Vec3::ZERO, 40.0, 8, 8)
            .quad(
                "floor",
                Vec3::new(-0.01, 0.0, 0.01),
                Vec3::X * 0.02,
                Vec3::NEG_Z * 0.02,
                Material::Lambert { albedo: Vec3::splat(0.5) },
                Vec3::ZERO,
            )
            .quad("roof", Vec3::new(-50.0, 0.5, -50.0), Vec3::X * 100.0, Vec3::Z * 100.0, roof, Vec3::ZERO)
            .environment(Environment::Constant(Vec3::ONE))
            .build();
        s.objects[1].dynamic = dynamic;
        s
    }

    /// Irradiance on a floor (normal +y) from its transfer under a uniform sky and channel
    /// weights `w`.
    fn irradiance(b: &Bounce, t: &[f32], w: &[f32]) -> f32 {
        let cc = w.len();
        let cos = sh_clamped_cosine(4, Vec3::Y);
        let mut e = 0.0;
        for l in 0..b.lights() {
            for (c, wc) in w.iter().enumerate() {
                for s in 0..SH {
                    e += wc * t[(l * cc + c) * SH + s] * cos[s];
                }
            }
        }
        e
    }

    #[test]
    fn a_floor_under_a_diffuse_roof_receives_pi_rho_after_one_bounce() {
        // Measured: within 5 × 10⁻⁴ of π ρ (the roof's finite edge, the quadrature).
        let s = roofed(Material::Lambert { albedo: Vec3::splat(0.8) }, false);
        let accel = Accel::build(&s, BuildQuality::Fast);
        let vis = visibility(&s, 32, 8);
        let basis =
            relume_base::brdf_space::test_support::basis(&relume_base::brdf_space::test_support::space(6, 6, 12, 12, 1.0, 100.0), 3).0;
        let ch = Channels::new(&s, basis.bases()).expect("layout");
        assert_eq!(ch.count(), 1, "two fixed grey objects: one channel");
        let b = Bounce::new(&s, &accel, &vis, &basis, &ch, 32);
        let mut t = vec![0.0; b.floats()];
        assert!(b.vertex(0, &mut t) > 0);
        let e = irradiance(&b, &t, &[1.0]);
        let want = std::f32::consts::PI * 0.8;
        assert!((e / want - 1.0).abs() < 0.03, "irradiance {e}, want {want}");
    }

    #[test]
    fn a_dynamic_roof_through_its_diffuse_basis_gives_the_same_bounce() {
        // The roof dynamic: its channels are the basis BRDFs; weighing the diffuse one by
        // kd = 0.8 (and the specular ones by 0) is the Lambert roof of ρ = 0.8.
        let s = roofed(Material::BlinnPhong { kd: Vec3::splat(0.8), ks: Vec3::ZERO, exponent: 10.0 }, true);
        let accel = Accel::build(&s, BuildQuality::Fast);
        let vis = visibility(&s, 32, 8);
        let basis =
            relume_base::brdf_space::test_support::basis(&relume_base::brdf_space::test_support::space(6, 6, 12, 12, 1.0, 100.0), 3).0;
        let ch = Channels::new(&s, basis.bases()).expect("layout");
        assert_eq!((ch.fixed, ch.count()), (1, 1 + basis.bases()));
        let b = Bounce::new(&s, &accel, &vis, &basis, &ch, 32);
        let mut t = vec![0.0; b.floats()];
        b.vertex(0, &mut t);
        let mut w = vec![0.0; ch.count()];
        w[1] = 0.8;
        let e = irradiance(&b, &t, &w);
        let want = std::f32::consts::PI * 0.8;
        assert!((e / want - 1.0).abs() < 0.03, "irradiance {e}, want {want}");
        // A specular basis reflects something too (signed, not zero).
        w.fill(0.0);
        w[2] = 1.0;
        assert!(irradiance(&b, &t, &w).abs() > 1e-4);
    }
}
