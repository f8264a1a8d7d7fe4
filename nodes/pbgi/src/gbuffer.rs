use crate::types::Receivers;
use glam::Vec3;
use relume_base::render::camera::CameraRays;
use relume_base::render::surface::Surface;
use relume_base::types::accel::Accel;
use relume_base::types::{Material, Scene};
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// The camera's primary hits as receivers: pixel, position, shading normal turned toward
    /// the camera, direction to the camera, object, material and share of the pixel. A pixel
    /// whose footprint lies on one smooth piece of surface gets one receiver, at its centre; one
    /// that spans an edge (another object, a fold, a step in depth, the background) gets one per
    /// hit of an `edge_samples` × `edge_samples` grid over it, each with its share, so the
    /// gathered light is the pixel's mean as the direct light's antialiased rays see it, not
    /// the light at one surface's point. Pixels that see the background or the back of a
    /// one-sided surface get no receiver, nor do those that see a smooth dielectric unless
    /// `dielectrics` is on (only `WaveletGather` shades them, through its spherical
    /// microbuffer; the other gathers leave them black).
    pub struct GBuffer {
        /// make receivers of the pixels that see a smooth dielectric (glass) too
        pub dielectrics: bool = false;
        /// side of the grid of receivers in a pixel that spans an edge (1: one receiver at
        /// every pixel centre)
        pub edge_samples: usize = 2, range = 1..=4;
    }
}

/// Two hits lie on one smooth piece of surface: the same object, shading normals within about
/// 25°, distances from the camera within 5 %.
fn same_surface(a: &(Surface, Vec3, f32), b: &(Surface, Vec3, f32)) -> bool {
    a.0.object == b.0.object && a.0.ns.dot(b.0.ns) >= 0.9 && (a.2 - b.2).abs() <= 0.05 * a.2.min(b.2)
}

/// Receivers of every pixel, row by row in parallel. First the pixel centres' hits; then each
/// pixel whose centre's hit lies on another piece of surface than one of its four neighbours'
/// (or sees what the other does not) traces a `k` × `k` grid: where all of the grid's hits lie on
/// its centre's piece of surface it keeps the centre's receiver, else each hit becomes one at
/// 1/k² of the pixel. An edge that passes between no two pixel centres goes unseen.
pub fn gbuffer(scene: &Scene, accel: &Accel, dielectrics: bool, k: usize, cx: &RunCtx) -> Result<Receivers, NodeError> {
    let cam = CameraRays::new(&scene.camera);
    let (w, h) = (scene.camera.width, scene.camera.height);
    let k = k.max(1);
    // The surface a ray through (x, y) of the image makes a receiver of, with the direction
    // back to the camera and the distance.
    let receiver_at = |x: f32, y: f32| {
        let (o, d) = cam.ray(x, y);
        let hit = accel.intersect(o, d, 0.0, f32::INFINITY)?;
        let s = Surface::at(scene, &hit, o, d);
        let m = s.material(scene);
        let dist = (s.p - o).length();
        (d.dot(s.ng) < 0.0 && (dielectrics || !matches!(m, Material::Dielectric { .. }))).then_some((s, -d, dist))
    };
    let centres: Vec<Vec<Option<(Surface, Vec3, f32)>>> =
        cx.par_map(h, |y| (0..w).map(|x| receiver_at(x as f32 + 0.5, y as f32 + 0.5)).collect())?;
    let differs = |a: &Option<(Surface, Vec3, f32)>, b: &Option<(Surface, Vec3, f32)>| match (a, b) {
        (Some(a), Some(b)) => !same_surface(a, b),
        (None, None) => false,
        _ => true,
    };
    let rows: Vec<Vec<(u32, Surface, Vec3, f32)>> = cx.par_map(h, |y| {
        let mut row = Vec::new();
        for x in 0..w {
            let i = (y * w + x) as u32;
            let centre = &centres[y][x];
            let neighbours = [(x.wrapping_sub(1), y), (x + 1, y), (x, y.wrapping_sub(1)), (x, y + 1)];
            let edge = k > 1 && neighbours.iter().any(|&(nx, ny)| nx < w && ny < h && differs(centre, &centres[ny][nx]));
            if !edge {
                row.extend(centre.as_ref().map(|(s, wo, _)| (i, s.clone(), *wo, 1.0)));
                continue;
            }
            let grid: Vec<_> = (0..k * k)
                .map(|j| receiver_at(x as f32 + ((j % k) as f32 + 0.5) / k as f32, y as f32 + ((j / k) as f32 + 0.5) / k as f32))
                .collect();
            match centre {
                Some(c) if grid.iter().all(|g| g.as_ref().is_some_and(|g| same_surface(c, g))) => row.push((i, c.0.clone(), c.1, 1.0)),
                _ => row.extend(grid.into_iter().flatten().map(|(s, wo, _)| (i, s, wo, 1.0 / (k * k) as f32))),
            }
        }
        row
    })?;
    let mut r = Receivers { width: w, height: h, ..Default::default() };
    for (pixel, s, wo, weight) in rows.into_iter().flatten() {
        r.pixel.push(pixel);
        r.position.push(s.p);
        r.normal.push(s.ns);
        r.wo.push(wo);
        r.object.push(s.object);
        r.material.push(s.material(scene));
        r.weight.push(weight);
    }
    Ok(r)
}

/// Pixels with more than one receiver, or one that covers only part of them.
fn edge_pixels(r: &Receivers) -> usize {
    let mut last = None;
    r.pixel.iter().zip(&r.weight).filter(|&(&p, &w)| w < 1.0 && last.replace(p) != Some(p)).count()
}

#[node(category = "pbgi", version = 3, metrics = ["receivers", "edge_pixels"], outputs = [receivers])]
impl GBuffer {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // At most edge_samples² receivers per pixel; the pixel centres' hits while it runs.
        let per_pixel = self.edge_samples.clamp(1, 4).pow(2);
        let dims = inputs[0].and_then(|s| s.dims);
        let size = dims.map(|[w, h]| relume_core::PortSize {
            bytes: (w * h * per_pixel * crate::types::Receivers::BYTES_PER_RECEIVER) as u64,
            dims: Some([w, h]),
        });
        let centres = dims.map_or(0, |[w, h]| (w * h * std::mem::size_of::<Option<(Surface, Vec3, f32)>>()) as u64);
        relume_core::MemoryEstimate { outputs: vec![size], working: centres }
    }

    fn run(&self, scene: &Scene, accel: &Accel, cx: &RunCtx) -> Result<Receivers, NodeError> {
        let r = gbuffer(scene, accel, self.dielectrics, self.edge_samples, cx)?;
        cx.metric("receivers", r.len() as f64);
        cx.metric("edge_pixels", edge_pixels(&r) as f64);
        Ok(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::testing::{cancels_midway, test_scene};
    use relume_base::types::accel::BuildQuality;
    use relume_core::{CancelToken, Value};

    /// `test_scene::spheres`'s receivers with a `k` × `k` grid in pixels that span an edge.
    fn spheres(k: usize) -> (Scene, Receivers) {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let cancel = CancelToken::new();
        let r = gbuffer(&scene, &accel, false, k, &RunCtx::new("t", &cancel, None)).unwrap();
        (scene, r)
    }

    #[test]
    fn receivers_are_the_visible_hits_with_normals_toward_the_camera() {
        let (scene, r) = spheres(1);
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
    fn a_pixel_that_spans_an_edge_gets_a_receiver_per_share_of_it() {
        let (_, one) = spheres(1);
        for k in [2, 3] {
            let (_, r) = spheres(k);
            let mut share = vec![0.0f32; r.width * r.height];
            let mut count = vec![0usize; r.width * r.height];
            for i in 0..r.len() {
                share[r.pixel[i] as usize] += r.weight[i];
                count[r.pixel[i] as usize] += 1;
                assert!(r.weight[i] == 1.0 || r.weight[i] == 1.0 / (k * k) as f32, "{}", r.weight[i]);
            }
            assert!(share.iter().all(|&s| s <= 1.0 + 1e-6), "no pixel holds more than itself");
            let edges = count.iter().filter(|&&c| c > 1).count();
            assert!(edges > 10 && edges < r.width * r.height / 2, "{edges} pixels span an edge (k = {k})");
            assert!(count.iter().all(|&c| c <= k * k));
            // A pixel whole on one surface keeps the centre's receiver.
            for i in (0..r.len()).filter(|&i| r.weight[i] == 1.0) {
                let j = one.pixel.binary_search(&r.pixel[i]).expect("its centre is a receiver with one per pixel");
                assert_eq!((one.position[j], one.normal[j]), (r.position[i], r.normal[i]));
            }
        }
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
        let run = |d| gbuffer(&scene, &accel, d, 1, &RunCtx::new("t", &cancel, None)).unwrap();
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
