//! Evaluating basis BRDFs at a shading point, for the relighting precompute ([S] 4.1.3: "在需要
//! 计算BRDF时，根据 (θi, θo, φ)，通过三线性插值相应的 ρ̃ 得到" — when a BRDF is needed, the basis
//! ρ̃ is interpolated trilinearly at (θi, θo, φ)).
//!
//! Basis BRDFs are not physical: bases 2 … N_b have negative lobes and may reflect more than
//! they receive ([S] 4.1.2). Everything here returns them signed; the BRDF library (`brdf/`)
//! clamps to ≥ 0 and must not be used for them. A precompute that weights paths by a basis
//! value must carry the sign through: no clamping of throughput, no Russian roulette or
//! importance sampling driven by a signed basis value (the thesis samples the hemisphere
//! uniformly for this reason). The lookup itself is `BrdfBasis::eval` / `BrdfGrid::trilinear`
//! (see `types/brdf_space.rs` for the grid, its edges and φ folding); this module adds the
//! world-frame entry points.

use crate::math::frame::Frame;
use crate::types::{BrdfBasis, Trilinear};
use glam::Vec3;

/// The trilinear lookup for world directions `wi` (toward the light) and `wo` (toward the
/// viewer) at a point with shading frame `frame`; `None` when either is at or below the
/// surface (one-sided, as the opaque BRDFs of `brdf/`).
pub fn lookup(basis: &BrdfBasis, frame: &Frame, wi: Vec3, wo: Vec3) -> Option<Trilinear> {
    basis.grid.trilinear(frame.to_local(wi), frame.to_local(wo))
}

/// Every basis BRDF at world directions (`wi`, `wo`) into `out` (`basis.bases()` values,
/// signed); zeros below the surface.
pub fn eval_bases(basis: &BrdfBasis, frame: &Frame, wi: Vec3, wo: Vec3, out: &mut [f32]) {
    match lookup(basis, frame, wi, wo) {
        Some(t) => out.iter_mut().enumerate().for_each(|(k, o)| *o = t.apply(basis.table(k)) as f32),
        None => out.fill(0.0),
    }
}

/// The tabulated material Σ_k c_k ρ̃_k at world directions (`wi`, `wo`), signed, in f64: what
/// a renderer that uses the projected BRDF (rather than the analytic one) evaluates.
pub fn eval_material(basis: &BrdfBasis, c: &[f64], frame: &Frame, wi: Vec3, wo: Vec3) -> f64 {
    lookup(basis, frame, wi, wo).map_or(0.0, |t| c.iter().enumerate().map(|(k, ck)| ck * t.apply(basis.table(k))).sum())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::brdf_space::test_support::{basis, space};
    use crate::math::rng::uniform;
    use crate::types::BrdfGrid;

    /// A direction of the upper hemisphere with cos θ ∈ [0.05, 1).
    fn upper(seed: u64, n: u64) -> Vec3 {
        let z = 0.05 + 0.95 * uniform(seed, n, 0);
        let a = 2.0 * std::f32::consts::PI * uniform(seed, n, 1);
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(r * a.cos(), r * a.sin(), z)
    }

    #[test]
    fn negative_lobes_come_back_signed_in_any_frame() {
        let (b, _) = basis(&space(10, 10, 20, 30, 1.0, 100.0), 6);
        let g = b.grid;
        let neg = (0..g.cells()).find(|&c| b.table(3)[c] < -1e-3).expect("basis 4 has a negative lobe");
        let [ti, to, phi] = g.centre(neg);
        let (li, lo) = BrdfGrid::directions(ti, to, phi);
        let n = Vec3::new(0.3, -0.8, 0.52).normalize();
        let f = Frame::from_normal(n);
        let (wi, wo) = (f.to_world(li.as_vec3()), f.to_world(lo.as_vec3()));
        let mut out = vec![0.0; b.bases()];
        eval_bases(&b, &f, wi, wo, &mut out);
        assert!((out[3] - b.table(3)[neg]).abs() < 1e-4 * b.table(3)[neg].abs().max(1.0), "{} vs {}", out[3], b.table(3)[neg]);
        assert!(out[3] < 0.0);
        // The material sum with one-hot coefficients is the basis itself.
        let onehot = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0];
        assert!((eval_material(&b, &onehot, &f, wi, wo) as f32 - out[3]).abs() < 1e-6);
        // Below the surface: zero.
        eval_bases(&b, &f, -wi, wo, &mut out);
        assert!(out.iter().all(|v| *v == 0.0));
    }

    #[test]
    fn bases_are_reciprocal_and_turn_with_the_frame() {
        // Blinn-Phong is reciprocal and isotropic, so are its PCA bases on a grid with as many
        // θi as θo cells.
        let (b, _) = basis(&space(12, 12, 24, 20, 1.0, 50.0), 5);
        let f = Frame::from_normal(Vec3::Z);
        let turned = Frame::from_normal(Vec3::new(-0.4, 0.1, 0.9).normalize());
        let (mut x, mut y) = (vec![0.0; 5], vec![0.0; 5]);
        for n in 0..300 {
            let (wi, wo) = (upper(3, 2 * n), upper(3, 2 * n + 1));
            eval_bases(&b, &f, wi, wo, &mut x);
            eval_bases(&b, &f, wo, wi, &mut y);
            for k in 0..5 {
                assert!((x[k] - y[k]).abs() <= 2e-3 * (1.0 + x[k].abs()), "basis {k}: {} vs {}", x[k], y[k]);
            }
            eval_bases(&b, &turned, turned.to_world(wi), turned.to_world(wo), &mut y);
            for k in 0..5 {
                assert!((x[k] - y[k]).abs() <= 2e-3 * (1.0 + x[k].abs()), "basis {k} turned: {} vs {}", x[k], y[k]);
            }
        }
    }
}
