//! GBuffer node.

use crate::render::camera::CameraRays;
use crate::render::surface::Surface;
use crate::types::accel::Accel;
use crate::types::{Material, Receivers, Scene};
use relume_core::{inputs, node, outputs, NodeError, Params, RunCtx};

/// The camera's primary hits at pixel centres, as receivers: pixel, position, shading normal
/// turned toward the camera, direction to the camera, object and material. Pixels that see
/// the background, the back of a one-sided surface or a dielectric get no receiver.
#[derive(Params)]
pub struct GBuffer;

inputs!(pub GBufferIn { scene: Scene, accel: Accel });
outputs!(pub GBufferOut { receivers: Receivers });

/// Receivers of every pixel centre, row by row in parallel.
pub fn gbuffer(scene: &Scene, accel: &Accel, cx: &RunCtx) -> Result<Receivers, NodeError> {
    let cam = CameraRays::new(&scene.camera);
    let (w, h) = (scene.camera.width, scene.camera.height);
    let rows: Vec<Vec<(u32, Surface, glam::Vec3)>> = cx.par_map(h, |y| {
        (y * w..(y + 1) * w)
            .filter_map(|i| {
                let (o, d) = cam.ray((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                let hit = accel.intersect(o, d, 0.0, f32::INFINITY)?;
                let s = Surface::at(scene, &hit, o, d);
                let m = s.material(scene);
                (d.dot(s.ng) < 0.0 && !matches!(m, Material::Dielectric { .. })).then_some((i as u32, s, -d))
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

#[node(category = "pbgi")]
impl GBuffer {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // At most one receiver per pixel.
        let size = inputs[0].and_then(|s| s.dims).map(|[w, h]| relume_core::PortSize {
            bytes: (w * h * crate::types::Receivers::BYTES_PER_RECEIVER) as u64,
            dims: Some([w, h]),
        });
        relume_core::MemoryEstimate { outputs: vec![size], working: 0 }
    }

    fn run(&self, i: GBufferIn, cx: &RunCtx) -> Result<GBufferOut, NodeError> {
        let r = gbuffer(i.scene, i.accel, cx)?;
        cx.metric("receivers", r.len() as f64);
        Ok(GBufferOut { receivers: r })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{cancels_midway, test_scene};
    use crate::types::accel::BuildQuality;
    use relume_core::{CancelToken, Value};

    #[test]
    fn receivers_are_the_visible_hits_with_normals_toward_the_camera() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let cancel = CancelToken::new();
        let r = gbuffer(&scene, &accel, &RunCtx::new("t", &cancel, None)).unwrap();
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
    fn the_node_stops_when_cancelled() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        cancels_midway::<GBuffer>(&[], vec![Value::new(scene), Value::new(accel)]);
    }
}
