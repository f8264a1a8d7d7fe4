//! The BRDF space of pipeline 1 ([S] 4.1.2), which pipeline 2's bounce channels take too:
//! `BrdfSpace` (Blinn-Phong or Cook-Torrance samples tabulated on a (θi, θo, φ) grid) and
//! `BrdfBasis` (basis BRDF tables on the same grid, with the coefficient table c(s) of a
//! Blinn-Phong space or the sampled ranges of a Cook-Torrance one, and a signed trilinear
//! lookup).
//!
//! **The grid** ([`BrdfGrid`]): θi, θo ∈ [0, π/2] and φ ∈ [0, π], φ the relative azimuth of ωi
//! and ωo folded into [0, π] (an isotropic BRDF is symmetric in φ ↔ 2π − φ, [S] 4-17), so the
//! mirror direction of ωo is at φ = π. Each axis is split into n equal cells and a value is
//! taken at each cell's centre: θ_a = (a + ½) (π/2) / n, φ_c = (c + ½) π / n_φ. No sample lies
//! on θ = π/2 (grazing) or on the axis ends. Cell (a, b, c) — θi index a, θo index b, φ index
//! c — is entry (a n_θo + b) n_φ + c of a table.
//!
//! **Weights** ([`BrdfGrid::weights`]): the cell's share of the measure dωi dωo, with the
//! absolute azimuth integrated out: (cos θi,lo − cos θi,hi)(cos θo,lo − cos θo,hi) Δφ, summing
//! to π over the grid (the full ∫∫ dωi dωo over two hemispheres is 4π × that). `BrdfPca`
//! weighs cells by it by default; [S] flattens the uniformly sampled tensor into a plain
//! vector, i.e. weighs every cell alike (`BrdfPca`'s `Uniform`; it reports both errors).
//!
//! **Lookup** ([`BrdfBasis::eval`], [`BrdfGrid::trilinear`]): trilinear between the eight
//! surrounding cell centres, in the angles. Between the outermost centre of an axis and that
//! axis' end (the outer half cell), the coordinate is held at the outermost centre: the lookup
//! is constant there. For φ this is exact symmetry (the table continues mirrored past 0 and π,
//! so the interpolant between the last centre and its mirror image is flat); for θ it is
//! nearest-centre extrapolation over the last half cell. Values are never clamped: basis
//! BRDFs have negative lobes and the lookup returns them signed. Directions at or below the
//! horizon (ω.z ≤ 0) give 0, as the one-sided BRDFs of `brdf/` do.
//!
//! **Precision**: tables are f32. A table entry's rounding (2⁻²⁴ relative) is five orders of
//! magnitude below the PCA's reconstruction error (≈ 10⁻² at N_b = 6), the renderer evaluates
//! in f32 anyway, and f32 halves memory and disk (the default space, 201 samples of
//! 30 × 30 × 60, is 43 MB instead of 87 MB). The PCA reads them as f64 and works in f64; the
//! coefficient table c(s) (a few thousand numbers) is kept in f64.

use crate::brdf::{blinn_phong, cook_torrance};
use bytemuck::{Pod, Zeroable};
use glam::{DVec3, Vec3};
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};
use std::f64::consts::{FRAC_1_PI, FRAC_PI_2, PI};

/// Largest `BrdfSpace` a node may allocate (2 GiB of table values); bigger requests are refused
/// before allocating, with the estimate.
pub const MAX_BRDF_SPACE_BYTES: u64 = 2 << 30;

/// The (θi, θo, φ) grid of cell centres (see the module comment). Every size is ≥ 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct BrdfGrid {
    /// Cells over θi ∈ [0, π/2].
    pub n_theta_i: u32,
    /// Cells over θo ∈ [0, π/2].
    pub n_theta_o: u32,
    /// Cells over the folded relative azimuth φ ∈ [0, π].
    pub n_phi: u32,
}

/// The eight table entries and weights of one trilinear lookup (weights sum to 1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trilinear {
    pub cells: [u32; 8],
    pub weights: [f64; 8],
}

impl Trilinear {
    /// Σ weight × table[cell], signed, in f64.
    pub fn apply(&self, table: &[f32]) -> f64 {
        self.cells.iter().zip(&self.weights).map(|(&c, &w)| w * table[c as usize] as f64).sum()
    }
}

/// Index and fraction of a coordinate `x` (in cell units, centres at k + ½) on an axis of
/// `n` cells: the lower centre, the upper one and the weight of the upper one, held constant
/// over the outer half cells.
fn axis(x: f64, n: u32) -> (u32, u32, f64) {
    let u = (x - 0.5).clamp(0.0, (n - 1) as f64);
    if n == 1 {
        return (0, 0, 0.0);
    }
    let i0 = (u.floor() as u32).min(n - 2);
    (i0, i0 + 1, u - i0 as f64)
}

impl BrdfGrid {
    /// Number of cells n_θi n_θo n_φ (as u64: sizes are checked before any allocation).
    pub fn cells_u64(&self) -> u64 {
        (self.n_theta_i as u64).saturating_mul(self.n_theta_o as u64).saturating_mul(self.n_phi as u64)
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.cells_u64() as usize
    }

    /// Whether every size is ≥ 1.
    pub fn is_valid(&self) -> bool {
        self.n_theta_i >= 1 && self.n_theta_o >= 1 && self.n_phi >= 1
    }

    /// Table index of cell (θi index a, θo index b, φ index c).
    pub fn index(&self, a: u32, b: u32, c: u32) -> usize {
        ((a as usize * self.n_theta_o as usize) + b as usize) * self.n_phi as usize + c as usize
    }

    /// The (θi, θo, φ) centre of cell `cell` (radians).
    pub fn centre(&self, cell: usize) -> [f64; 3] {
        let c = cell % self.n_phi as usize;
        let b = (cell / self.n_phi as usize) % self.n_theta_o as usize;
        let a = cell / (self.n_phi as usize * self.n_theta_o as usize);
        [
            (a as f64 + 0.5) * FRAC_PI_2 / self.n_theta_i as f64,
            (b as f64 + 0.5) * FRAC_PI_2 / self.n_theta_o as f64,
            (c as f64 + 0.5) * PI / self.n_phi as f64,
        ]
    }

    /// `sample` at every cell centre, in table order, in f32: the values a `BrdfSpace` holds
    /// for it, before any compression.
    pub fn tabulate(&self, sample: &BrdfSample) -> Vec<f32> {
        (0..self.cells()).map(|c| sample.eval(self.centre(c)) as f32).collect()
    }

    /// Solid-angle weight of every cell, in table order (see the module comment).
    pub fn weights(&self) -> Vec<f64> {
        let band = |k: u32, n: u32| {
            let d = FRAC_PI_2 / n as f64;
            (k as f64 * d).cos() - ((k + 1) as f64 * d).cos()
        };
        let dphi = PI / self.n_phi as f64;
        let mut w = Vec::with_capacity(self.cells());
        for a in 0..self.n_theta_i {
            for b in 0..self.n_theta_o {
                let ab = band(a, self.n_theta_i) * band(b, self.n_theta_o) * dphi;
                w.extend(std::iter::repeat_n(ab, self.n_phi as usize));
            }
        }
        w
    }

    /// [`BrdfGrid::weights`] times cos θi cos θo at each cell's centre: the projected solid
    /// angle (`BrdfBasis::fit_specular` weighs by it).
    pub fn projected_weights(&self) -> Vec<f64> {
        let w = self.weights();
        (0..self.cells())
            .map(|c| {
                let [ti, to, _] = self.centre(c);
                w[c] * ti.cos() * to.cos()
            })
            .collect()
    }

    /// (ωi, ωo) in the local frame (+z the normal) for angles (θi, θo, φ): ωo in the xz-plane
    /// at azimuth 0, ωi at azimuth φ.
    pub fn directions(theta_i: f64, theta_o: f64, phi: f64) -> (DVec3, DVec3) {
        let wi = DVec3::new(theta_i.sin() * phi.cos(), theta_i.sin() * phi.sin(), theta_i.cos());
        let wo = DVec3::new(theta_o.sin(), 0.0, theta_o.cos());
        (wi, wo)
    }

    /// (θi, θo, φ) of two local-frame directions (need not be unit length); `None` when either
    /// is at or below the horizon or not finite. φ ∈ [0, π] is the folded relative azimuth.
    pub fn angles(wi: Vec3, wo: Vec3) -> Option<[f64; 3]> {
        let (i, o) = (wi.as_dvec3(), wo.as_dvec3());
        if !(i.z > 0.0 && o.z > 0.0 && i.is_finite() && o.is_finite()) {
            return None;
        }
        let theta = |v: DVec3| (v.x * v.x + v.y * v.y).sqrt().atan2(v.z);
        let phi = (i.x * o.y - i.y * o.x).abs().atan2(i.x * o.x + i.y * o.y);
        Some([theta(i), theta(o), phi])
    }

    /// The trilinear lookup of angles (θi, θo, φ) (see the module comment for the edges).
    pub fn trilinear_at(&self, [ti, to, phi]: [f64; 3]) -> Trilinear {
        let (a0, a1, ta) = axis(ti / (FRAC_PI_2 / self.n_theta_i as f64), self.n_theta_i);
        let (b0, b1, tb) = axis(to / (FRAC_PI_2 / self.n_theta_o as f64), self.n_theta_o);
        let (c0, c1, tc) = axis(phi / (PI / self.n_phi as f64), self.n_phi);
        let mut cells = [0u32; 8];
        let mut weights = [0.0f64; 8];
        for k in 0..8 {
            let (a, wa) = if k & 4 == 0 { (a0, 1.0 - ta) } else { (a1, ta) };
            let (b, wb) = if k & 2 == 0 { (b0, 1.0 - tb) } else { (b1, tb) };
            let (c, wc) = if k & 1 == 0 { (c0, 1.0 - tc) } else { (c1, tc) };
            cells[k] = self.index(a, b, c) as u32;
            weights[k] = wa * wb * wc;
        }
        Trilinear { cells, weights }
    }

    /// The trilinear lookup of two local-frame directions; `None` below the horizon.
    pub fn trilinear(&self, wi: Vec3, wo: Vec3) -> Option<Trilinear> {
        Self::angles(wi, wo).map(|a| self.trilinear_at(a))
    }
}

/// One material of the space: f = kd/π + ks · lobe, the lobe Blinn-Phong (s+2)/(8π) cos^s δ
/// (`brdf::blinn_phong`) when m = 0, or Cook-Torrance D F G / (4 cos θi cos θo) of Beckmann
/// roughness m > 0 and Schlick F0 `f0` (`brdf::cook_torrance`), s unused.
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
#[repr(C)]
pub struct BrdfSample {
    pub kd: f32,
    pub ks: f32,
    /// Blinn-Phong exponent s.
    pub s: f32,
    /// Cook-Torrance roughness m (0 for a Blinn-Phong lobe).
    pub m: f32,
    /// Cook-Torrance Schlick F0.
    pub f0: f32,
}

impl BrdfSample {
    /// The diffuse sample kd/π (ks = 0).
    pub fn diffuse(kd: f32) -> Self {
        Self::blinn_phong(kd, 0.0, 0.0)
    }

    /// A Blinn-Phong material (kd, ks, s).
    pub fn blinn_phong(kd: f32, ks: f32, s: f32) -> Self {
        BrdfSample { kd, ks, s, m: 0.0, f0: 0.0 }
    }

    /// A Cook-Torrance lobe ks D F G / (4 cos θi cos θo) of roughness m > 0 and F0 `f0` (kd = 0).
    pub fn cook_torrance(ks: f32, m: f32, f0: f32) -> Self {
        BrdfSample { kd: 0.0, ks, s: 0.0, m, f0 }
    }

    /// True for a Cook-Torrance lobe (m > 0).
    pub fn is_cook_torrance(&self) -> bool {
        self.m > 0.0
    }

    /// f at angles (θi, θo, φ), in f64, with the library's BRDFs.
    pub fn eval(&self, angles: [f64; 3]) -> f64 {
        if self.is_cook_torrance() {
            let (wi, wo) = BrdfGrid::directions(angles[0], angles[1], angles[2]);
            self.kd as f64 * FRAC_1_PI + self.ks as f64 * cook_torrance::specular(self.m, self.f0, wo.as_vec3(), wi.as_vec3())
        } else {
            self.eval_cos_h(cos_half(angles[0], angles[1], angles[2]))
        }
    }

    /// f of a Blinn-Phong sample for a half vector at cos δ = `cos_h` from the normal.
    pub fn eval_cos_h(&self, cos_h: f64) -> f64 {
        self.kd as f64 * FRAC_1_PI + self.ks as f64 * blinn_phong::specular(self.s, cos_h)
    }

    /// True for the diffuse sample (ks = 0, kd > 0).
    pub fn is_diffuse(&self) -> bool {
        self.ks == 0.0 && self.kd > 0.0
    }
}

/// cos δ of the half vector of the directions at (θi, θo, φ) (both above the horizon).
pub fn cos_half(theta_i: f64, theta_o: f64, phi: f64) -> f64 {
    let (wi, wo) = BrdfGrid::directions(theta_i, theta_o, phi);
    let h = wi + wo;
    h.z / h.length()
}

/// Bytes of one [`BrdfSample`].
const SAMPLE_BYTES: u64 = std::mem::size_of::<BrdfSample>() as u64;

/// BRDF samples tabulated on a grid ([S] 4-18): sample i's values are
/// `values[i * cells..(i + 1) * cells]`, in table order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BrdfSpace {
    pub grid: BrdfGrid,
    #[serde(with = "pod_vec")]
    pub samples: Vec<BrdfSample>,
    /// f32 values (see the module comment), `samples.len() × grid.cells()`.
    #[serde(with = "pod_vec")]
    pub values: Vec<f32>,
}

impl BrdfSpace {
    /// Bytes a space of `samples` samples on `grid` holds (table and sample list), for
    /// refusing requests before allocating.
    pub fn bytes_for(grid: &BrdfGrid, samples: u64) -> u64 {
        grid.cells_u64().saturating_mul(samples).saturating_mul(4).saturating_add(samples.saturating_mul(SAMPLE_BYTES) + 32)
    }

    /// The table of sample `i`.
    pub fn sample(&self, i: usize) -> &[f32] {
        let n = self.grid.cells();
        &self.values[i * n..(i + 1) * n]
    }
}

impl BrdfSpace {
    /// Whether the grid is valid and the values fill it for every sample (what a decoded
    /// payload must satisfy).
    pub fn is_consistent(&self) -> bool {
        let n = self.grid.cells_u64().checked_mul(self.samples.len() as u64);
        self.grid.is_valid() && n == Some(self.values.len() as u64)
    }
}

/// Disk encoding: serde through postcard, the sample list and the table as little-endian byte
/// strings; decoding checks that the grid is valid and the table has one value per sample and
/// cell.
impl PortValue for BrdfSpace {
    const NAME: &'static str = "BrdfSpace";
    const COLOR: [u8; 3] = [200, 140, 240];
    const DOC: &'static str = "BRDF samples (Blinn-Phong kd, ks, s or Cook-Torrance m, F0) tabulated on a (θi, θo, φ) grid";
    fn byte_size(&self) -> usize {
        self.values.len() * 4 + self.samples.len() * SAMPLE_BYTES as usize + 32
    }
    relume_core::serde_codec!(check BrdfSpace::is_consistent);
}

/// Basis BRDFs ([S] 4-19) on a grid: basis 0 is the diffuse sample (kd = 1: the table 1/π),
/// bases 1.. the PCA components of the specular samples, in order of decreasing eigenvalue,
/// each W-orthonormal (W the cell weights). The coefficient table c(s) ([S] 4-20, 4-22) holds,
/// for each sampled exponent s_j (non-decreasing), the coefficients of the material
/// (kd = 0, ks = 1, s_j) on the specular bases; the diffuse coefficient is kd itself and the
/// specular samples have none on basis 0 ([S] 4-21). A basis made from Cook-Torrance samples
/// has no table (`family` says so): its materials are fitted ([`BrdfBasis::fit_specular`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BrdfBasis {
    pub grid: BrdfGrid,
    /// The specular samples' family, which says how a material finds its coefficients.
    pub family: BasisFamily,
    /// `bases() × grid.cells()` f32 values, basis k at `[k * cells..]`.
    #[serde(with = "pod_vec")]
    pub tables: Vec<f32>,
    /// The sampled exponents s_j, non-decreasing.
    pub s_values: Vec<f64>,
    /// `s_values.len() × (bases() − 1)`: row j = c(s_j) on bases 1...
    pub coefficients: Vec<f64>,
    /// The PCA eigenvalue of each specular basis (decreasing), for reports.
    pub eigenvalues: Vec<f64>,
}

/// The family of specular samples a [`BrdfBasis`] was made from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum BasisFamily {
    /// Blinn-Phong samples: the coefficient table c(s) over `s_values`.
    BlinnPhong,
    /// Cook-Torrance samples over roughness m ∈ [m[0], m[1]] and Schlick F0 ∈ [f0[0], f0[1]]:
    /// no table (`s_values` and `coefficients` are empty); a material is fitted.
    CookTorrance { m: [f64; 2], f0: [f64; 2] },
}

impl BrdfBasis {
    /// Number of bases N_b (the diffuse one included).
    pub fn bases(&self) -> usize {
        self.tables.len() / self.grid.cells().max(1)
    }

    /// The table of basis k.
    pub fn table(&self, k: usize) -> &[f32] {
        let n = self.grid.cells();
        &self.tables[k * n..(k + 1) * n]
    }

    /// Basis k at (ωi, ωo) (local frame, +z the normal), signed, trilinear; 0 below the horizon.
    pub fn eval(&self, k: usize, wi: Vec3, wo: Vec3) -> f32 {
        self.grid.trilinear(wi, wo).map_or(0.0, |t| t.apply(self.table(k)) as f32)
    }

    /// Every basis at (ωi, ωo) into `out` (one lookup, `bases()` tables); zeros below the horizon.
    pub fn eval_all(&self, wi: Vec3, wo: Vec3, out: &mut [f32]) {
        match self.grid.trilinear(wi, wo) {
            Some(t) => out.iter_mut().enumerate().for_each(|(k, o)| *o = t.apply(self.table(k)) as f32),
            None => out.fill(0.0),
        }
    }

    /// The range [s_min, s_max] of sampled exponents (`None` without specular samples).
    pub fn s_range(&self) -> Option<(f64, f64)> {
        Some((*self.s_values.first()?, *self.s_values.last()?))
    }

    /// c(s) on bases 1.. for (kd = 0, ks = 1, s), linear in s between the sampled exponents
    /// ([S] 4-22); an error message naming the range for s outside it.
    pub fn specular_coefficients(&self, s: f64) -> Result<Vec<f64>, String> {
        let k = self.bases() - 1;
        if let BasisFamily::CookTorrance { .. } = self.family {
            return Err("the basis was made from Cook-Torrance samples and has no table c(s) for a Blinn-Phong exponent".into());
        }
        let Some((lo, hi)) = self.s_range() else {
            return Err("the basis has no specular samples".into());
        };
        if !(s >= lo && s <= hi) {
            return Err(format!("s = {s} is outside the exponents [{lo}, {hi}] the BRDF basis was sampled over"));
        }
        let j = self.s_values.partition_point(|&v| v < s).max(1) - 1;
        let j1 = (j + 1).min(self.s_values.len() - 1);
        let (s0, s1) = (self.s_values[j], self.s_values[j1]);
        let t = if s1 > s0 { ((s - s0) / (s1 - s0)).clamp(0.0, 1.0) } else { 0.0 };
        let (r0, r1) = (&self.coefficients[j * k..(j + 1) * k], &self.coefficients[j1 * k..(j1 + 1) * k]);
        Ok(r0.iter().zip(r1).map(|(a, b)| a + t * (b - a)).collect())
    }

    /// The coefficients of (kd, ks, s) on every basis: (kd, ks c(s)) ([S] 4-22). With ks = 0
    /// the exponent plays no part (and may lie outside the sampled range).
    pub fn project(&self, kd: f64, ks: f64, s: f64) -> Result<Vec<f64>, String> {
        let spec = if ks == 0.0 { vec![0.0; self.bases() - 1] } else { self.specular_coefficients(s)? };
        Ok(std::iter::once(kd).chain(spec.iter().map(|c| ks * c)).collect())
    }

    /// The least-squares coefficients on bases 1.. of a specular BRDF `f(θi, θo, φ)` outside
    /// the sampled family (a Cook-Torrance lobe, ks = 1), and the fit's relative L2 error
    /// ‖f − f̂‖ / ‖f‖ (0 for f = 0). Cells weigh by their projected solid angle, the solid
    /// angle times cos θi cos θo, the measure reflected light integrates the BRDF against
    /// (cos θi) as seen from ωo (cos θo), which keeps a microfacet BRDF's 1/(cos θi cos θo)
    /// growth toward grazing from ruling the fit as much as it would under the plain solid
    /// angle. Blinn-Phong bases cannot hold that growth: a Cook-Torrance lobe of m 0.3 fits
    /// them with 79.5 % error (91 % under the solid angle), nearly all of it in grazing cells,
    /// while the same lobe times cos θi cos θo fits within 5 %.
    pub fn fit_specular(&self, f: impl Fn([f64; 3]) -> f64) -> (Vec<f64>, f64) {
        let (k, cells) = (self.bases() - 1, self.grid.cells());
        let w = self.grid.projected_weights();
        let values: Vec<f64> = (0..cells).map(|c| f(self.grid.centre(c))).collect();
        let table = |b: usize| &self.tables[(b + 1) * cells..(b + 2) * cells];
        let mut gram = vec![0.0; k * k];
        for a in 0..k {
            for b in a..k {
                let g = crate::math::pca::weighted_dot(table(a), &w, table(b));
                (gram[a * k + b], gram[b * k + a]) = (g, g);
            }
        }
        let rhs: Vec<f64> = (0..k).map(|a| crate::math::pca::weighted_dot(table(a), &w, &values)).collect();
        let c = crate::math::sh_rotation::solve(gram, rhs, k, 1);
        let (mut err, mut norm) = (0.0, 0.0);
        for (l, v) in values.iter().enumerate() {
            let fit: f64 = c.iter().enumerate().map(|(b, cb)| cb * table(b)[l] as f64).sum();
            err += w[l] * (v - fit).powi(2);
            norm += w[l] * v * v;
        }
        let rel = if norm > 0.0 { (err / norm).sqrt() } else { 0.0 };
        (c, rel)
    }

    /// Σ_k c_k basis_k at (ωi, ωo): the material with coefficients `c` (one per basis).
    pub fn eval_sum(&self, c: &[f64], wi: Vec3, wo: Vec3) -> f64 {
        self.grid.trilinear(wi, wo).map_or(0.0, |t| c.iter().enumerate().map(|(k, ck)| ck * t.apply(self.table(k))).sum())
    }
}

impl BrdfBasis {
    /// Whether the tables, coefficients and eigenvalues agree with the grid and the number of
    /// bases (what a decoded payload must satisfy).
    pub fn is_consistent(&self) -> bool {
        let cells = self.grid.cells_u64();
        self.grid.is_valid()
            && (self.tables.len() as u64).is_multiple_of(cells)
            && self.tables.len() as u64 >= cells
            && self.coefficients.len() == self.s_values.len() * (self.bases() - 1)
            && self.eigenvalues.len() == self.bases() - 1
    }
}

/// Disk encoding: serde through postcard, the tables as a little-endian byte string; decoding
/// checks the grid, whole tables (at least the diffuse one), a coefficient row per sampled
/// exponent and an eigenvalue per specular basis.
impl PortValue for BrdfBasis {
    const NAME: &'static str = "BrdfBasis";
    const COLOR: [u8; 3] = [170, 110, 230];
    const DOC: &'static str = "basis BRDF tables (diffuse + PCA) with the coefficient table c(s)";
    fn byte_size(&self) -> usize {
        self.tables.len() * 4 + (self.s_values.len() + self.coefficients.len() + self.eigenvalues.len()) * 8 + 32
    }
    relume_core::serde_codec!(check BrdfBasis::is_consistent);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> BrdfGrid {
        BrdfGrid { n_theta_i: 3, n_theta_o: 4, n_phi: 5 }
    }

    fn space() -> BrdfSpace {
        let g = grid();
        let samples = vec![BrdfSample::diffuse(1.0), BrdfSample::blinn_phong(0.0, 1.0, 3.0)];
        let values = samples.iter().flat_map(|smp| (0..g.cells()).map(move |c| smp.eval(g.centre(c)) as f32)).collect();
        BrdfSpace { grid: g, samples, values }
    }

    fn basis() -> BrdfBasis {
        let g = grid();
        let n = g.cells();
        let tables = (0..3 * n).map(|i| (i as f32 * 0.37).sin() - 0.2).collect();
        BrdfBasis {
            grid: g,
            family: BasisFamily::BlinnPhong,
            tables,
            s_values: vec![1.0, 2.0, 4.0],
            coefficients: vec![1.0, 0.0, 3.0, -1.0, 5.0, -3.0],
            eigenvalues: vec![2.0, 1.0],
        }
    }

    #[test]
    fn weights_are_the_solid_angle_measure() {
        let g = BrdfGrid { n_theta_i: 7, n_theta_o: 5, n_phi: 9 };
        let w = g.weights();
        assert_eq!(w.len(), g.cells());
        assert!((w.iter().sum::<f64>() - PI).abs() < 1e-12);
        // ∫∫ cos θi cos θo (over the folded measure) = ½ · ½ · π, to the midpoint rule's accuracy.
        let g = BrdfGrid { n_theta_i: 60, n_theta_o: 50, n_phi: 3 };
        let w = g.weights();
        let ci: f64 = (0..g.cells()).map(|c| w[c] * g.centre(c)[0].cos() * g.centre(c)[1].cos()).sum();
        assert!((ci - PI / 4.0).abs() < 5e-3, "{ci}");
    }

    #[test]
    fn angles_fold_the_azimuth_and_put_the_mirror_at_pi() {
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let mirror = Vec3::new(-0.6, 0.0, 0.8);
        let [ti, to, phi] = BrdfGrid::angles(mirror, wo).unwrap();
        assert!((ti - to).abs() < 1e-7 && (phi - PI).abs() < 1e-12);
        // Symmetric in ±azimuth, invariant under a common rotation about the normal.
        let a = BrdfGrid::angles(Vec3::new(0.3, 0.4, 0.5), wo).unwrap();
        let b = BrdfGrid::angles(Vec3::new(0.3, -0.4, 0.5), wo).unwrap();
        assert!((a[2] - b[2]).abs() < 1e-12);
        let rot = glam::Quat::from_rotation_z(1.1);
        let c = BrdfGrid::angles(rot * Vec3::new(0.3, 0.4, 0.5), rot * wo).unwrap();
        assert!((a[2] - c[2]).abs() < 1e-6);
        assert!(BrdfGrid::angles(Vec3::new(0.0, 0.0, -1.0), wo).is_none());
        assert!(BrdfGrid::angles(Vec3::Z, Vec3::new(1.0, 0.0, 0.0)).is_none(), "grazing ωo");
        // Unit directions built from the angles give them back.
        let (wi, wo) = BrdfGrid::directions(0.3, 1.2, 2.5);
        let back = BrdfGrid::angles(wi.as_vec3(), wo.as_vec3()).unwrap();
        assert!(back.iter().zip([0.3, 1.2, 2.5]).all(|(x, y)| (x - y).abs() < 1e-6), "{back:?}");
    }

    #[test]
    fn the_lookup_is_exact_at_centres_linear_between_and_flat_at_the_edges() {
        let b = basis();
        let g = b.grid;
        for cell in [0, 7, g.cells() - 1] {
            let t = g.trilinear_at(g.centre(cell));
            assert!((t.apply(b.table(1)) - b.table(1)[cell] as f64).abs() < 1e-6);
        }
        // Halfway between two φ centres: the mean of the two.
        let [ti, to, p0] = g.centre(g.index(1, 2, 1));
        let p1 = g.centre(g.index(1, 2, 2))[2];
        let mid = g.trilinear_at([ti, to, 0.5 * (p0 + p1)]).apply(b.table(2));
        let expect = 0.5 * (b.table(2)[g.index(1, 2, 1)] as f64 + b.table(2)[g.index(1, 2, 2)] as f64);
        assert!((mid - expect).abs() < 1e-6);
        // Past the last centre (toward φ = π, θ = π/2) and before the first: held.
        let last = g.centre(g.index(2, 3, 4));
        let edge = g.trilinear_at([FRAC_PI_2, FRAC_PI_2, PI]).apply(b.table(0));
        assert!((edge - g.trilinear_at(last).apply(b.table(0))).abs() < 1e-7);
        let first = g.trilinear_at([0.0, 0.0, 0.0]).apply(b.table(0));
        assert!((first - b.table(0)[0] as f64).abs() < 1e-7);
        // Weights sum to one everywhere, values are signed (never clamped).
        for k in 0..50 {
            let a = [k as f64 * 0.031, (k * 7 % 50) as f64 * 0.031, k as f64 * 0.062];
            let t = g.trilinear_at(a);
            assert!((t.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
        assert!(b.tables.iter().any(|v| *v < 0.0));
        let neg = (0..g.cells()).find(|&c| b.table(1)[c] < 0.0).unwrap();
        let [ti, to, phi] = g.centre(neg);
        let (wi, wo) = BrdfGrid::directions(ti, to, phi);
        assert!(b.eval(1, wi.as_vec3(), wo.as_vec3()) < 0.0, "negative lobes come back negative");
        assert_eq!(b.eval(1, -Vec3::Z, wo.as_vec3()), 0.0);
    }

    #[test]
    fn a_one_cell_axis_is_constant() {
        let g = BrdfGrid { n_theta_i: 1, n_theta_o: 1, n_phi: 1 };
        let t = g.trilinear_at([1.0, 0.2, 3.0]);
        assert_eq!(t.cells, [0; 8]);
        assert!((t.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn coefficients_interpolate_linearly_in_s_and_refuse_outside_the_range() {
        let b = basis();
        assert_eq!(b.specular_coefficients(1.0).unwrap(), vec![1.0, 0.0]);
        assert_eq!(b.specular_coefficients(4.0).unwrap(), vec![5.0, -3.0]);
        assert_eq!(b.specular_coefficients(1.5).unwrap(), vec![2.0, -0.5]);
        assert_eq!(b.specular_coefficients(3.0).unwrap(), vec![4.0, -2.0]);
        assert_eq!(b.project(0.3, 0.5, 2.0).unwrap(), vec![0.3, 1.5, -0.5]);
        assert_eq!(b.project(1.0, 0.0, 1e9).unwrap(), vec![1.0, 0.0, 0.0], "ks = 0 ignores s");
        let e = b.specular_coefficients(4.5).unwrap_err();
        assert!(e.contains("[1, 4]"), "{e}");
        assert!(b.specular_coefficients(f64::NAN).is_err());
        // Equal exponents (a rank-deficient sample set) take the first row.
        let mut flat = basis();
        flat.s_values = vec![2.0, 2.0, 2.0];
        assert_eq!(flat.specular_coefficients(2.0).unwrap(), vec![1.0, 0.0]);
    }

    #[test]
    fn encodings_round_trip_and_refuse_inconsistent_payloads() {
        let s = space();
        assert_eq!(BrdfSpace::decode(&s.encode()).unwrap(), s);
        assert_eq!(s.byte_size(), 2 * 60 * 4 + 2 * 20 + 32);
        let b = basis();
        assert_eq!(BrdfBasis::decode(&b.encode()).unwrap(), b);
        for bytes in [s.encode(), b.encode()] {
            for len in [0, 3, bytes.len() / 2, bytes.len() - 1] {
                assert!(BrdfSpace::decode(&bytes[..len]).is_none() && BrdfBasis::decode(&bytes[..len]).is_none(), "{len}");
            }
        }
        let mut short = space();
        short.values.pop();
        assert!(BrdfSpace::decode(&short.encode()).is_none(), "a value short");
        let mut zero = space();
        zero.grid.n_phi = 0;
        zero.values.clear();
        assert!(BrdfSpace::decode(&zero.encode()).is_none(), "an empty axis");
        let mut odd = basis();
        odd.coefficients.pop();
        assert!(BrdfBasis::decode(&odd.encode()).is_none(), "a coefficient short");
        let mut none = basis();
        none.tables.clear();
        none.coefficients.clear();
        none.eigenvalues.clear();
        none.s_values.clear();
        assert!(BrdfBasis::decode(&none.encode()).is_none(), "no diffuse table");
        let mut other = space();
        other.samples[1].s = 4.0;
        assert_ne!(other.fingerprint(), space().fingerprint(), "the sample list is part of the content");
    }
}
