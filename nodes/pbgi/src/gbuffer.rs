use crate::types::{Fill, Receivers};
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
    ///
    /// With `stride` s > 1 (2, 4 or 8) only every s-th pixel of every s-th row is sure to be
    /// gathered where the image is smooth: any other pixel that is not at an edge, on a surface
    /// without texture maps and not glass (what glass shows changes fast across it), is filled
    /// after the gather by bilinear weights from the corners of
    /// the largest cell (side s, s/2, … 2, on the same grid) whose corners with a weight are
    /// each whole on the pixel's own piece of surface (the edge test's) and not at an edge;
    /// where no cell is, the pixel gets its own receiver. Indirect light is smooth across a
    /// surface, so a gather costs about 1/s² of its receivers on smooth surfaces and stays per
    /// pixel at edges, textures and glass. The fraction of pixels filled is a metric.
    pub struct GBuffer {
        /// make receivers of the pixels that see a smooth dielectric (glass) too
        pub dielectrics: bool = false;
        /// side of the grid of receivers in a pixel that spans an edge (1: one receiver at
        /// every pixel centre)
        pub edge_samples: usize = 2, range = 1..=4;
        /// spacing of the pixels gathered where the surface is smooth: 1 (every pixel), 2, 4 or 8
        pub stride: usize = 1, range = 1..=8, unit = "pixels";
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
///
/// With `stride` s > 1 (a power of two), a pixel off the s-grid that is not an edge and can be
/// read off the corners of a cell around it becomes a `Fill` instead of a receiver (see the
/// node's doc).
pub fn gbuffer(scene: &Scene, accel: &Accel, dielectrics: bool, k: usize, stride: usize, cx: &RunCtx) -> Result<Receivers, NodeError> {
    let cam = CameraRays::new(&scene.camera);
    let (w, h) = (scene.camera.width, scene.camera.height);
    let (k, stride) = (k.max(1), stride.max(1));
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
    let edge: Vec<Vec<bool>> = cx.par_map(h, |y| {
        (0..w)
            .map(|x| {
                let neighbours = [(x.wrapping_sub(1), y), (x + 1, y), (x, y.wrapping_sub(1)), (x, y + 1)];
                k > 1 && neighbours.iter().any(|&(nx, ny)| nx < w && ny < h && differs(&centres[y][x], &centres[ny][nx]))
            })
            .collect()
    })?;
    // Pixel (x, y), whose centre sees `c`, read off the corners of the coarsest cell whose
    // corners all lie whole on its surface, with the class of that cell (`fill_class`).
    let fill_of = |x: usize, y: usize, c: &(Surface, Vec3, f32)| -> Option<(u32, Fill)> {
        let object = &scene.objects[c.0.object as usize];
        if !object.maps.is_empty() || matches!(object.material, Material::Dielectric { .. }) {
            return None;
        }
        let valid =
            |ax: usize, ay: usize| ax < w && ay < h && !edge[ay][ax] && centres[ay][ax].as_ref().is_some_and(|a| same_surface(c, a));
        let own = fill_class(x, y, stride);
        (own + 1..=stride.trailing_zeros()).rev().find_map(|m| {
            let side = 1usize << m;
            let (x0, y0) = (x / side * side, y / side * side);
            let (fx, fy) = ((x - x0) as f32 / side as f32, (y - y0) as f32 / side as f32);
            let corners = [
                (x0, y0, (1.0 - fx) * (1.0 - fy)),
                (x0 + side, y0, fx * (1.0 - fy)),
                (x0, y0 + side, (1.0 - fx) * fy),
                (x0 + side, y0 + side, fx * fy),
            ];
            let mut f = Fill { pixel: (y * w + x) as u32, ..Default::default() };
            for (j, &(ax, ay, wt)) in corners.iter().enumerate().filter(|(_, c)| c.2 > 0.0) {
                if !valid(ax, ay) {
                    return None;
                }
                (f.from[j], f.weight[j]) = ((ay * w + ax) as u32, wt);
            }
            Some((own, f))
        })
    };
    let rows: Vec<(Vec<(u32, Surface, Vec3, f32)>, Vec<(u32, Fill)>)> = cx.par_map(h, |y| {
        let (mut row, mut fills) = (Vec::new(), Vec::new());
        for x in 0..w {
            let i = (y * w + x) as u32;
            let centre = &centres[y][x];
            if !edge[y][x] {
                match centre.as_ref().map(|c| (c, fill_of(x, y, c))) {
                    Some((_, Some(f))) => fills.push(f),
                    Some(((s, wo, _), None)) => row.push((i, s.clone(), *wo, 1.0)),
                    None => {}
                }
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
        (row, fills)
    })?;
    let mut r = Receivers { width: w, height: h, ..Default::default() };
    let (rows, fills): (Vec<_>, Vec<_>) = rows.into_iter().unzip();
    // Coarser classes first: a filled pixel's corners are gathered or filled before it.
    let mut fills: Vec<(u32, Fill)> = fills.into_iter().flatten().collect();
    fills.sort_by_key(|&(class, f)| (std::cmp::Reverse(class), f.pixel));
    r.fill = fills.into_iter().map(|(_, f)| f).collect();
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

/// The class of pixel (x, y) on the grids of a power-of-two `stride`: the largest m with
/// 2^m ≤ stride dividing both coordinates (the s-grid's pixels are of the top class, always
/// gathered). A pixel of class l is read off the corners of a cell of side 2^m, m > l, which
/// are of class m or more.
fn fill_class(x: usize, y: usize, stride: usize) -> u32 {
    (x | y | stride).trailing_zeros().min(stride.trailing_zeros())
}

/// Pixels with more than one receiver, or one that covers only part of them.
fn edge_pixels(r: &Receivers) -> usize {
    let mut last = None;
    r.pixel.iter().zip(&r.weight).filter(|&(&p, &w)| w < 1.0 && last.replace(p) != Some(p)).count()
}

#[node(category = "pbgi", version = 4, metrics = ["receivers", "edge_pixels", "filled_pct"], outputs = [receivers])]
impl GBuffer {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // At most edge_samples² receivers per pixel, or one fill; the pixel centres' hits and
        // edge flags while it runs.
        let per_pixel = self.edge_samples.clamp(1, 4).pow(2) * Receivers::BYTES_PER_RECEIVER;
        let dims = inputs[0].and_then(|s| s.dims);
        let size = dims
            .map(|[w, h]| relume_core::PortSize { bytes: (w * h * per_pixel.max(Receivers::BYTES_PER_FILL)) as u64, dims: Some([w, h]) });
        let centres = dims.map_or(0, |[w, h]| (w * h * (std::mem::size_of::<Option<(Surface, Vec3, f32)>>() + 1)) as u64);
        relume_core::MemoryEstimate { outputs: vec![size], working: centres }
    }

    fn run(&self, scene: &Scene, accel: &Accel, cx: &RunCtx) -> Result<Receivers, NodeError> {
        if !self.stride.is_power_of_two() {
            return Err(NodeError::param("stride", format!("{} is not 1, 2, 4 or 8", self.stride)));
        }
        let r = gbuffer(scene, accel, self.dielectrics, self.edge_samples, self.stride, cx)?;
        cx.metric("receivers", r.len() as f64);
        cx.metric("edge_pixels", edge_pixels(&r) as f64);
        cx.metric("filled_pct", 100.0 * r.fill.len() as f64 / (r.width * r.height).max(1) as f64);
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
        let r = gbuffer(&scene, &accel, false, k, 1, &RunCtx::new("t", &cancel, None)).unwrap();
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
    fn with_a_stride_smooth_pixels_are_read_off_cells_on_their_own_surface() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let cancel = CancelToken::new();
        let run = |s| gbuffer(&scene, &accel, false, 2, s, &RunCtx::new("t", &cancel, None)).unwrap();
        let every = run(1);
        assert!(every.fill.is_empty());
        let covered = |r: &Receivers| {
            let mut px: Vec<u32> = r.pixel.iter().copied().chain(r.fill.iter().map(|f| f.pixel)).collect();
            px.sort();
            px.dedup();
            px
        };
        let object_at = |r: &Receivers, p: u32| r.pixel.iter().position(|&q| q == p).map(|i| r.object[i]);
        for stride in [2, 4] {
            let r = run(stride);
            assert_eq!(covered(&r), covered(&every), "the same pixels lit, gathered or filled");
            // 16² pixels, a third of them at an edge.
            assert!(r.fill.len() >= 16, "stride {stride}: {} filled", r.fill.len());
            assert!(r.len() + r.fill.len() <= every.len(), "stride {stride}: {} receivers against {}", r.len(), every.len());
            for (k, f) in r.fill.iter().enumerate() {
                let (x, y) = (f.pixel as usize % r.width, f.pixel as usize / r.width);
                assert!(x % stride != 0 || y % stride != 0, "the s-grid is gathered");
                assert!(!r.pixel.contains(&f.pixel), "a filled pixel has no receiver");
                assert!((f.weight.iter().sum::<f32>() - 1.0).abs() < 1e-6, "{:?}", f.weight);
                let own = object_at(&every, f.pixel).expect("lit at stride 1");
                for (&p, _) in f.from.iter().zip(&f.weight).filter(|(_, &w)| w > 0.0) {
                    assert_eq!(object_at(&every, p), Some(own), "read off the pixel's own object");
                    let at: Vec<usize> = (0..r.len()).filter(|&i| r.pixel[i] == p).collect();
                    let earlier = r.fill[..k].iter().any(|g| g.pixel == p);
                    assert!(earlier || (at.len() == 1 && r.weight[at[0]] == 1.0), "read off a whole receiver or a pixel filled before");
                }
            }
        }
    }

    #[test]
    fn a_stride_must_be_a_power_of_two() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        let e = relume_base::testing::run_full::<GBuffer>(
            &[("stride", relume_base::testing::i(3))],
            std::path::Path::new("."),
            vec![Value::new(scene), Value::new(accel)],
        );
        assert!(e.is_err_and(|e| e.to_string().contains("not 1, 2, 4 or 8")));
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
        let run = |d, stride| gbuffer(&scene, &accel, d, 1, stride, &RunCtx::new("t", &cancel, None)).unwrap();
        let (without, with) = (run(false, 1), run(true, 1));
        let on_glass = |r: &Receivers| r.material.iter().filter(|m| matches!(m, Material::Dielectric { .. })).count();
        assert_eq!(on_glass(&without), 0);
        assert!(on_glass(&with) > 20 && with.len() == without.len() + on_glass(&with), "{} {}", with.len(), without.len());
        assert!((0..with.len()).all(|i| with.normal[i].dot(with.wo[i]) > 0.0), "seen from outside");
        let strided = run(true, 4);
        assert!(!strided.fill.is_empty(), "the floor is filled");
        assert_eq!(on_glass(&strided), on_glass(&with), "glass is never filled: what it shows changes fast");
    }

    #[test]
    fn the_node_stops_when_cancelled() {
        let scene = test_scene::spheres();
        let accel = Accel::build(&scene, BuildQuality::Fast);
        cancels_midway::<GBuffer>(&[], vec![Value::new(scene), Value::new(accel)]);
    }
}
