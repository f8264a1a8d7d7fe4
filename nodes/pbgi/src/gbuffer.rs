use crate::types::Receivers;
use relume_base::render::camera::CameraRays;
use relume_base::render::surface::Surface;
use relume_base::types::accel::Accel;
use relume_base::types::{Material, Scene};
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// The camera's primary hits at pixel centres, as receivers: pixel, position, shading normal
    /// turned toward the camera, direction to the camera, object and material. Pixels that see
    /// the background or the back of a one-sided surface get no receiver, nor do those that
    /// see a smooth dielectric unless `dielectrics` is on (only `WaveletGather` shades them,
    /// through its spherical microbuffer; the other gathers leave them black).
    pub struct GBuffer {
        /// make receivers of the pixels that see a smooth dielectric (glass) too
        pub dielectrics: bool = false;
    }
}

/// Receivers of every pixel centre, row by row in parallel.
pub fn gbuffer(scene: &Scene, accel: &Accel, dielectrics: bool, cx: &RunCtx) -> Result<Receivers, NodeError> {
    let cam = CameraRays::new(&scene.camera);
    let (w, h) = (scene.camera.width, scene.camera.height);
    let rows: Vec<Vec<(u32, Surface, glam::Vec3)>> = cx.par_map(h, |y| {
        (y * w..(y + 1) * w)
            .filter_map(|i| {
                let (o, d) = cam.ray((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                let hit = accel.intersect(o, d, 0.0, f32::INFINITY)?;
                let s = Surface::at(scene, &hit, o, d);
                let m = s.material(scene);
                (d.dot(s.ng) < 0.0 && (dielectrics || !matches!(m, Material::Dielectric { .. }))).then_some((i as u32, s, -d))
            })
            .collect()
    })?;
    let mut r = Receivers { width: w, height: h, ..Default::default() };
    for (pixel, s, wo) in rows.into_iter().flatten() {
        r.pixel.push(pixel);
        r.position.push(s.p);
        r.normal.push(s.ns);
        r.wo.push(wo);
        r.object.push(s.object);
        r.material.push(s.material(scene));
    }
    Ok(r)
}

#[node(category = "pbgi", metrics = ["receivers"], outputs = [receivers])]
impl GBuffer {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // At most one receiver per pixel.
        let size = inputs[0].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize {
            bytes: (w * h * crate::types::Receivers::BYTES_PER_RECEIVER) as u64,
            dims: Some([w, h]),
        });
        relume_core::MemoryEstimate { outputs: vec![size], working: 0 }
    }

    fn run(&self, scene: &Scene, accel: &Accel, cx: &RunCtx) -> Result<Receivers, NodeError> {
        let r = gbuffer(scene, accel, self.dielectrics, cx)?;
        cx.metric("receivers", r.len() as f64);
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::testing::{cancels_midway, test_scene};
    use relume_base::types::accel::BuildQuality;
    use relume_core::{CancelToken, Value};

    #[test]
    fn receivers_are_the_visible_hits_with_normals_toward_the_camera() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let cancel = CancelToken::new();
        let r = gbuffer(&scene, &accel, false, &RunCtx::new("t", &cancel, None)).unwrap();
        assert!(r.len() > 100 && r.len() <= 16 * 16, "{}", r.len());
        for i in 0..r.len() {
            assert!(r.normal[i].dot(r.wo[i]) > 0.0, "faces the camera");
            let to_cam = (scene.camera.origin - r.position[i]).normalize();
            assert!((to_cam - r.wo[i]).length() < 1e-4);
        }
        let mut px = r.pixel.clone();
        px.dedup();
        assert_eq!(px.len(), r.len(), "one receiver per pixel, in pixel order");
    }

    #[test]
    fn pixels_on_glass_become_receivers_only_when_asked() {
        use glam::Vec3;
        use relume_base::scene::builder::SceneBuilder;
        let grey = Material::Lambert { albedo: Vec3::splat(0.5) };
        let glass = Material::Dielectric { ior: 1.5, medium: None };
        let scene = SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, 16, 16)
            .sphere("glass", Vec3::ZERO, 0.6, glass, Vec3::ZERO, false)
            .quad("floor", Vec3::new(-2.0, -1.0, 2.0), Vec3::new(4.0, 0.0, 0.0), Vec3::new(0.0, 0.0, -4.0), grey, Vec3::ZERO)
            .build();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let cancel = CancelToken::new();
        let run = |d| gbuffer(&scene, &accel, d, &RunCtx::new("t", &cancel, None)).unwrap();
        let (without, with) = (run(false), run(true));
        let on_glass = |r: &Receivers| r.material.iter().filter(|m| matches!(m, Material::Dielectric { .. })).count();
        assert_eq!(on_glass(&without), 0);
        assert!(on_glass(&with) > 20 && with.len() == without.len() + on_glass(&with), "{} {}", with.len(), without.len());
        assert!((0..with.len()).all(|i| with.normal[i].dot(with.wo[i]) > 0.0), "seen from outside");
    }

    #[test]
    fn the_node_stops_when_cancelled() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        cancels_midway::<GBuffer>(&[], vec![Value::new(scene), Value::new(accel)]);
    }
}
