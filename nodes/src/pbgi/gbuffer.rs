//! GBuffer node.

use crate::geometry::accel::Accel;
use crate::geometry::surface::Surface;
use crate::reference::camera::CameraRays;
use crate::types::{Material, Receivers, Scene};
use rayon::prelude::*;
use relume_core::{node_doc, Caching, Io, Node, NodeError, Ports, RunCtx};

node_doc! {
    /// The camera's primary hits at pixel centres, as receivers: pixel, position, shading normal
    /// turned toward the camera, direction to the camera, object and material. Pixels that see
    /// the background, the back of a one-sided surface or a dielectric get no receiver.
    pub struct GBuffer;
}

/// Receivers of every pixel centre.
pub fn gbuffer(scene: &Scene, accel: &Accel) -> Receivers {
    let cam = CameraRays::new(&scene.camera);
    let (w, h) = (scene.camera.width, scene.camera.height);
    let hits: Vec<Option<(u32, Surface, glam::Vec3)>> = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let (o, d) = cam.ray((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            let hit = accel.intersect(o, d, 0.0, f32::INFINITY)?;
            let s = Surface::at(scene, &hit, o, d);
            let m = scene.objects[s.object as usize].material;
            (d.dot(s.ng) < 0.0 && !matches!(m, Material::Dielectric { .. })).then_some((i as u32, s, -d))
        })
        .collect();
    let mut r = Receivers { width: w, height: h, ..Default::default() };
    for (pixel, s, wo) in hits.into_iter().flatten() {
        r.pixel.push(pixel);
        r.position.push(s.p);
        r.normal.push(s.ns);
        r.wo.push(wo);
        r.object.push(s.object);
        r.material.push(scene.objects[s.object as usize].material);
    }
    r
}

impl Node for GBuffer {
    const KIND: &'static str = "GBuffer";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "pbgi";
    const CACHING: Caching = Caching::Memory;
    type Params = ();

    fn ports() -> Ports {
        Ports::new().input::<Scene>("scene").input::<Accel>("accel").output::<Receivers>("receivers")
    }

    fn run(&self, _: &(), io: &mut Io, cx: &RunCtx) -> Result<(), NodeError> {
        let r = gbuffer(io.input::<Scene>("scene")?, io.input::<Accel>("accel")?);
        cx.metric("receivers", r.len() as f64);
        io.set("receivers", r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::accel::BuildQuality;
    use crate::testing::test_scene;

    #[test]
    fn receivers_are_the_visible_hits_with_normals_toward_the_camera() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let r = gbuffer(&scene, &accel);
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
}
