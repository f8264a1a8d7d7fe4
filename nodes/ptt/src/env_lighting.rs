use super::types::lobe_side;
use super::types::{EnvLight, PrefilteredEnv};
use glam::Vec3;
use relume_base::math::cube_haar::CubeHaar;
use relume_base::math::cubemap::{sub_texel_bytes, CubeMap};
use relume_base::types::{Environment, Metrics, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, MemoryEstimate, NodeError, PortSize, RunCtx};

params! {
    /// The scene's environment as the transfer-tensor renderer reads it ([S] 5.2.3, 5.3.3.3): a
    /// cube map of 6 × `side` × `side` texels (each the solid-angle-weighted mean of sub-texels
    /// of the lat-long map, `supersample` or more a side: at most half a map texel wide, so a sun
    /// a few map texels wide is averaged into the texel, never hit or missed by a sparse sample;
    /// turn or scale the sky with `TurnEnvironment` upstream, so the reference sees it too); its
    /// Haar
    /// coefficients C^L (`math::cube_haar`: non-standard Haar per face, then one orthonormal step
    /// over the faces' six scaling terms, so a constant environment is one coefficient); and, for
    /// the specular lobes of widths `lobe_step_deg` × 1 … `lobes` ([S] 5-13: 7°, 14°, 21°; the
    /// 0° lobe reads the map itself), the environment convolved with each normalised Gaussian
    /// lobe (`CubeMap::gaussian_prefilter`, on a box-filtered copy whose texels are at most half
    /// the lobe's σ wide). All coefficients are kept: each transfer keeps its own largest terms.
    /// Turning or swapping the environment re-runs this node and the relighting only.
    ///
    /// Metrics: the largest texel radiance and the luminance integral ∫ L dω (sr-weighted sum),
    /// the number of non-zero Haar coefficients and the share of the coefficients' energy the 96
    /// largest area-weighted ones hold (how sparse the sky is), bytes.
    pub struct EnvLighting {
        /// texels along a cube face ([S]: 64)
        pub side: usize = 64, range = 4..=512, test = 8;
        /// fewest sub-texels per texel side averaged from the lat-long map (more where the map is
        /// finer, as long as a face holds at most 2,048 sub-texels along it)
        pub supersample: usize = 4, range = 1..=16, test = 2;
        /// angular standard deviation of the first specular lobe; lobe k has k times it
        pub lobe_step_deg: f64 = 7.0, range = 0.1..=60.0, unit = "°";
        /// prefiltered environments for the lobes of non-zero width ([S]: 3)
        pub lobes: usize = 3, range = 0..=8;
    }
}

/// The most sub-texels along a cube face that the map's resolution adds beyond `supersample`
/// (their coordinates and solid angles, 56 bytes a sub-texel of one face, are held: 224 MiB).
const MAX_SUB: usize = 2048;

impl EnvLighting {
    fn bytes(&self) -> u64 {
        let lobes: u64 = (1..=self.lobes).map(|k| 2 * CubeMap::bytes_for(lobe_side(k as f64 * self.lobe_step_deg, self.side))).sum();
        3 * CubeMap::bytes_for(self.side) + lobes
    }

    /// Sub-texels per texel side: `supersample`, or as many as make a sub-texel at most half a
    /// map texel wide at a face's centre (a texel spans 2 / side radians there, a texel of a
    /// map `width` wide 2π / width; the bilinear lookup's tent, two texels wide, is then
    /// sampled four times across); what the map adds stops at `MAX_SUB` along a face.
    fn sub_texels(&self, scene: &Scene) -> usize {
        let width = match &scene.environment {
            Some(Environment::Map(m)) => m.width,
            _ => 0,
        };
        let fine = (2.0 * width as f64 / (std::f64::consts::PI * self.side as f64)).ceil() as usize;
        self.supersample.max(fine.min(MAX_SUB / self.side))
    }

    /// The cube map of the scene's environment.
    pub fn cube(&self, scene: &Scene) -> CubeMap {
        match &scene.environment {
            Some(Environment::Constant(c)) => CubeMap::constant(self.side, *c),
            Some(Environment::Map(m)) => CubeMap::from_latlong(self.side, self.sub_texels(scene), |uv| m.lookup(uv)),
            None => CubeMap::constant(self.side, Vec3::ZERO),
        }
    }
}

#[node(category = "ptt", version = 2, metrics = ["radiance_max", "luminance_integral", "haar_nonzero", "energy_share_top96", "bytes"], outputs = [light, metrics])]
impl EnvLighting {
    fn memory(&self, _inputs: &[Option<PortSize>]) -> MemoryEstimate {
        MemoryEstimate {
            outputs: vec![Some(PortSize::bytes(self.bytes())), Some(PortSize::bytes(1024))],
            // The sub-texels' coordinates and solid angles at the finest the map may ask for.
            working: CubeMap::bytes_for(self.side) + sub_texel_bytes((self.side * self.supersample).max(MAX_SUB)) as u64,
        }
    }

    fn run(&self, scene: &Scene, cx: &RunCtx) -> Result<(EnvLight, Metrics), NodeError> {
        if !self.side.is_power_of_two() {
            return Err(NodeError::param("side", format!("the Haar transform needs a power of two, not {}", self.side)));
        }
        if scene.environment.is_none() {
            return Err(NodeError::input("scene", "the scene has no environment to light it (add `environment: Map(…)` or `Constant(…)`)"));
        }
        let bytes = self.bytes();
        if bytes > cx.memory_budget() {
            return Err(NodeError::OverLimit {
                param: Some("side".into()),
                msg: format!("the cube maps would hold {}, over the {} budget", fmt_bytes(bytes), fmt_bytes(cx.memory_budget())),
            });
        }
        let map = self.cube(scene);
        cx.check()?;
        let haar = CubeHaar::forward(&map);
        let lobes = (1..=self.lobes)
            .map(|k| {
                cx.check()?;
                let sigma = k as f64 * self.lobe_step_deg;
                let m = lobe_side(sigma, self.side);
                let texels = map.box_downsample(m).gaussian_prefilter((sigma as f32).to_radians(), m).texels;
                Ok(PrefilteredEnv { sigma_deg: sigma as f32, n: m as u32, texels })
            })
            .collect::<Result<Vec<_>, NodeError>>()?;
        let lum = |v: Vec3| v.dot(Vec3::new(0.2126, 0.7152, 0.0722));
        let max = map.texels.iter().map(|t| lum(*t)).fold(0.0f32, f32::max);
        let energy: f64 = haar.coeffs.iter().map(|c| c.length_squared() as f64).sum();
        let kept = haar.keep_largest(96);
        let kept_energy: f64 = kept.value.iter().map(|c| c.length_squared() as f64).sum();
        let m = Metrics(vec![
            ("radiance_max".into(), max as f64),
            ("luminance_integral".into(), lum(map.integral()) as f64),
            ("haar_nonzero".into(), haar.coeffs.iter().filter(|c| **c != Vec3::ZERO).count() as f64),
            ("energy_share_top96".into(), if energy > 0.0 { kept_energy / energy } else { 1.0 }),
            ("bytes".into(), bytes as f64),
        ]);
        for (name, v) in &m.0 {
            cx.metric(name, *v);
        }
        Ok((EnvLight { n: self.side as u32, map: map.texels, haar: haar.coeffs, lobes }, m))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::scene::builder::SceneBuilder;
    use relume_base::testing::{first, i, run_on};
    use relume_core::Value;

    fn scene(env: Environment) -> Scene {
        SceneBuilder::new(Vec3::Z, Vec3::ZERO, 40.0, 8, 8).environment(env).build()
    }

    fn light(s: &Scene, params: &[(&str, relume_core::ParamValue)]) -> EnvLight {
        first(&run_on::<EnvLighting>(params, vec![Value::new(s.clone())]).expect("runs"))
    }

    #[test]
    fn a_constant_environment_is_one_coefficient_and_a_zero_one_none() {
        let s = scene(Environment::Constant(Vec3::new(0.5, 1.0, 2.0)));
        let l = light(&s, &[("side", i(16))]);
        let nz: Vec<usize> = (0..l.haar.len()).filter(|&k| l.haar[k] != Vec3::ZERO).collect();
        assert_eq!(nz, [0]);
        // The one coefficient is the mean radiance times √(texels): the map's L2 norm.
        let want = Vec3::new(0.5, 1.0, 2.0) * (6.0f32 * 256.0).sqrt();
        assert!((l.haar[0] - want).abs().max_element() < 1e-4 * want.max_element(), "{:?}", l.haar[0]);
        // Prefiltered copies of a constant stay constant.
        assert_eq!(l.lobes.len(), 3);
        for lobe in &l.lobes {
            assert!(lobe.texels.iter().all(|t| (*t - Vec3::new(0.5, 1.0, 2.0)).abs().max_element() < 1e-5));
        }
        let z = light(&scene(Environment::Constant(Vec3::ZERO)), &[("side", i(16))]);
        assert!(z.haar.iter().chain(&z.map).all(|c| *c == Vec3::ZERO));
    }

    #[test]
    fn a_sun_keeps_its_energy_and_turns_with_the_rotation() {
        // A one-texel sun in a dark lat-long map: the cube map's integral is the map's.
        let (w, h) = (256usize, 128usize);
        let sun = Vec3::new(0.663, 0.643, 0.383).normalize();
        let uv = relume_base::math::latlong::dir_to_uv(sun);
        let (sx, sy) = (((uv.x * w as f32) as usize).min(w - 1), ((uv.y * (h - 1) as f32).round() as usize).min(h - 1));
        let mut texels = vec![Vec3::splat(0.01); w * h];
        texels[sy * w + sx] = Vec3::splat(1.0e4);
        let env = relume_base::types::EnvMap::new(w, h, texels).expect("map");
        let s = scene(Environment::Map(env.clone()));
        // Reference integral by brute force over the sphere (Fibonacci points).
        let k = 400_000;
        let brute: f64 = (0..k)
            .map(|j| {
                let z = 1.0 - (2.0 * j as f64 + 1.0) / k as f64;
                let r = (1.0 - z * z).sqrt();
                let phi = j as f64 * 2.399_963_229_728_653;
                env.eval(Vec3::new((r * phi.cos()) as f32, z as f32, (r * phi.sin()) as f32)).x as f64
            })
            .sum::<f64>()
            * 4.0
            * std::f64::consts::PI
            / k as f64;
        let l = light(&s, &[("side", i(32)), ("supersample", i(8))]);
        let total = l.cube().integral().x as f64;
        assert!((total / brute - 1.0).abs() < 0.02, "cube {total} against {brute}");
        // Coarse cube maps with one sub-texel asked: as many are taken as the map's texels
        // need, so the sun is averaged in, not hit (far too bright) or missed (gone).
        for side in [4, 8, 16] {
            let total = light(&s, &[("side", i(side)), ("supersample", i(1))]).cube().integral().x as f64;
            assert!((total / brute - 1.0).abs() < 0.02, "side {side}: cube {total} against {brute}");
        }
        // The brightest texel points at the sun.
        let brightest = |l: &EnvLight| (0..l.map.len()).max_by(|&a, &b| l.map[a].x.total_cmp(&l.map[b].x)).unwrap_or(0);
        assert!(l.cube().direction(brightest(&l)).dot(sun) > 0.99);
    }

    #[test]
    fn lobe_sides_resolve_their_sigma_and_no_environment_is_refused() {
        assert_eq!(lobe_side(7.0, 64), 32);
        assert_eq!(lobe_side(14.0, 64), 16);
        assert_eq!(lobe_side(21.0, 64), 16);
        assert_eq!(lobe_side(1.0, 64), 64);
        let e =
            run_on::<EnvLighting>(&[], vec![Value::new(SceneBuilder::new(Vec3::Z, Vec3::ZERO, 40.0, 8, 8).build())]).expect_err("refused");
        assert!(e.to_string().contains("no environment"), "{e}");
        let e = run_on::<EnvLighting>(&[("side", i(48))], vec![Value::new(scene(Environment::Constant(Vec3::ONE)))]).expect_err("refused");
        assert!(e.to_string().contains("power of two"), "{e}");
    }
}
