use super::types::VertexColors;
use glam::Vec3;
use relume_base::render::integrator::{Counts, Settings, Tracer};
use relume_base::types::{Accel, Scene};
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// The reference path tracer's radiance leaving every vertex toward the scene's camera: the
    /// vertex-sampled reference of per-vertex relighting ([S] chapter 5). Rasterised like the
    /// relit colours (`RasterizeVertexColors`), it has the same interpolation across triangles
    /// and none of the method's approximations, so its error against the pixel reference is what
    /// interpolation costs (a shadow edge across a coarse ground), and the relit image's error
    /// against it is the method's own. Per vertex, `spp` paths of the reference integrator
    /// (`PathTrace`'s, same `max_depth` meaning: the first segment is the short one arriving at
    /// the vertex) start 10⁻³ of the scene's extent in front of the vertex toward the camera and
    /// aim at it (a thousandth of the way into its first triangle, not at the vertex itself, which
    /// rays can slip past between triangles). Vertices no triangle uses are black. Each vertex's mean depends only on (seed,
    /// vertex, sample): the same bytes on any thread count.
    ///
    /// Metrics: vertices, rays traced.
    pub struct VertexPathTrace {
        /// paths per vertex
        pub spp: u32 = 256, range = 1..=(1 << 20), unit = "samples/vertex", test = 4;
        /// maximum path segments (Mitsuba's meaning); -1 = unbounded
        pub max_depth: i32 = 4, range = -1..=1024;
        /// depth at which Russian roulette starts
        pub rr_depth: u32 = 5, range = 1..=1024;
        /// random seed
        pub seed: u64 = 0, range = 0..=u32::MAX;
    }
}

#[node(category = "ptt", version = 2, metrics = ["vertices", "rays"], outputs = [colors])]
impl VertexPathTrace {
    fn run(&self, scene: &Scene, accel: &Accel, cx: &RunCtx) -> Result<VertexColors, NodeError> {
        let n = scene.positions.len();
        VertexColors::check_budget(n, cx.memory_budget())?;
        // Per vertex, a point a thousandth of the way from it to the centroid of its first
        // triangle: rays aimed exactly at a vertex shared by several triangles can slip
        // between them.
        let mut aim: Vec<Option<Vec3>> = vec![None; n];
        for tri in &scene.triangles {
            let c = tri.iter().map(|&v| scene.positions[v as usize]).sum::<Vec3>() / 3.0;
            for &v in tri {
                let p = scene.positions[v as usize];
                aim[v as usize].get_or_insert(p + (c - p) * 1e-3);
            }
        }
        let tracer = Tracer::new(
            scene,
            accel,
            Settings { max_depth: self.max_depth, min_depth: 1, rr_depth: self.rr_depth, seed: self.seed, fresnel_reflection: true },
        );
        let (eye, back) = (scene.camera.origin, 1e-3 * scene.extent());
        let per = cx.par_map(n, |v| {
            let Some(p) = aim[v] else { return (Vec3::ZERO, 0) };
            let wo = (eye - p).normalize_or_zero();
            if wo == Vec3::ZERO {
                return (Vec3::ZERO, 0);
            }
            let mut counts = Counts { rays: 0 };
            let mut sum = [0.0f64; 3];
            for s in 0..self.spp {
                let l = tracer.radiance(p + wo * back, -wo, (v as u64) << 32 | s as u64, &mut counts);
                if l.is_finite() {
                    sum.iter_mut().zip(l.to_array()).for_each(|(a, x)| *a += x as f64);
                }
            }
            (Vec3::from_array(sum.map(|a| (a / self.spp as f64) as f32)), counts.rays)
        })?;
        cx.metric("vertices", n as f64);
        cx.metric("rays", per.iter().map(|p| p.1).sum::<u64>() as f64);
        Ok(VertexColors::plain(per.into_iter().map(|p| p.0).collect()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::plane;
    use relume_base::testing::{first, i, run_on};
    use relume_base::types::accel::BuildQuality;
    use relume_base::types::{Environment, Material};
    use relume_core::Value;

    #[test]
    fn an_open_lambert_plane_under_a_constant_sky_leaves_albedo_times_sky_and_threads_do_not_matter() {
        let s = plane(Material::Lambert { albedo: Vec3::splat(0.6) }, false, Environment::Constant(Vec3::new(1.0, 0.5, 0.25)));
        let inputs = vec![Value::new(s.clone()), Value::new(Accel::build(&s, BuildQuality::Fast))];
        let c: VertexColors = first(&run_on::<VertexPathTrace>(&[("spp", i(256))], inputs.clone()).expect("runs"));
        assert_eq!(c.colors.len(), 81);
        let mean = c.colors.iter().sum::<Vec3>() / 81.0;
        // Unbiased (the mean over vertices within 1 %); each vertex's mean of 256 paths within
        // 12 % (at 64 paths the spread measured −10 … +7 %, at 256 it halves).
        let want = Vec3::new(0.6, 0.3, 0.15);
        assert!(((mean - want) / want).abs().max_element() < 0.01, "{mean}");
        for col in &c.colors {
            assert!(((*col - want) / want).abs().max_element() < 0.12, "{col}");
        }
        let one: VertexColors = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| first(&run_on::<VertexPathTrace>(&[("spp", i(256))], inputs).expect("runs")));
        assert_eq!(one, c);
    }
}
