//! Port types of pipeline 2's BRDF side ([S] 5.2.2, 5.3.1, 5.3.3.1): the sampled tensor
//! F(h, ωo, ωi) ([`BrdfTensorTable`]), the separated specular lobes ([`SpecularLobes`]) and the
//! Tucker-decomposed residual a renderer shades with ([`TuckerBrdf`]).
//!
//! **Directions** ([`DiskGrid`], [S] 5.3.3.1 after Wang et al.): the upper hemisphere of the
//! local frame (+z the normal) projected orthographically onto the unit disk. The square
//! [−1, 1]² is cut into n × n cells; a cell whose centre (x, y) lies strictly inside the disk is
//! a sample, with direction (x, y, √(1 − x² − y²)) and solid angle (2/n)² / cos θ (the cell's
//! area divided by the Jacobian cos θ of the projection dA = cos θ dω). Samples run in cell
//! order (row y, then x). The grid is symmetric under x → −x, y → −y and x ↔ y, so the mirror
//! direction of a sample, (−x, −y, z), and its turns by 90° about the normal are samples too.
//! Lookups ([`DiskGrid::bilinear`]) are bilinear in the orthographic (x, y) between the four
//! surrounding cell centres, over those that are samples (weights renormalised); where none
//! is, the nearest sample. Directions at or below the horizon have no lookup.
//!
//! **Materials** ([`BrdfFamily`]): the h axis. Blinn-Phong: exponents s_j (increasing), a
//! material's s maps linearly between the two neighbouring samples; Cook-Torrance: a grid over
//! Beckmann roughness m (outer index) × Schlick F0 (inner), h = i_m · N_F0 + i_F0, a material's
//! (m, F0) maps bilinearly on it. Either way the position is a [`Blend`] of up to four h rows.
//! Parameters outside the sampled range are refused (as `BrdfBasis` refuses s), with the range.
//!
//! **Lobes** ([`lobe_row`]): lobe k of width σ_k around the mirror direction m(ωo) is
//! g_σ(∠(ωi, m)) / cos θi, g_σ(θ) = exp(−θ²/2σ²) / Z(σ) for θ ≤ min(4σ, π) and 0 beyond, Z the
//! integral of the same over the sphere, so ∫_sphere g_σ dω = 1: the weights of
//! `CubeMap::gaussian_prefilter` with the same σ. A renderer therefore shades lobe k as
//! a_k × (environment prefiltered with σ_k) at m(ωo): ∫ L f_s cos θi dωi = Σ_k a_k L_σk(m).
//! σ = 0 is the discrete normalised delta: 1 / (Ω_j cos θ_j) at the sample j holding m(ωo).
//!
//! **Precision**: tables are f32 (rounding 2⁻²⁴, far below every decomposition error here);
//! the nodes compute in f64 and accessors sum in f64.

use glam::{DVec3, Vec3};
use relume_base::brdf::{blinn_phong, cook_torrance};
use relume_base::types::{Material, ObjectMaterial, Specular};
use relume_core::codec::pod_vec;
use relume_core::PortValue;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Largest tensor (F or its residual) a node may allocate: 2 GiB of f32 values.
pub const MAX_BRDF_TENSOR_BYTES: u64 = 2 << 30;
/// Most lobes a separation fits ([S] 5-13 uses four: 0°, 7°, 14°, 21°).
pub const MAX_LOBES: usize = 4;
/// Largest disk resolution (n × n cells).
pub const MAX_DISK: u32 = 256;

// ---- blends --------------------------------------------------------------------------------

/// Up to four table rows and their weights (summing to 1; unused slots have weight 0 and
/// index 0): a material's position on the h axis, or a direction's on the disk.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Blend {
    pub idx: [u32; 4],
    pub w: [f64; 4],
}

impl Blend {
    /// Row `i` alone.
    pub fn one(i: usize) -> Blend {
        Blend { idx: [i as u32, 0, 0, 0], w: [1.0, 0.0, 0.0, 0.0] }
    }

    /// Σ w · row(idx) of a table of rows of `width` entries, into f64.
    pub fn rows(&self, table: &[f32], width: usize) -> Vec<f64> {
        let mut out = vec![0.0; width];
        for (&i, &w) in self.idx.iter().zip(&self.w) {
            if w != 0.0 {
                let row = &table[i as usize * width..(i as usize + 1) * width];
                out.iter_mut().zip(row).for_each(|(o, &v)| *o += w * v as f64);
            }
        }
        out
    }
}

/// Where `v` falls on an increasing `axis`: (j, j + 1, t) with v = (1 − t) a_j + t a_{j+1}; an
/// error naming `what` and the range when v is outside [a_0, a_last] or not finite.
fn locate(axis: &[f64], v: f64, what: &str) -> Result<(usize, usize, f64), String> {
    let (Some(&lo), Some(&hi)) = (axis.first(), axis.last()) else { return Err("the family holds no samples".into()) };
    if !(v >= lo && v <= hi) {
        return Err(format!("{what} = {v} is outside the sampled range [{lo}, {hi}]"));
    }
    let j = axis.partition_point(|&a| a < v).max(1) - 1;
    let j1 = (j + 1).min(axis.len() - 1);
    let (a0, a1) = (axis[j], axis[j1]);
    let t = if a1 > a0 { ((v - a0) / (a1 - a0)).clamp(0.0, 1.0) } else { 0.0 };
    Ok((j, j1, t))
}

// ---- the disk ------------------------------------------------------------------------------

/// The hemisphere's sample directions through the unit disk (see the module comment). Encoded
/// as n alone; the tables are rebuilt on decoding.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(into = "u32", try_from = "u32")]
pub struct DiskGrid {
    n: u32,
    /// Per sample, its cell (iy · n + ix).
    cells: Vec<u32>,
    /// Per cell, its sample, or `u32::MAX` for a cell outside the disk.
    sample_of: Vec<u32>,
}

impl From<DiskGrid> for u32 {
    fn from(d: DiskGrid) -> u32 {
        d.n
    }
}

impl TryFrom<u32> for DiskGrid {
    type Error = String;
    fn try_from(n: u32) -> Result<DiskGrid, String> {
        if (1..=MAX_DISK).contains(&n) {
            Ok(DiskGrid::new(n))
        } else {
            Err(format!("a disk resolution of {n} is outside [1, {MAX_DISK}]"))
        }
    }
}

impl DiskGrid {
    /// The grid of n × n cells (n in 1 ..= `MAX_DISK`; panics otherwise).
    pub fn new(n: u32) -> DiskGrid {
        assert!((1..=MAX_DISK).contains(&n), "disk resolution {n}");
        let mut cells = Vec::new();
        let mut sample_of = vec![u32::MAX; (n * n) as usize];
        for c in 0..n * n {
            let [x, y] = Self::centre(n, c % n, c / n);
            if x * x + y * y < 1.0 {
                sample_of[c as usize] = cells.len() as u32;
                cells.push(c);
            }
        }
        DiskGrid { n, cells, sample_of }
    }

    /// The number of samples of an n × n grid, without building it (for memory estimates).
    pub fn count(n: u32) -> usize {
        (0..n * n)
            .filter(|c| {
                let [x, y] = Self::centre(n, c % n, c / n);
                x * x + y * y < 1.0
            })
            .count()
    }

    /// Cell (ix, iy)'s centre, (2i + 1 − n)/n: an integer over n, so that mirrored cells
    /// have exactly opposite coordinates.
    fn centre(n: u32, ix: u32, iy: u32) -> [f64; 2] {
        let c = |i: u32| (2.0 * i as f64 + 1.0 - n as f64) / n as f64;
        [c(ix), c(iy)]
    }

    /// Cells per side.
    pub fn n(&self) -> u32 {
        self.n
    }

    /// Number of sample directions.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// The orthographic (x, y) of sample `k`.
    pub fn xy(&self, k: usize) -> [f64; 2] {
        let c = self.cells[k];
        Self::centre(self.n, c % self.n, c / self.n)
    }

    /// The unit direction of sample `k`, (x, y, √(1 − x² − y²)).
    pub fn direction(&self, k: usize) -> DVec3 {
        let [x, y] = self.xy(k);
        DVec3::new(x, y, (1.0 - x * x - y * y).sqrt())
    }

    /// The solid angle sample `k` stands for: (2/n)² / cos θ.
    pub fn solid_angle(&self, k: usize) -> f64 {
        (2.0 / self.n as f64).powi(2) / self.direction(k).z
    }

    /// The sample of cell (ix, iy), if that cell is inside the disk.
    fn sample_at(&self, ix: u32, iy: u32) -> Option<usize> {
        let s = self.sample_of[(iy * self.n + ix) as usize];
        (s != u32::MAX).then_some(s as usize)
    }

    /// The sample (−x, −y): the mirror direction of sample `k` about the normal.
    pub fn mirror(&self, k: usize) -> usize {
        let c = self.cells[k];
        let (ix, iy) = (c % self.n, c / self.n);
        self.sample_at(self.n - 1 - ix, self.n - 1 - iy).expect("the grid is symmetric")
    }

    /// The orthographic coordinates of a direction (normalised first); `None` at or below the
    /// horizon or for a non-finite direction.
    fn project(w: Vec3) -> Option<[f64; 2]> {
        let w = w.as_dvec3().normalize_or_zero();
        (w.z > 0.0).then_some([w.x, w.y])
    }

    /// The sample whose cell holds `w`'s projection, or, for a point in a cell outside the
    /// disk, the sample nearest to it in (x, y) (first in sample order on ties).
    pub fn nearest(&self, w: Vec3) -> Option<usize> {
        let p = Self::project(w)?;
        let cell = |v: f64| (((v + 1.0) * 0.5 * self.n as f64).floor().max(0.0) as u32).min(self.n - 1);
        if let Some(s) = self.sample_at(cell(p[0]), cell(p[1])) {
            return Some(s);
        }
        let d2 = |k: usize| {
            let [x, y] = self.xy(k);
            (x - p[0]).powi(2) + (y - p[1]).powi(2)
        };
        (0..self.len()).min_by(|&a, &b| d2(a).total_cmp(&d2(b)))
    }

    /// Bilinear weights of `w` in (x, y) over the surrounding samples (see the module
    /// comment); `None` at or below the horizon.
    pub fn bilinear(&self, w: Vec3) -> Option<Blend> {
        let p = Self::project(w)?;
        let axis = |v: f64| {
            let u = ((v + 1.0) * 0.5 * self.n as f64 - 0.5).clamp(0.0, (self.n - 1) as f64);
            // u ≥ 0: the conversion is its floor.
            let i0 = (u as u32).min(self.n - 1);
            (i0, (i0 + 1).min(self.n - 1), u - i0 as f64)
        };
        let ((x0, x1, tx), (y0, y1, ty)) = (axis(p[0]), axis(p[1]));
        let corners = [(x0, y0, (1.0 - tx) * (1.0 - ty)), (x1, y0, tx * (1.0 - ty)), (x0, y1, (1.0 - tx) * ty), (x1, y1, tx * ty)];
        let mut b = Blend { idx: [0; 4], w: [0.0; 4] };
        let mut total = 0.0;
        for (slot, &(ix, iy, wt)) in corners.iter().enumerate() {
            if let Some(s) = self.sample_at(ix, iy) {
                if wt > 0.0 {
                    b.idx[slot] = s as u32;
                    b.w[slot] = wt;
                    total += wt;
                }
            }
        }
        if total <= 0.0 {
            return self.nearest(w).map(Blend::one);
        }
        b.w.iter_mut().for_each(|x| *x /= total);
        Some(b)
    }
}

// ---- the family (h axis) -------------------------------------------------------------------

/// A material's parameter on the h axis: the exponent s of Blinn-Phong, or Cook-Torrance's
/// Beckmann roughness m and Schlick F0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MaterialParam {
    BlinnPhong { s: f64 },
    CookTorrance { m: f64, f0: f64 },
}

impl MaterialParam {
    /// The parameter of a scene material (`None` for Lambert and dielectrics).
    pub fn of(m: &Material) -> Option<MaterialParam> {
        match *m {
            Material::BlinnPhong { exponent, .. } => Some(MaterialParam::BlinnPhong { s: exponent as f64 }),
            Material::CookTorrance { roughness, f0, .. } => Some(MaterialParam::CookTorrance { m: roughness as f64, f0: f0 as f64 }),
            _ => None,
        }
    }

    /// The parameter of a dynamic object's (edited) material.
    pub fn of_object(m: &ObjectMaterial) -> MaterialParam {
        match m.specular {
            Specular::BlinnPhong => MaterialParam::BlinnPhong { s: m.s as f64 },
            Specular::CookTorrance { m, f0 } => MaterialParam::CookTorrance { m: m as f64, f0: f0 as f64 },
        }
    }

    /// The model's name, for messages.
    pub fn model(&self) -> &'static str {
        match self {
            MaterialParam::BlinnPhong { .. } => "Blinn-Phong",
            MaterialParam::CookTorrance { .. } => "Cook-Torrance",
        }
    }
}

/// The BRDFs sampled along h (see the module comment), each with ks = 1 and no diffuse term.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum BrdfFamily {
    /// Exponents s_j, increasing.
    BlinnPhong { s: Vec<f64> },
    /// Roughness values (outer) × F0 values (inner), each increasing.
    CookTorrance { m: Vec<f64>, f0: Vec<f64> },
}

impl BrdfFamily {
    /// N_h.
    pub fn len(&self) -> usize {
        match self {
            BrdfFamily::BlinnPhong { s } => s.len(),
            BrdfFamily::CookTorrance { m, f0 } => m.len() * f0.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The model's name, for messages.
    pub fn model(&self) -> &'static str {
        match self {
            BrdfFamily::BlinnPhong { .. } => "Blinn-Phong",
            BrdfFamily::CookTorrance { .. } => "Cook-Torrance",
        }
    }

    /// Non-empty, finite and increasing axes.
    pub fn is_valid(&self) -> bool {
        let ok = |a: &[f64]| !a.is_empty() && a.iter().all(|v| v.is_finite()) && a.windows(2).all(|w| w[0] < w[1]);
        match self {
            BrdfFamily::BlinnPhong { s } => ok(s),
            BrdfFamily::CookTorrance { m, f0 } => ok(m) && ok(f0),
        }
    }

    /// The parameter of sample h.
    pub fn param(&self, h: usize) -> MaterialParam {
        match self {
            BrdfFamily::BlinnPhong { s } => MaterialParam::BlinnPhong { s: s[h] },
            BrdfFamily::CookTorrance { m, f0 } => MaterialParam::CookTorrance { m: m[h / f0.len()], f0: f0[h % f0.len()] },
        }
    }

    /// The specular part (ks = 1) of sample h at (ωo, ωi), by the library's `eval`.
    pub fn eval(&self, h: usize, wo: Vec3, wi: Vec3) -> f64 {
        match self.param(h) {
            MaterialParam::BlinnPhong { s } => blinn_phong::eval(Vec3::ZERO, Vec3::ONE, s as f32, wo, wi).x as f64,
            MaterialParam::CookTorrance { m, f0 } => cook_torrance::eval(Vec3::ZERO, Vec3::ONE, m as f32, f0 as f32, wo, wi).x as f64,
        }
    }

    /// A material's position on the h axis: linear in s between Blinn-Phong samples, bilinear
    /// on the Cook-Torrance (m, F0) grid. An error for the other model's parameter or one
    /// outside the sampled range.
    pub fn position(&self, p: MaterialParam) -> Result<Blend, String> {
        match (self, p) {
            (BrdfFamily::BlinnPhong { s }, MaterialParam::BlinnPhong { s: v }) => {
                let (j0, j1, t) = locate(s, v, "s")?;
                Ok(Blend { idx: [j0 as u32, j1 as u32, 0, 0], w: [1.0 - t, t, 0.0, 0.0] })
            }
            (BrdfFamily::CookTorrance { m, f0 }, MaterialParam::CookTorrance { m: mv, f0: fv }) => {
                let (a0, a1, ta) = locate(m, mv, "roughness m")?;
                let (b0, b1, tb) = locate(f0, fv, "F0")?;
                let h = |a: usize, b: usize| (a * f0.len() + b) as u32;
                Ok(Blend {
                    idx: [h(a0, b0), h(a0, b1), h(a1, b0), h(a1, b1)],
                    w: [(1.0 - ta) * (1.0 - tb), (1.0 - ta) * tb, ta * (1.0 - tb), ta * tb],
                })
            }
            _ => Err(format!("a {p:?} parameter does not address a {} family", self.model())),
        }
    }

    fn bytes(&self) -> usize {
        match self {
            BrdfFamily::BlinnPhong { s } => 8 * s.len(),
            BrdfFamily::CookTorrance { m, f0 } => 8 * (m.len() + f0.len()),
        }
    }
}

// ---- the tensor ----------------------------------------------------------------------------

/// F(h, ωo, ωi) ([S] 5.2.2): N_h × N_ω × N_ω f32 values, entry (h, o, i) at
/// (h · N_ω + o) · N_ω + i, N_ω = `disk.len()`; the specular part of each family member.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BrdfTensorTable {
    pub family: BrdfFamily,
    pub disk: DiskGrid,
    #[serde(with = "pod_vec")]
    pub values: Vec<f32>,
}

impl BrdfTensorTable {
    /// Bytes of a table of `n_h` members over `n_dirs` directions (for refusing before
    /// allocating).
    pub fn bytes_for(n_h: u64, n_dirs: u64) -> u64 {
        n_h.saturating_mul(n_dirs).saturating_mul(n_dirs).saturating_mul(4).saturating_add(n_h * 8 + 64)
    }

    /// [N_h, N_ωo, N_ωi].
    pub fn dims(&self) -> [usize; 3] {
        [self.family.len(), self.disk.len(), self.disk.len()]
    }

    pub fn at(&self, h: usize, o: usize, i: usize) -> f32 {
        let n = self.disk.len();
        self.values[(h * n + o) * n + i]
    }

    /// The ωi row of (h, o).
    pub fn row(&self, h: usize, o: usize) -> &[f32] {
        let n = self.disk.len();
        &self.values[(h * n + o) * n..(h * n + o + 1) * n]
    }

    fn consistent(&self) -> bool {
        let [a, b, c] = self.dims();
        self.family.is_valid() && a as u64 * b as u64 * c as u64 == self.values.len() as u64
    }
}

/// Disk encoding: serde through postcard, the values as a little-endian byte string; decoding
/// checks the family and one value per entry.
impl PortValue for BrdfTensorTable {
    const NAME: &'static str = "BrdfTensorTable";
    const COLOR: [u8; 3] = [230, 150, 90];
    const DOC: &'static str = "a BRDF family sampled as F(h, ωo, ωi) over the disk-projected hemisphere";
    fn byte_size(&self) -> usize {
        self.values.len() * 4 + self.family.bytes() + 64
    }
    relume_core::serde_codec!(check BrdfTensorTable::consistent);
}

// ---- lobes ---------------------------------------------------------------------------------

/// Z(σ) = ∫_sphere exp(−θ²/2σ²) dω over θ ≤ min(4σ, π), the cut-off of
/// `CubeMap::gaussian_prefilter` (Simpson's rule in θ, 4096 intervals).
pub fn gaussian_norm(sigma: f64) -> f64 {
    let reach = (4.0 * sigma).min(PI);
    let n = 4096;
    let d = reach / n as f64;
    let f = |t: f64| (-(t * t) / (2.0 * sigma * sigma)).exp() * t.sin();
    let inner: f64 = (1..n).map(|k| f(k as f64 * d) * if k % 2 == 1 { 4.0 } else { 2.0 }).sum();
    2.0 * PI * d / 3.0 * (f(0.0) + inner + f(reach))
}

/// Lobe σ (radians) of direction sample `o` over every ωi sample: g_σ(∠(ωi, m(ωo))) / cos θi,
/// or for σ = 0 the discrete delta 1 / (Ω_m cos θ_m) at m(ωo)'s sample (module comment).
pub fn lobe_row(disk: &DiskGrid, sigma: f64, o: usize) -> Vec<f64> {
    let m = disk.mirror(o);
    let mut row = vec![0.0; disk.len()];
    if sigma <= 0.0 {
        row[m] = 1.0 / (disk.solid_angle(m) * disk.direction(m).z);
        return row;
    }
    let (dm, z, reach) = (disk.direction(m), gaussian_norm(sigma), (4.0 * sigma).min(PI));
    for (i, r) in row.iter_mut().enumerate() {
        let d = disk.direction(i);
        let theta = dm.dot(d).clamp(-1.0, 1.0).acos();
        if theta <= reach {
            *r = (-(theta * theta) / (2.0 * sigma * sigma)).exp() / z / d.z;
        }
    }
    row
}

/// The specular lobes separated from a tensor ([S] 5-12, 5-13): widths σ_k (radians,
/// increasing) and amplitudes a_k ≥ 0 per (h, ωo) sample, N_h × N_ω × K f32 values, entry
/// (h, o, k) at (h · N_ω + o) · K + k. f_s(h, ωo, ωi) = Σ_k a_k lobe_k (`lobe_row`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpecularLobes {
    pub family: BrdfFamily,
    pub disk: DiskGrid,
    pub sigmas: Vec<f64>,
    #[serde(with = "pod_vec")]
    pub amplitudes: Vec<f32>,
}

impl SpecularLobes {
    /// K.
    pub fn lobes(&self) -> usize {
        self.sigmas.len()
    }

    /// a_k at sample (h, o).
    pub fn amplitude(&self, h: usize, o: usize, k: usize) -> f32 {
        self.amplitudes[(h * self.disk.len() + o) * self.lobes() + k]
    }

    /// a_k(h, ωo) for a material position `h` (`family.position`) and a local ωo, bilinear
    /// over the disk; slots past `lobes()` and directions below the horizon give 0.
    pub fn amplitudes(&self, h: &Blend, wo: Vec3) -> [f32; MAX_LOBES] {
        let mut out = [0.0f32; MAX_LOBES];
        let (Some(o), k) = (self.disk.bilinear(wo), self.lobes()) else { return out };
        let mut acc = [0.0f64; MAX_LOBES];
        for (&hi, &hw) in h.idx.iter().zip(&h.w) {
            for (&oi, &ow) in o.idx.iter().zip(&o.w) {
                if hw * ow != 0.0 {
                    for (l, a) in acc.iter_mut().enumerate().take(k) {
                        *a += hw * ow * self.amplitude(hi as usize, oi as usize, l) as f64;
                    }
                }
            }
        }
        out.iter_mut().zip(acc).for_each(|(o, a)| *o = a as f32);
        out
    }

    /// Per disk sample o, the amplitudes a_k(h, o) of a material at `h` (K entries a row,
    /// blended over h in f64): what `amplitudes` blends over the disk, for a shader that
    /// reads one material at many directions.
    pub fn table_at(&self, h: &Blend) -> Vec<f32> {
        let k = self.lobes();
        let mut out = Vec::with_capacity(self.disk.len() * k);
        for o in 0..self.disk.len() {
            for l in 0..k {
                let a: f64 = h
                    .idx
                    .iter()
                    .zip(&h.w)
                    .filter(|(_, w)| **w != 0.0)
                    .map(|(&hi, &hw)| hw * self.amplitude(hi as usize, o, l) as f64)
                    .sum();
                out.push(a as f32);
            }
        }
        out
    }

    /// f_s over the ωi row of sample (h, o), from the stored amplitudes, in f64.
    pub fn row(&self, h: usize, o: usize) -> Vec<f64> {
        let mut row = vec![0.0; self.disk.len()];
        for (k, &s) in self.sigmas.iter().enumerate() {
            let a = self.amplitude(h, o, k) as f64;
            if a != 0.0 {
                row.iter_mut().zip(lobe_row(&self.disk, s, o)).for_each(|(r, l)| *r += a * l);
            }
        }
        row
    }
}

impl SpecularLobes {
    /// Whether the family is valid, the lobe widths finite and few enough, and the amplitudes
    /// fill the table (what a decoded payload must satisfy).
    pub fn is_consistent(&self) -> bool {
        self.family.is_valid()
            && self.sigmas.len() <= MAX_LOBES
            && self.sigmas.iter().all(|s| s.is_finite() && *s >= 0.0)
            && (self.family.len() * self.disk.len() * self.lobes()) as u64 == self.amplitudes.len() as u64
    }
}

/// Disk encoding: serde through postcard; decoding checks the family, at most `MAX_LOBES`
/// finite widths and K amplitudes per (h, ωo).
impl PortValue for SpecularLobes {
    const NAME: &'static str = "SpecularLobes";
    const COLOR: [u8; 3] = [250, 210, 110];
    const DOC: &'static str = "Gaussian specular lobes around the mirror direction, amplitudes per (h, ωo)";
    fn byte_size(&self) -> usize {
        self.amplitudes.len() * 4 + self.sigmas.len() * 8 + self.family.bytes() + 64
    }
    relume_core::serde_codec!(check SpecularLobes::is_consistent);
}

// ---- the decomposition ---------------------------------------------------------------------

/// A Tucker-decomposed BRDF tensor ([S] 5-3, 5-4): core D (n_h × n_ωo × n_ωi, entry (a, b, c)
/// at (a · n_ωo + b) · n_ωi + c) and row-major factors U^h (N_h × n_h), U^ωo (N_ω × n_ωo),
/// U^ωi (N_ω × n_ωi), f32, with the family and the directions they index. f(h, ωo, ωi) ≈
/// Σ D(a, b, c) U^h(h, a) U^ωo(ωo, b) U^ωi(ωi, c).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TuckerBrdf {
    pub family: BrdfFamily,
    pub disk: DiskGrid,
    /// [n_h, n_ωo, n_ωi] (each at most the numerical rank of its mode; 0 for a zero tensor).
    pub ranks: [u32; 3],
    #[serde(with = "pod_vec")]
    pub core: Vec<f32>,
    #[serde(with = "pod_vec")]
    pub factor_h: Vec<f32>,
    #[serde(with = "pod_vec")]
    pub factor_o: Vec<f32>,
    #[serde(with = "pod_vec")]
    pub factor_i: Vec<f32>,
}

impl TuckerBrdf {
    fn rank(&self, n: usize) -> usize {
        self.ranks[n] as usize
    }

    /// U^h's row for a material (interpolated as `BrdfFamily::position`), n_h entries.
    pub fn u_h(&self, p: MaterialParam) -> Result<Vec<f32>, String> {
        Ok(self.u_h_at(&self.family.position(p)?))
    }

    /// U^h's rows blended at `h`.
    pub fn u_h_at(&self, h: &Blend) -> Vec<f32> {
        h.rows(&self.factor_h, self.rank(0)).into_iter().map(|v| v as f32).collect()
    }

    fn u_dir(&self, table: &[f32], r: usize, w: Vec3) -> Vec<f32> {
        match self.disk.bilinear(w) {
            Some(b) => b.rows(table, r).into_iter().map(|v| v as f32).collect(),
            None => vec![0.0; r],
        }
    }

    /// U^ωo's row at a local ωo (bilinear over the disk; zeros below the horizon), n_ωo entries.
    pub fn u_o(&self, wo: Vec3) -> Vec<f32> {
        self.u_dir(&self.factor_o, self.rank(1), wo)
    }

    /// Per disk sample o, the row U^ωo(o) · M of a core matrix `m` from `core_for` (n_ωi
    /// entries a row, summed in f64): u_o · M · u_i is then this table blended over the disk
    /// at ωo, dotted with u_i, for a shader that reads one material at many directions.
    pub fn view_table(&self, m: &[f32]) -> Vec<f32> {
        let (r, ni) = (self.rank(1), self.rank(2));
        let mut out = Vec::with_capacity(self.disk.len() * ni);
        for o in 0..self.disk.len() {
            let u = &self.factor_o[o * r..(o + 1) * r];
            for c in 0..ni {
                out.push(u.iter().enumerate().map(|(b, &x)| x as f64 * m[b * ni + c] as f64).sum::<f64>() as f32);
            }
        }
        out
    }

    /// U^ωi's row at a local ωi (bilinear over the disk; zeros below the horizon), n_ωi entries.
    pub fn u_i(&self, wi: Vec3) -> Vec<f32> {
        self.u_dir(&self.factor_i, self.rank(2), wi)
    }

    /// D ×_h u_h: the n_ωo × n_ωi matrix (row-major) of one material.
    pub fn core_for(&self, u_h: &[f32]) -> Vec<f32> {
        let m = self.rank(1) * self.rank(2);
        let mut out = vec![0.0f64; m];
        for (a, &u) in u_h.iter().enumerate().take(self.rank(0)) {
            out.iter_mut().zip(&self.core[a * m..(a + 1) * m]).for_each(|(o, &d)| *o += u as f64 * d as f64);
        }
        out.into_iter().map(|v| v as f32).collect()
    }

    /// u_o · M · u_i for a core matrix `m` from `core_for`.
    pub fn contract(&self, m: &[f32], u_o: &[f32], u_i: &[f32]) -> f64 {
        let ni = self.rank(2);
        u_o.iter().enumerate().map(|(b, &uo)| uo as f64 * (0..ni).map(|c| m[b * ni + c] as f64 * u_i[c] as f64).sum::<f64>()).sum()
    }

    /// The reconstructed f_r of a material at local (ωo, ωi); 0 below the horizon.
    pub fn eval(&self, p: MaterialParam, wo: Vec3, wi: Vec3) -> Result<f32, String> {
        let m = self.core_for(&self.u_h(p)?);
        Ok(self.contract(&m, &self.u_o(wo), &self.u_i(wi)) as f32)
    }

    /// The reconstruction at tensor entry (h, o, i), in f64.
    pub fn at(&self, h: usize, o: usize, i: usize) -> f64 {
        let [rh, ro, ri] = [self.rank(0), self.rank(1), self.rank(2)];
        let mut sum = 0.0;
        for a in 0..rh {
            let ua = self.factor_h[h * rh + a] as f64;
            for b in 0..ro {
                let ub = ua * self.factor_o[o * ro + b] as f64;
                let core = &self.core[(a * ro + b) * ri..(a * ro + b + 1) * ri];
                sum += ub * core.iter().zip(&self.factor_i[i * ri..(i + 1) * ri]).map(|(&d, &u)| d as f64 * u as f64).sum::<f64>();
            }
        }
        sum
    }
}

impl TuckerBrdf {
    /// Whether the core and the three factors have the sizes the ranks, the family and the
    /// disk give (what a decoded payload must satisfy).
    pub fn is_consistent(&self) -> bool {
        let [a, b, c] = self.ranks.map(|r| r as usize);
        self.family.is_valid()
            && self.core.len() == a * b * c
            && self.factor_h.len() == self.family.len() * a
            && self.factor_o.len() == self.disk.len() * b
            && self.factor_i.len() == self.disk.len() * c
    }
}

/// Disk encoding: serde through postcard; decoding checks the family and every table's size
/// against the ranks.
impl PortValue for TuckerBrdf {
    const NAME: &'static str = "TuckerBrdf";
    const COLOR: [u8; 3] = [240, 120, 70];
    const DOC: &'static str = "a Tucker-decomposed BRDF tensor: core and the h, ωo, ωi factors";
    fn byte_size(&self) -> usize {
        (self.core.len() + self.factor_h.len() + self.factor_o.len() + self.factor_i.len()) * 4 + self.family.bytes() + 64
    }
    relume_core::serde_codec!(check TuckerBrdf::is_consistent);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disk_solid_angles_cover_the_hemisphere() {
        // Σ (2/n)² / cos θ → 2π, slowly and not monotonically: a rim cell whose centre is
        // just inside the disk weighs (2/n)²/cos θ with cos θ small. Measured: n = 8 −9.1 %,
        // 16 +4.9 %, 32 +0.35 %, 64 +2.5 %, 128 +0.55 %, 256 −0.16 %.
        for (n, tol) in [(8u32, 0.1), (16, 0.05), (32, 0.005), (64, 0.03), (128, 0.006), (256, 0.002)] {
            let d = DiskGrid::new(n);
            let total: f64 = (0..d.len()).map(|k| d.solid_angle(k)).sum();
            assert!((total / (2.0 * PI) - 1.0).abs() < tol, "n {n}: {total}");
            assert_eq!(d.len(), DiskGrid::count(n));
        }
        assert_eq!(DiskGrid::new(16).len(), 208);
        assert_eq!(DiskGrid::new(1).len(), 1);
        assert!((DiskGrid::new(1).direction(0) - DVec3::Z).length() < 1e-15);
    }

    #[test]
    fn the_disk_is_symmetric_and_lookups_are_exact_at_centres() {
        let d = DiskGrid::new(10);
        for k in 0..d.len() {
            let m = d.mirror(k);
            let (a, b) = (d.direction(k), d.direction(m));
            assert!(a.x == -b.x && a.y == -b.y && a.z == b.z, "{a} {b}");
            let w = a.as_vec3();
            assert_eq!(d.nearest(w), Some(k));
            let bl = d.bilinear(w).unwrap();
            let got: f64 = bl.idx.iter().zip(&bl.w).filter(|(&i, _)| i as usize == k).map(|(_, w)| w).sum();
            assert!((got - 1.0).abs() < 1e-6, "sample {k}: {bl:?}");
        }
        assert!(d.bilinear(Vec3::new(0.3, 0.2, -0.1)).is_none() && d.nearest(-Vec3::Z).is_none());
        // Grazing directions land on a rim sample; weights sum to one everywhere.
        for a in 0..64 {
            let phi = a as f32 * 0.1;
            let w = Vec3::new(phi.cos(), phi.sin(), 1e-4);
            let b = d.bilinear(w).unwrap();
            assert!((b.w.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn families_locate_parameters_and_refuse_outside_their_range() {
        let bp = BrdfFamily::BlinnPhong { s: vec![1.0, 2.0, 4.0] };
        let b = bp.position(MaterialParam::BlinnPhong { s: 3.0 }).unwrap();
        assert_eq!((b.idx[0], b.idx[1], b.w[0], b.w[1]), (1, 2, 0.5, 0.5));
        assert_eq!(bp.position(MaterialParam::BlinnPhong { s: 4.0 }).unwrap().rows(&[0.0, 1.0, 7.0], 1), vec![7.0]);
        let e = bp.position(MaterialParam::BlinnPhong { s: 5.0 }).unwrap_err();
        assert!(e.contains("[1, 4]"), "{e}");
        assert!(bp.position(MaterialParam::CookTorrance { m: 0.1, f0: 0.5 }).is_err());
        let ct = BrdfFamily::CookTorrance { m: vec![0.1, 0.2], f0: vec![0.0, 0.5, 1.0] };
        assert_eq!(ct.len(), 6);
        assert_eq!(ct.param(4), MaterialParam::CookTorrance { m: 0.2, f0: 0.5 });
        let table: Vec<f32> = (0..6).map(|h| h as f32).collect();
        let b = ct.position(MaterialParam::CookTorrance { m: 0.15, f0: 0.75 }).unwrap();
        assert!((b.rows(&table, 1)[0] - 3.0).abs() < 1e-12, "bilinear: mean of 1, 2, 4, 5");
        assert!(ct.position(MaterialParam::CookTorrance { m: 0.3, f0: 0.5 }).unwrap_err().contains("roughness"));
    }

    #[test]
    fn gaussian_lobes_are_normalised_like_the_cube_map_prefilter() {
        // ∫ g_σ dω = 1 over the sphere, and on the disk's upper hemisphere for a lobe at the
        // normal: Σ_i lobe(i) cos θi Ω_i ≈ 1 (the disk's quadrature error).
        let d = DiskGrid::new(64);
        let centre = (0..d.len()).min_by(|&a, &b| d.direction(b).z.total_cmp(&d.direction(a).z)).unwrap();
        for deg in [0.0f64, 7.0, 14.0, 21.0] {
            let row = lobe_row(&d, deg.to_radians(), centre);
            let mass: f64 = row.iter().enumerate().map(|(i, r)| r * d.direction(i).z * d.solid_angle(i)).sum();
            assert!((mass - 1.0).abs() < 0.02, "{deg}°: {mass}");
        }
        // Z(σ) → 2πσ² for small σ.
        let s = 0.02;
        assert!((gaussian_norm(s) / (2.0 * PI * s * s) - 1.0).abs() < 1e-3);
    }

    #[test]
    fn the_per_material_tables_blended_at_a_view_give_the_tensor_and_the_lobes_there() {
        // What a shader of one material reads at many views: U^ωo · M and the lobes'
        // amplitudes per disk sample, blended at ωo, against the contraction and `amplitudes`.
        for (brdf, lobes) in [crate::brdf_factors::test_support::small_brdf(), crate::brdf_factors::test_support::small_ct_brdf()] {
            let h = brdf.family.position(brdf.family.param(1)).unwrap();
            let m = brdf.core_for(&brdf.u_h_at(&h));
            let (view, amps, k) = (brdf.view_table(&m), lobes.table_at(&h), lobes.lobes());
            let ni = brdf.ranks[2] as usize;
            for wo in [Vec3::new(0.3, -0.2, 0.9), Vec3::new(-0.7, 0.1, 0.2), Vec3::Z, Vec3::new(0.05, 0.99, 0.02)] {
                let b = brdf.disk.bilinear(wo).unwrap();
                let blend = |table: &[f32], width: usize, j: usize| -> f64 {
                    b.idx.iter().zip(&b.w).map(|(&o, &w)| w * table[o as usize * width + j] as f64).sum()
                };
                for wi in [Vec3::new(0.1, 0.4, 0.8), Vec3::new(-0.5, -0.5, 0.3)] {
                    let u_i = brdf.u_i(wi);
                    let got: f64 = (0..ni).map(|c| blend(&view, ni, c) * u_i[c] as f64).sum();
                    let want = brdf.contract(&m, &brdf.u_o(wo), &u_i);
                    assert!((got - want).abs() <= 1e-5 * want.abs().max(1e-3), "{wo} {wi}: {got} against {want}");
                }
                let a = lobes.amplitudes(&h, wo);
                for (l, &want) in a.iter().enumerate().take(k) {
                    let got = blend(&amps, k, l);
                    assert!((got - want as f64).abs() <= 1e-5 * (want as f64).abs().max(1e-3), "{wo} lobe {l}: {got} against {want}");
                }
            }
            // Below the horizon there is nothing to blend.
            assert!(brdf.disk.bilinear(-Vec3::Z).is_none());
        }
    }
}
