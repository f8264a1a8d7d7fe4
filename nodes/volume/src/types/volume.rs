//! `Volume`: a dense voxel grid over an axis-aligned box (pipeline 3, [S] chapter 6), one or
//! more f32 channels per voxel (1: a scalar field such as the refractive index n; 3: RGB
//! radiance). Voxel (x, y, z) covers `min + voxel · [x, x+1] × …`; values sit at voxel centres
//! and are read trilinearly between them (clamped at the faces).

use glam::{UVec3, Vec3, Vec4};
use relume_core::codec::pod_vec;
use relume_core::memory::fmt_bytes;
use relume_core::{NodeError, PortValue};
use serde::{Deserialize, Serialize};

/// Largest volume any node may hold (a 1024³ scalar grid is 4 GiB).
pub const MAX_VOLUME_BYTES: u64 = 8 << 30;

/// Trilinear lookups into a volume with the world-to-grid map worked out once: a lookup
/// multiplies where `Volume::to_grid` divides (the marchers' inner loops; results may differ
/// from `Volume::sample_n` in the last bit).
#[derive(Clone, Copy, Debug)]
pub struct Sampler<'a> {
    pub volume: &'a Volume,
    /// Voxels per world unit along each axis.
    pub scale: Vec3,
    top: Vec3,
}

impl<'a> Sampler<'a> {
    pub fn new(volume: &'a Volume) -> Self {
        let dims = UVec3::from(volume.dims).as_vec3();
        Sampler { volume, scale: dims / (volume.max - volume.min), top: (dims - 1.0).max(Vec3::ZERO) }
    }

    /// `p` in voxel units (voxel (x, y, z) spans [x, x + 1] × …).
    #[inline]
    pub fn to_grid(&self, p: Vec3) -> Vec3 {
        (p - self.volume.min) * self.scale
    }

    /// Channels `c .. c + N` at `p`, trilinear between voxel centres, clamped at the faces.
    #[inline]
    pub fn sample_n<const N: usize>(&self, p: Vec3, c: usize) -> [f32; N] {
        self.volume.trilinear(self.to_grid(p) - 0.5, self.top, c)
    }

    /// Channels `c .. c + 4` at `p`, the same numbers as `sample_n::<4>` (the same lerps, four
    /// channels at once, one bounds check a corner).
    #[inline]
    pub fn sample4(&self, p: Vec3, c: usize) -> Vec4 {
        let v = self.volume;
        let (b, [sx, sy, sz], f) = v.cell(self.to_grid(p) - 0.5, self.top, c);
        let at = |off: usize| Vec4::from_slice(&v.data[b + off..b + off + 4]);
        let lerp = |a: Vec4, b: Vec4, t: f32| a + (b - a) * t;
        let p0 = lerp(lerp(at(0), at(sx), f.x), lerp(at(sy), at(sy + sx), f.x), f.y);
        let p1 = lerp(lerp(at(sz), at(sz + sx), f.x), lerp(at(sz + sy), at(sz + sy + sx), f.x), f.y);
        lerp(p0, p1, f.z)
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Volume {
    pub dims: [u32; 3],
    pub channels: u32,
    pub min: Vec3,
    pub max: Vec3,
    /// x fastest, then y, then z; the channels of a voxel together.
    #[serde(with = "pod_vec")]
    pub data: Vec<f32>,
    /// Facts derived from the voxels (an octree's clearance bricks, whether a medium absorbs),
    /// made on first use and shared by every node reading this value; a volume is not changed
    /// once a node has read it, and a clone starts without them.
    #[serde(skip)]
    pub derived: super::Derived,
}

impl Volume {
    /// Bytes of a `dims` grid of `channels` f32 (saturating: a request never overflows).
    pub fn bytes_for(dims: [u32; 3], channels: u32) -> u64 {
        dims.iter().fold(channels as u64 * 4, |b, &d| b.saturating_mul(d as u64))
    }

    /// A grid of `value` everywhere; refuses, before allocating, an empty or degenerate box,
    /// zero sizes, and more bytes than `budget` or `MAX_VOLUME_BYTES`, with the estimate.
    pub fn try_new(dims: [u32; 3], channels: u32, min: Vec3, max: Vec3, value: f32, budget: u64) -> Result<Volume, NodeError> {
        if dims.contains(&0) || channels == 0 {
            return Err(NodeError::failed(format!("a volume needs at least one voxel and one channel, not {dims:?} × {channels}")));
        }
        if !(min.is_finite() && max.is_finite() && min.cmplt(max).all()) {
            return Err(NodeError::failed(format!("a volume's box must be finite and non-empty, not {min} … {max}")));
        }
        let bytes = Volume::bytes_for(dims, channels);
        let limit = budget.min(MAX_VOLUME_BYTES);
        if bytes > limit {
            return Err(NodeError::OverLimit {
                param: None,
                msg: format!(
                    "a {} × {} × {} volume of {channels} channel(s) would hold {}, over the {} limit: lower the resolution",
                    dims[0],
                    dims[1],
                    dims[2],
                    fmt_bytes(bytes),
                    fmt_bytes(limit)
                ),
            });
        }
        Ok(Volume { dims, channels, min, max, data: vec![value; (bytes / 4) as usize], derived: Default::default() })
    }

    /// Whether channel 1 (the extinction κ of a medium) is positive anywhere; worked out once
    /// per value, for every node that reads it.
    pub fn absorbs(&self) -> bool {
        use rayon::prelude::*;
        *self.derived.get("absorbs", || self.channels > 1 && self.data.par_chunks(self.channels as usize).any(|c| c[1] > 0.0))
    }

    /// How many voxels have a positive channel 2 (the scattering σ of a medium); worked out once
    /// per value.
    pub fn scatterers(&self) -> usize {
        use rayon::prelude::*;
        let ch = self.channels as usize;
        *self.derived.get("scatterers", || if ch > 2 { self.data.par_chunks(ch).filter(|c| c[2] > 0.0).count() } else { 0 })
    }

    pub fn voxels(&self) -> usize {
        self.dims.iter().map(|&d| d as usize).product()
    }

    /// The size of one voxel along each axis.
    pub fn voxel(&self) -> Vec3 {
        (self.max - self.min) / UVec3::from(self.dims).as_vec3()
    }

    /// The index of voxel (x, y, z)'s first channel.
    #[inline]
    pub fn index(&self, x: usize, y: usize, z: usize) -> usize {
        ((z * self.dims[1] as usize + y) * self.dims[0] as usize + x) * self.channels as usize
    }

    #[inline]
    pub fn get(&self, x: usize, y: usize, z: usize, c: usize) -> f32 {
        self.data[self.index(x, y, z) + c]
    }

    /// The centre of voxel (x, y, z) in world space.
    pub fn centre(&self, x: usize, y: usize, z: usize) -> Vec3 {
        self.min + (Vec3::new(x as f32, y as f32, z as f32) + 0.5) * self.voxel()
    }

    /// `p` in voxel units (voxel centres at integers + 0.5).
    pub fn to_grid(&self, p: Vec3) -> Vec3 {
        (p - self.min) / self.voxel()
    }

    /// Whether `p` lies in the box.
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// Channel `c` at `p`, trilinear between voxel centres, clamped to the outermost centres.
    pub fn sample(&self, p: Vec3, c: usize) -> f32 {
        self.sample_n::<1>(p, c)[0]
    }

    /// Channels `c .. c + N` at `p`, trilinear as `sample` (one index computation for all).
    pub fn sample_n<const N: usize>(&self, p: Vec3, c: usize) -> [f32; N] {
        let d = UVec3::from(self.dims).as_vec3() - 1.0;
        self.trilinear(self.to_grid(p) - 0.5, d.max(Vec3::ZERO), c)
    }

    /// The trilinear cell of grid point `g` (voxel centres at integers), clamped to [0, `top`]
    /// (the largest voxel index per axis; a point that is not finite reads voxel 0): the index
    /// of channel `c` of its first corner, the offsets to the next corner along x, y and z (0
    /// on the last voxel), and `g`'s fractions inside the cell.
    #[inline]
    fn cell(&self, g: Vec3, top: Vec3, c: usize) -> (usize, [usize; 3], Vec3) {
        let g = g.clamp(Vec3::ZERO, top);
        let g = if g.is_finite() { g } else { Vec3::ZERO };
        // g ≥ 0: truncation is the floor (and no call into libm where the target lacks a
        // rounding instruction).
        let (x0, y0, z0) = (g.x as usize, g.y as usize, g.z as usize);
        let i = Vec3::new(x0 as f32, y0 as f32, z0 as f32);
        let step = |v: usize, axis: usize, s: usize| if v + 1 < self.dims[axis] as usize { s } else { 0 };
        let ch = self.channels as usize;
        let sx = step(x0, 0, ch);
        let sy = step(y0, 1, self.dims[0] as usize * ch);
        let sz = step(z0, 2, (self.dims[0] * self.dims[1]) as usize * ch);
        (self.index(x0, y0, z0) + c, [sx, sy, sz], g - i)
    }

    /// Channels `c .. c + N` at grid point `g` (voxel centres at integers), clamped to
    /// [0, `top`] (the largest voxel index per axis).
    #[inline]
    fn trilinear<const N: usize>(&self, g: Vec3, top: Vec3, c: usize) -> [f32; N] {
        let (b, [sx, sy, sz], f) = self.cell(g, top, c);
        let mut out = [0.0; N];
        for (k, o) in out.iter_mut().enumerate() {
            let at = |off: usize| self.data[b + off + k];
            let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
            let p0 = lerp(lerp(at(0), at(sx), f.x), lerp(at(sy), at(sy + sx), f.x), f.y);
            let p1 = lerp(lerp(at(sz), at(sz + sx), f.x), lerp(at(sz + sy), at(sz + sy + sx), f.x), f.y);
            *o = lerp(p0, p1, f.z);
        }
        out
    }

    /// The gradient of channel `c` at `p` in world units: central differences of `sample`
    /// one voxel apart along each axis (exact on linear fields away from the faces).
    pub fn gradient(&self, p: Vec3, c: usize) -> Vec3 {
        let h = self.voxel();
        let d = |e: Vec3, h: f32| (self.sample(p + e * h, c) - self.sample(p - e * h, c)) / (2.0 * h);
        Vec3::new(d(Vec3::X, h.x), d(Vec3::Y, h.y), d(Vec3::Z, h.z))
    }

    fn is_consistent(&self) -> bool {
        let n = self.dims.iter().try_fold(self.channels as usize, |a, &d| a.checked_mul(d as usize));
        n == Some(self.data.len())
            && self.channels > 0
            && !self.dims.contains(&0)
            && self.min.is_finite()
            && self.max.is_finite()
            && self.min.cmplt(self.max).all()
    }
}

/// Disk encoding: serde through postcard, the voxels as a little-endian byte string; decoding
/// checks the sizes and the box.
impl PortValue for Volume {
    const NAME: &'static str = "Volume";
    const COLOR: [u8; 3] = [110, 160, 230];
    const DOC: &'static str = "a dense voxel grid over a box (refractive index, extinction, radiance), trilinearly sampled";
    fn byte_size(&self) -> usize {
        self.data.len() * 4 + 64
    }
    relume_core::serde_codec!(check Volume::is_consistent, own fingerprint);
    /// The header and the floats' bytes where they lie: no copy of the encoding (64 MiB for
    /// an octree at 128³, the largest part of its time in the engine after its own work).
    fn fingerprint(&self) -> relume_core::Hash {
        let mut h = relume_core::Hasher::new();
        h.str(Self::NAME);
        self.dims.iter().for_each(|&d| {
            h.u64(d as u64);
        });
        h.u64(self.channels as u64).f32s(&self.min.to_array()).f32s(&self.max.to_array());
        h.bytes(bytemuck::cast_slice(&self.data)).finish()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 6 × 5 × 4 grid over [−1, 2] × [0, 1] × [0, 4] holding the linear field
    /// 2x − y + 0.5z + 1 at voxel centres.
    fn linear() -> Volume {
        let mut v = Volume::try_new([6, 5, 4], 1, Vec3::new(-1.0, 0.0, 0.0), Vec3::new(2.0, 1.0, 4.0), 0.0, u64::MAX).unwrap();
        for z in 0..4 {
            for y in 0..5 {
                for x in 0..6 {
                    let p = v.centre(x, y, z);
                    let i = v.index(x, y, z);
                    v.data[i] = 2.0 * p.x - p.y + 0.5 * p.z + 1.0;
                }
            }
        }
        v
    }

    #[test]
    fn four_channels_at_once_are_the_same_numbers_as_one_at_a_time() {
        // A 5 × 4 × 3 grid of 6 channels, values from a seeded hash; points inside, on the
        // faces, outside (clamped) and not finite.
        let mut v = Volume::try_new([5, 4, 3], 6, Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.5, 0.5, 3.0), 0.0, u64::MAX).unwrap();
        for (k, x) in v.data.iter_mut().enumerate() {
            *x = relume_base::math::rng::uniform(3, k as u64, 0) * 4.0 - 2.0;
        }
        let s = Sampler::new(&v);
        for k in 0..200u64 {
            let u = |d| relume_base::math::rng::uniform(4, k, d) * 1.4 - 0.2;
            let p = v.min + (v.max - v.min) * Vec3::new(u(0), u(1), u(2));
            for c in [0, 2] {
                assert_eq!(s.sample4(p, c).to_array(), s.sample_n::<4>(p, c), "{p} from channel {c}");
            }
        }
        let nan = Vec3::splat(f32::NAN);
        assert_eq!(s.sample4(nan, 1).to_array(), s.sample_n::<4>(nan, 1));
    }

    #[test]
    fn trilinear_sampling_and_the_gradient_are_exact_on_a_linear_field_inside() {
        let v = linear();
        assert_eq!(v.voxel(), Vec3::new(0.5, 0.2, 1.0));
        for p in [Vec3::new(0.0, 0.5, 2.0), Vec3::new(-0.7, 0.15, 0.55), Vec3::new(1.7, 0.85, 3.45)] {
            let want = 2.0 * p.x - p.y + 0.5 * p.z + 1.0;
            assert!((v.sample(p, 0) - want).abs() < 1e-5, "{p}: {} vs {want}", v.sample(p, 0));
        }
        let g = v.gradient(Vec3::new(0.3, 0.5, 2.0), 0);
        assert!((g - Vec3::new(2.0, -1.0, 0.5)).abs().max_element() < 1e-4, "{g}");
        for p in [Vec3::new(0.0, 0.5, 2.0), Vec3::new(-0.7, 0.15, 0.55), Vec3::new(1.9, 0.99, 3.9), Vec3::splat(-9.0)] {
            assert_eq!(v.sample_n::<1>(p, 0)[0], v.sample(p, 0), "{p}");
        }
        // Outside the outermost centres the value is held (clamped), never extrapolated.
        assert_eq!(v.sample(Vec3::new(-5.0, 0.5, 2.0), 0), v.sample(Vec3::new(-0.75, 0.5, 2.0), 0));
        assert!(v.sample(Vec3::splat(f32::NAN), 0).is_finite());
        // The sampler agrees to rounding, clamps the same way and survives NaN.
        let s = Sampler::new(&v);
        for p in [Vec3::new(-0.7, 0.15, 0.55), Vec3::new(1.9, 0.99, 3.9), Vec3::splat(-9.0), Vec3::splat(9.0)] {
            let (a, b) = (s.sample_n::<1>(p, 0)[0], v.sample(p, 0));
            assert!((a - b).abs() <= 1e-5 * b.abs().max(1.0), "{p}: {a} vs {b}");
        }
        assert!(s.sample_n::<1>(Vec3::splat(f32::NAN), 0)[0].is_finite());
    }

    #[test]
    fn a_4096_cubed_grid_is_refused_before_allocating_with_the_estimate() {
        let e = Volume::try_new([4096; 3], 1, Vec3::ZERO, Vec3::ONE, 1.0, u64::MAX).unwrap_err();
        assert!(matches!(e, NodeError::OverLimit { .. }), "{e}");
        assert!(e.to_string().contains("256.00 GiB") && e.to_string().contains("8.00 GiB"), "{e}");
        let e = Volume::try_new([128; 3], 3, Vec3::ZERO, Vec3::ONE, 1.0, 1 << 20).unwrap_err();
        assert!(e.to_string().contains("24.0 MiB") && e.to_string().contains("1.0 MiB"), "{e}");
        assert!(Volume::try_new([0, 4, 4], 1, Vec3::ZERO, Vec3::ONE, 1.0, u64::MAX).is_err());
        assert!(Volume::try_new([4; 3], 1, Vec3::ONE, Vec3::ZERO, 1.0, u64::MAX).is_err(), "an inverted box");
        assert_eq!(Volume::bytes_for([u32::MAX; 3], 3), u64::MAX, "no overflow");
    }

    #[test]
    fn it_round_trips_and_bad_bytes_decode_to_none() {
        let v = linear();
        assert_eq!(Volume::decode(&v.encode()).unwrap(), v);
        let bytes = v.encode();
        for len in [0, 7, bytes.len() / 2, bytes.len() - 1] {
            assert!(Volume::decode(&bytes[..len]).is_none(), "{len}");
        }
        let mut bad = v.clone();
        bad.dims[2] = 5;
        assert!(Volume::decode(&bad.encode()).is_none(), "sizes that disagree");
        let mut bad = v;
        bad.max.x = -3.0;
        assert!(Volume::decode(&bad.encode()).is_none(), "an inverted box");
    }
}
