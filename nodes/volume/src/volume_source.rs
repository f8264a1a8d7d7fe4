use crate::types::Volume;
use glam::Vec3;
use relume_base::math::rng::uniform;
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

params! {
    /// A procedural medium ([S] 6.5: gradient-index objects, turbulent media) on a cubic grid of
    /// `resolution`³ voxels over the cube of side `size` at `centre`, in the layout `Voxelize`
    /// gives (channels: refractive index n, extinction κ, scattering σ):
    /// - `Constant`: n = `index` everywhere;
    /// - `GrinSphere`: inside the sphere of `radius`, n falls parabolically from `index` at the
    ///   centre to 1 at the surface (n = 1 + (index − 1)(1 − r²/R²)), 1 outside;
    /// - `Luneburg`: the Luneburg lens n = √(2 − r²/R²) inside, 1 outside — it focuses a parallel
    ///   beam on the sphere's far side, an analytic check of photon marching;
    /// - `Turbulence`: n = `index` + `amplitude` × seeded value noise (four octaves of trilinear
    ///   lattice noise at `frequency` cells across the cube, zero mean).
    ///
    /// κ = `extinction` and σ = `scattering` wherever n ≠ 1 (everywhere for `Constant` and
    /// `Turbulence`). Voxels in parallel; the same bytes on any thread count.
    pub struct VolumeSource {
        /// which medium
        pub kind: SourceKind = GrinSphere;
        /// voxels along each side
        pub resolution: u32 = 128, range = 1..=1024, unit = "voxels", test = 32;
        /// centre of the cube
        pub centre: Vec3 = (0.0, 0.6, 0.0);
        /// side of the cube (scene units)
        pub size: f32 = 1.2, range = 1e-6..=1e6;
        /// radius of the sphere (GrinSphere, Luneburg)
        pub radius: f32 = 0.5, range = 1e-6..=1e6;
        /// refractive index (Constant, Turbulence), or at the centre (GrinSphere)
        pub index: f32 = 1.5, range = 1.0..=10.0;
        /// amplitude of the index noise (Turbulence)
        pub amplitude: f32 = 0.05, range = 0.0..=5.0;
        /// noise cells across the cube at the first octave (Turbulence)
        pub frequency: f32 = 4.0, range = 1.0..=256.0;
        /// extinction κ where the medium is (per unit length)
        pub extinction: f32 = 0.0, range = 0.0..=1e6, unit = "1/unit";
        /// scattering σ where the medium is (per unit length, ≤ κ)
        pub scattering: f32 = 0.0, range = 0.0..=1e6, unit = "1/unit";
        /// random seed (Turbulence)
        pub seed: u64 = 0, range = 0..=u32::MAX;
    }
}

/// A procedural medium.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum SourceKind {
    /// one index everywhere
    Constant,
    /// a parabolic gradient-index sphere
    GrinSphere,
    /// the Luneburg lens n = √(2 − r²/R²)
    Luneburg,
    /// index noise around a constant
    Turbulence,
}

/// Zero-mean trilinear lattice noise at `p` (lattice units), values in [−1, 1].
fn lattice_noise(seed: u64, p: Vec3) -> f32 {
    let i = p.floor();
    let f = p - i;
    let s = f * f * (Vec3::splat(3.0) - 2.0 * f);
    let at = |dx: i64, dy: i64, dz: i64| {
        let (x, y, z) = (i.x as i64 + dx, i.y as i64 + dy, i.z as i64 + dz);
        let id = (x.rem_euclid(1 << 20) as u64) | (y.rem_euclid(1 << 20) as u64) << 20 | (z.rem_euclid(1 << 20) as u64) << 40;
        2.0 * uniform(seed, id, 7) - 1.0
    };
    let lerp = |a: f32, b: f32, t: f32| a + (b - a) * t;
    let plane = |dz: i64| lerp(lerp(at(0, 0, dz), at(1, 0, dz), s.x), lerp(at(0, 1, dz), at(1, 1, dz), s.x), s.y);
    lerp(plane(0), plane(1), s.z)
}

impl VolumeSource {
    /// (n, inside) at `p`.
    fn index_at(&self, p: Vec3) -> (f32, bool) {
        let r2 = (p - self.centre).length_squared() / (self.radius * self.radius);
        match self.kind {
            SourceKind::Constant => (self.index, true),
            SourceKind::GrinSphere if r2 < 1.0 => (1.0 + (self.index - 1.0) * (1.0 - r2), true),
            SourceKind::Luneburg if r2 < 1.0 => ((2.0 - r2).sqrt(), true),
            SourceKind::GrinSphere | SourceKind::Luneburg => (1.0, false),
            SourceKind::Turbulence => {
                let q = (p - self.centre) / self.size * self.frequency;
                let n: f32 = (0..4).map(|o| lattice_noise(self.seed + o, q * (1 << o) as f32) / (1 << o) as f32).sum::<f32>() / 1.875;
                ((self.index + self.amplitude * n).max(1.0), true)
            }
        }
    }
}

#[node(category = "volume", outputs = [medium])]
impl VolumeSource {
    fn memory(&self, _inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let bytes = Volume::bytes_for([self.resolution; 3], 3);
        relume_core::MemoryEstimate { outputs: vec![Some(relume_core::PortSize::bytes(bytes))], working: 0 }
    }

    fn run(&self, cx: &RunCtx) -> Result<Volume, NodeError> {
        if self.scattering > self.extinction {
            return Err(NodeError::param("scattering", format!("σ = {} exceeds the extinction κ = {}", self.scattering, self.extinction)));
        }
        let half = Vec3::splat(self.size / 2.0);
        let mut v = Volume::try_new([self.resolution; 3], 3, self.centre - half, self.centre + half, 0.0, cx.memory_budget())?;
        let n = self.resolution as usize;
        let (min, h) = (v.min, v.voxel());
        cx.par_chunks_mut(&mut v.data, n * n * 3, |z, slice| {
            for y in 0..n {
                for x in 0..n {
                    let (index, inside) = self.index_at(min + (Vec3::new(x as f32, y as f32, z as f32) + 0.5) * h);
                    let (k, s) = if inside { (self.extinction, self.scattering) } else { (0.0, 0.0) };
                    slice[(y * n + x) * 3..(y * n + x) * 3 + 3].copy_from_slice(&[index, k, s]);
                }
            }
        })?;
        Ok(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::testing::{f, first, i, id, run_on};

    fn source(p: &[(&str, relume_core::ParamValue)]) -> Volume {
        first(&run_on::<VolumeSource>(p, vec![]).unwrap())
    }

    #[test]
    fn the_luneburg_lens_is_root_two_at_the_centre_one_at_the_surface_and_outside() {
        let v = source(&[
            ("kind", id("Luneburg")),
            ("resolution", i(33)),
            ("centre", relume_core::ParamValue::Tuple(vec![f(0.0), f(0.0), f(0.0)])),
            ("size", f(2.2)),
            ("radius", f(1.0)),
        ]);
        assert!((v.get(16, 16, 16, 0) - 2f32.sqrt()).abs() < 1e-6);
        let near_surface = v.sample(Vec3::new(0.99, 0.0, 0.0), 0);
        assert!(near_surface > 1.0 && near_surface < 1.1, "{near_surface}");
        assert_eq!(v.get(0, 0, 0, 0), 1.0);
        assert!(v.data.iter().all(|x| x.is_finite()));
    }

    #[test]
    fn the_grin_sphere_falls_parabolically_and_media_fill_only_the_sphere() {
        let v = source(&[("resolution", i(32)), ("index", f(2.0)), ("extinction", f(3.0)), ("scattering", f(1.0))]);
        // Voxel centres at ±0.01875 from the middle: r² / R² = 3 · 0.0375² / 4 … close to 2.
        let c = v.sample(Vec3::new(0.0, 0.6, 0.0), 0);
        assert!((c - 2.0).abs() < 0.01, "{c}");
        let half = v.sample(Vec3::new(0.25, 0.6, 0.0), 0);
        assert!((half - 1.75).abs() < 0.01, "{half}");
        let corner = v.index(0, 0, 0);
        assert_eq!(&v.data[corner..corner + 3], &[1.0, 0.0, 0.0]);
        let mid = v.index(16, 16, 16);
        assert_eq!(&v.data[mid + 1..mid + 3], &[3.0, 1.0]);
        let e = run_on::<VolumeSource>(&[("extinction", f(1.0)), ("scattering", f(2.0))], vec![]).unwrap_err().to_string();
        assert!(e.contains("exceeds the extinction"), "{e}");
    }

    #[test]
    fn turbulence_is_seeded_zero_mean_bounded_and_the_same_on_any_thread_count() {
        let p = [("kind", id("Turbulence")), ("resolution", i(24)), ("index", f(1.3)), ("amplitude", f(0.1))];
        let a = source(&p);
        let n: Vec<f32> = a.data.iter().step_by(3).copied().collect();
        let mean = n.iter().map(|x| *x as f64).sum::<f64>() / n.len() as f64;
        assert!((mean - 1.3).abs() < 0.03, "{mean}");
        assert!(n.iter().all(|x| (1.2..=1.4).contains(x)));
        assert!(n.iter().any(|x| (x - 1.3).abs() > 0.02), "not flat");
        let other = source(&[("kind", id("Turbulence")), ("resolution", i(24)), ("index", f(1.3)), ("amplitude", f(0.1)), ("seed", i(5))]);
        assert_ne!(a, other);
        let on = |t| rayon::ThreadPoolBuilder::new().num_threads(t).build().unwrap().install(|| source(&p));
        assert_eq!(on(1), on(3));
    }

    #[test]
    fn a_constant_medium_and_a_refused_size() {
        let v = source(&[("kind", id("Constant")), ("resolution", i(4)), ("index", f(1.0))]);
        assert!(v.data.chunks(3).all(|c| c == [1.0, 0.0, 0.0]), "index 1: the unrefracting medium");
        let e = run_on::<VolumeSource>(&[("resolution", i(1024))], vec![]);
        // 1024³ × 12 B = 12 GiB: over the 8 GiB any volume may hold.
        assert!(matches!(e, Err(NodeError::OverLimit { .. })), "{:?}", e.map(|_| ()));
    }
}
