//! The wavelet radiance product ([P] 5.3.1, scheme 2; the EGSR paper's eq. 2–4): a BRDF as
//! 4-D Haar coefficients, so a point's outgoing radiance in every direction comes from its
//! incoming radiance's 2-D Haar coefficients by one sparse product, not a convolution per
//! outgoing direction (O(N²) for N directions each way).
//!
//! Both directions live in the receiver's local frame on the microbuffer's N × N Nusselt grid
//! (`microbuffer::nusselt_dir`): every pixel inside the disk subtends the projected solid
//! angle (2/N)², so the cosine is counted once, in the grid, and the incoming image is the
//! microbuffer's radiance as it is. With ρ'[o][i] = f(ωo, ωi) (2/N)² (0 off the disk) the
//! outgoing image is L_o = ρ' L_i. The 2-D Haar transform T (`math::haar`, orthonormal,
//! non-standard) on ωi, then on ωo, gives V = T ρ' Tᵀ (the thesis' "2-D transform on ωi,
//! then on ωo"), and with C = T L_i:
//!
//! D = V C, L_o = T⁻¹ D (= Tᵀ D).
//!
//! Coefficients of V below a threshold (every channel) are dropped: the BRDF's own
//! non-linear approximation, which makes V sparse. At threshold 0 the product is the
//! microbuffer's convolution at every grid direction, to rounding (tested).
//!
//! The outgoing image is in the point's frame; `to_cube` resamples it into the world cube
//! map the point tree stores (as J = L_o · cos θ, `wavelet_radiance::outgoing_intensity`),
//! which the forward Haar per face then codes.

use super::microbuffer::nusselt_dir;
use glam::Vec3;
use relume_base::brdf;
use relume_base::math::cubemap::{texel_directions, CubeMap};
use relume_base::math::frame::Frame;
use relume_base::math::haar;
use relume_base::types::Material;

/// V, the BRDF's 4-D Haar coefficients on an N × N grid each way, thresholded: per outgoing
/// coefficient (row) its kept entries (incoming coefficient, RGB value), rows in order.
#[derive(Clone, Debug)]
pub struct BrdfWavelets {
    pub n: usize,
    start: Vec<u32>,
    index: Vec<u32>,
    value: Vec<Vec3>,
    /// Entries of V before the threshold (N⁴).
    pub total: usize,
}

impl BrdfWavelets {
    /// Bytes the dense ρ' takes while V is built (N⁴ RGB entries in f32).
    pub fn working_bytes(n: usize) -> u64 {
        (n as u64).pow(4) * 12
    }

    /// V for material `m` on an `n` × `n` grid (a power of two, 2 to 64), keeping the entries
    /// with some channel of magnitude at least `threshold`.
    pub fn new(m: &Material, n: usize, threshold: f32) -> BrdfWavelets {
        assert!(n.is_power_of_two() && (2..=64).contains(&n), "the BRDF grid is a power of two from 2 to 64, not {n}");
        let (n2, w) = (n * n, 4.0 / (n * n) as f32);
        let dirs: Vec<Option<Vec3>> = (0..n2).map(|i| nusselt_dir(n, i)).collect();
        // Per channel, ρ' row by row (row o, column i), then T over each row (ωi)…
        let mut rho = vec![vec![0.0f32; n2 * n2]; 3];
        for (o, wo) in dirs.iter().enumerate() {
            let Some(wo) = wo else { continue };
            for (i, wi) in dirs.iter().enumerate() {
                if let Some(wi) = wi {
                    let f = brdf::eval(m, *wo, *wi) * w;
                    for (c, r) in rho.iter_mut().enumerate() {
                        r[o * n2 + i] = f[c];
                    }
                }
            }
        }
        let mut column = vec![0.0f32; n2];
        for r in &mut rho {
            for row in r.chunks_mut(n2) {
                haar::forward(row, n);
            }
            // … then over each column (ωo).
            for i in 0..n2 {
                for (o, v) in column.iter_mut().enumerate() {
                    *v = r[o * n2 + i];
                }
                haar::forward(&mut column, n);
                for (o, v) in column.iter().enumerate() {
                    r[o * n2 + i] = *v;
                }
            }
        }
        let mut v = BrdfWavelets { n, start: vec![0], index: vec![], value: vec![], total: n2 * n2 };
        for o in 0..n2 {
            for i in 0..n2 {
                let e = Vec3::new(rho[0][o * n2 + i], rho[1][o * n2 + i], rho[2][o * n2 + i]);
                if e != Vec3::ZERO && e.abs().max_element() >= threshold {
                    v.index.push(i as u32);
                    v.value.push(e);
                }
            }
            v.start.push(v.index.len() as u32);
        }
        v
    }

    /// Entries kept.
    pub fn kept(&self) -> usize {
        self.index.len()
    }

    pub fn bytes(&self) -> usize {
        self.index.len() * 16 + self.start.len() * 4
    }

    /// D = V C: the outgoing radiance's Haar coefficients from the incoming radiance's.
    pub fn product(&self, c: &[Vec3]) -> Vec<Vec3> {
        assert_eq!(c.len(), self.n * self.n, "incoming coefficients of an {0} × {0} grid", self.n);
        self.start
            .windows(2)
            .map(|r| {
                let (a, b) = (r[0] as usize, r[1] as usize);
                self.index[a..b].iter().zip(&self.value[a..b]).map(|(&i, v)| *v * c[i as usize]).sum()
            })
            .collect()
    }

    /// The outgoing radiance toward every grid direction (`nusselt_dir`; entries off the disk
    /// are not directions) from the incoming radiance image `l` (the microbuffer's pixels):
    /// C = T L, D = V C, L_o = T⁻¹ D.
    pub fn outgoing(&self, l: &[Vec3]) -> Vec<Vec3> {
        let n = self.n;
        let d = self.product(&per_channel(l, n, haar::forward));
        per_channel(&d, n, haar::inverse)
    }
}

/// The outgoing image `lo` (an `n` × `n` Nusselt grid in `frame`, from `outgoing`) on a
/// world cube map of side `side`, as J = L_o · cos θ: each texel above the point's plane
/// reads the grid at its direction's (x, y), bilinearly between the four nearest pixel
/// centres that lie on the disk (their weights renormalised, so the rim is not pulled toward
/// the black corners); texels below the plane are 0.
pub fn to_cube(lo: &[Vec3], n: usize, frame: &Frame, side: usize) -> CubeMap {
    assert_eq!(lo.len(), n * n, "an outgoing image of an {n} × {n} grid");
    let on_disk: Vec<bool> = (0..n * n).map(|i| nusselt_dir(n, i).is_some()).collect();
    let mut map = CubeMap::constant(side, Vec3::ZERO);
    for (t, d) in map.texels.iter_mut().zip(texel_directions(side).iter()) {
        let local = frame.to_local(*d);
        if local.z <= 0.0 {
            continue;
        }
        // Pixel coordinates of (x, y), centres at integers.
        let (u, v) = ((local.x + 1.0) * 0.5 * n as f32 - 0.5, (local.y + 1.0) * 0.5 * n as f32 - 0.5);
        let (x0, y0) = (u.floor(), v.floor());
        let (fx, fy) = (u - x0, v - y0);
        let (mut sum, mut weight) = (Vec3::ZERO, 0.0f32);
        for (dx, dy, w) in [(0, 0, (1.0 - fx) * (1.0 - fy)), (1, 0, fx * (1.0 - fy)), (0, 1, (1.0 - fx) * fy), (1, 1, fx * fy)] {
            let (x, y) = (x0 as i64 + dx, y0 as i64 + dy);
            if (0..n as i64).contains(&x) && (0..n as i64).contains(&y) && on_disk[y as usize * n + x as usize] && w > 0.0 {
                sum += lo[y as usize * n + x as usize] * w;
                weight += w;
            }
        }
        if weight > 0.0 {
            *t = sum / weight * local.z;
        }
    }
    map
}

/// `t` applied to each channel of an n × n RGB image.
fn per_channel(img: &[Vec3], n: usize, t: fn(&mut [f32], usize)) -> Vec<Vec3> {
    let mut out = vec![Vec3::ZERO; img.len()];
    for c in 0..3 {
        let mut ch: Vec<f32> = img.iter().map(|v| v[c]).collect();
        t(&mut ch, n);
        for (o, v) in out.iter_mut().zip(&ch) {
            o[c] = *v;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::microbuffer::Microbuffer;
    use relume_base::math::rng::uniform;

    /// A microbuffer holding random radiance on the disk.
    fn random_buffer(n: usize, seed: u64) -> Microbuffer {
        let mut mb = Microbuffer::new(n);
        for i in 0..n * n {
            if mb.dir(i).is_some() {
                let l = Vec3::new(uniform(seed, i as u64, 0), uniform(seed, i as u64, 1), uniform(seed, i as u64, 2)) * 2.0;
                mb.write(i, 1.0, l, 1.0, 1.0, None);
            }
        }
        mb.resolve();
        mb
    }

    fn materials() -> [Material; 3] {
        [
            Material::Lambert { albedo: Vec3::new(0.7, 0.5, 0.3) },
            Material::BlinnPhong { kd: Vec3::splat(0.2), ks: Vec3::new(0.6, 0.5, 0.4), exponent: 30.0 },
            Material::CookTorrance { kd: Vec3::splat(0.1), ks: Vec3::splat(0.8), roughness: 0.2, f0: 0.5 },
        ]
    }

    #[test]
    fn at_threshold_zero_the_product_is_the_microbuffers_convolution_in_every_direction() {
        for n in [4, 8] {
            for (k, m) in materials().iter().enumerate() {
                let mb = random_buffer(n, k as u64);
                let v = BrdfWavelets::new(m, n, 0.0);
                let lo = v.outgoing(mb.radiance());
                for (o, got) in lo.iter().enumerate() {
                    let Some(wo) = nusselt_dir(n, o) else { continue };
                    let want = mb.convolve(m, wo);
                    assert!(
                        (*got - want).abs().max_element() <= 1e-4 * (1.0 + want.max_element()),
                        "{m:?}, n {n}, ωo {wo}: {got} vs {want}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_threshold_keeps_few_terms_of_a_glossy_brdf_at_a_small_error() {
        // Measured at 16² (51,544 entries of V are not 0; relative L2 error of the outgoing
        // image): threshold 1e-4 keeps 26,208 (0.039 %), 1e-3 keeps 10,668 (0.86 %), 1e-2
        // keeps 1,072 (12 %). Most of what remains is the disk's jagged edge on both grids.
        let n = 16;
        let m = Material::BlinnPhong { kd: Vec3::splat(0.2), ks: Vec3::splat(0.7), exponent: 60.0 };
        let exact = BrdfWavelets::new(&m, n, 0.0);
        let sparse = BrdfWavelets::new(&m, n, 1e-3);
        let mb = random_buffer(n, 9);
        let (a, b) = (exact.outgoing(mb.radiance()), sparse.outgoing(mb.radiance()));
        let on_disk: Vec<usize> = (0..n * n).filter(|&o| nusselt_dir(n, o).is_some()).collect();
        let err = on_disk.iter().map(|&o| (a[o] - b[o]).length_squared() as f64).sum::<f64>().sqrt();
        let norm = on_disk.iter().map(|&o| a[o].length_squared() as f64).sum::<f64>().sqrt();
        assert!(sparse.kept() * 4 < exact.kept(), "kept {} of {}", sparse.kept(), exact.kept());
        assert!(err < 0.01 * norm, "relative L2 error {}", err / norm);
    }

    #[test]
    fn resampled_into_the_world_cube_the_product_sends_what_the_surfel_map_sends() {
        // One bright pixel of incoming light on a glossy point with a tilted normal: the
        // product's outgoing image on the world cube against `outgoing_intensity` fed the
        // same light as a sample (weight L · (2/N)², the pixel's projected solid angle).
        use crate::wavelet_radiance::outgoing_intensity;
        let (n, side) = (16, 16);
        let m = Material::BlinnPhong { kd: Vec3::splat(0.3), ks: Vec3::splat(0.6), exponent: 20.0 };
        let normal = Vec3::new(0.3, 0.8, -0.2).normalize();
        let frame = Frame::from_normal(normal);
        let p = (0..n * n).find(|&i| nusselt_dir(n, i).is_some_and(|d| d.z > 0.6 && d.x > 0.2)).unwrap();
        let mut l = vec![Vec3::ZERO; n * n];
        l[p] = Vec3::splat(50.0);
        let v = BrdfWavelets::new(&m, n, 0.0);
        let cube = to_cube(&v.outgoing(&l), n, &frame, side);
        let wi = frame.to_world(nusselt_dir(n, p).unwrap());
        let want = outgoing_intensity(&m, normal, &[(wi, Vec3::splat(50.0 * 4.0 / (n * n) as f32))], side);
        // Measured: exitance 2.93 against 2.99 (−2 %), texels 6.5 % apart in L2 (the grid
        // is read between its pixel centres).
        let (got, exp) = (cube.integral().x, want.integral().x);

        assert!((got / exp - 1.0).abs() < 0.04, "exitance {got} vs {exp}");
        let diff: f32 = cube.texels.iter().zip(&want.texels).map(|(a, b)| (a.x - b.x).powi(2)).sum::<f32>().sqrt();
        let norm: f32 = want.texels.iter().map(|b| b.x * b.x).sum::<f32>().sqrt();
        assert!(diff < 0.05 * norm, "texels {} apart", diff / norm);
        // Nothing below the plane.
        for (t, d) in cube.texels.iter().zip(texel_directions(side).iter()) {
            assert!(d.dot(normal) > 0.0 || *t == Vec3::ZERO);
        }
    }

    #[test]
    fn uniform_light_on_a_lambert_point_comes_back_as_its_albedo() {
        // L_i = 1 over the hemisphere: L_o = albedo · (Σ over the disk's pixels of (2/N)²) / π,
        // the disk's area in pixels (π up to the grid) over π.
        let n = 16;
        let albedo = Vec3::new(0.8, 0.4, 0.2);
        let v = BrdfWavelets::new(&Material::Lambert { albedo }, n, 0.0);
        let l: Vec<Vec3> = (0..n * n).map(|i| if nusselt_dir(n, i).is_some() { Vec3::ONE } else { Vec3::ZERO }).collect();
        let disk = l.iter().filter(|v| v.x > 0.0).count() as f32 * 4.0 / (n * n) as f32;
        for (o, lo) in v.outgoing(&l).iter().enumerate() {
            if nusselt_dir(n, o).is_some() {
                assert!((*lo - albedo * disk / std::f32::consts::PI).abs().max_element() < 1e-4, "{lo}");
            }
        }
        // The grid's disk is 208 pixels at 16², 3.25 for π (3.4 % over): what the
        // microbuffer's convolution shares.
        assert!((disk / std::f32::consts::PI - 1.0).abs() < 0.04, "{disk}");
    }
}
