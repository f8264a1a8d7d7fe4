use super::screen_hits::ScreenHits;
use super::types::VertexColors;
use glam::Vec3;
use relume_base::types::{Image, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{node, params, NodeError, PortSize, RunCtx};

params! {
    /// Renders per-vertex radiance to an image ([S] chapter 5: the transfer tensors relight the
    /// vertices, and each pixel interpolates them): each pixel is the environment of `scene`
    /// seen where its missing samples look, times their fraction (black with `background`
    /// off; a band's sky directions are turned into lat-long coordinates together, through a
    /// polynomial atan2 within 3.2e-7 rad of the library's, which halved this node's time on
    /// envlit), plus the vertices' colours weighted as `CameraHits` found them (the samples'
    /// barycentrics over the samples per pixel, antialiased with its box filter), summed in the
    /// hits' order: the same bytes on any thread count. The camera and the samples live in
    /// `hits`, so a colour or sky edit re-runs only this weighted sum (wire the turned sky's
    /// scene here, the loaded one into `CameraHits`). Shading per vertex is the thesis' choice; what
    /// interpolation loses across shadow edges on coarse meshes is part of the method's error,
    /// measured against a vertex-sampled reference elsewhere. The image's bytes are checked
    /// against the budget before it is allocated. Where the colours have a `textured` part
    /// (fixed objects whose albedo is a texture map, `PttRelight`), each pixel adds that part
    /// interpolated like the colours times the object's map at the UV interpolated with the
    /// same weights: shading per vertex, texture per pixel (one lookup a pixel and object, so
    /// a map finer than the pixels aliases where the path tracer averages it).
    ///
    /// Metrics: the vertex weights summed.
    pub struct RasterizeVertexColors {
        /// samples that miss the geometry see the environment (else black)
        pub background: bool = true;
    }
}

/// Objects a pixel's texture lookups tell apart (more, at a pixel where more textured
/// objects meet, share the last one's coordinates).
const TEXTURED_PER_PIXEL: usize = 4;

/// What applies the colours' `textured` part: per vertex its object, and the scene's UVs and
/// maps.
struct Textured<'a> {
    scene: &'a Scene,
    part: &'a [Vec3],
    object: Vec<u32>,
}

impl<'a> Textured<'a> {
    /// `None` when nothing is textured; an input error when the part does not fit the scene.
    fn of(scene: &'a Scene, colors: &'a VertexColors) -> Result<Option<Textured<'a>>, NodeError> {
        if colors.textured.is_empty() {
            return Ok(None);
        }
        let n = scene.positions.len();
        if colors.textured.len() != n || scene.uvs.len() != n {
            return Err(NodeError::input(
                "colors",
                format!(
                    "has a textured part of {} vertices for a scene of {n} with {} UVs: they must come from the same scene",
                    colors.textured.len(),
                    scene.uvs.len()
                ),
            ));
        }
        let mut object = vec![u32::MAX; n];
        for (tri, &o) in scene.triangles.iter().zip(&scene.tri_object) {
            tri.iter().for_each(|&v| object[v as usize] = o);
        }
        Ok(Some(Textured { scene, part: &colors.textured, object }))
    }

    /// A pixel's textured radiance from its hits: per object, the textured part and the UV
    /// interpolated with the hits' weights, the part times the object's map at that UV.
    fn pixel(&self, vertices: &[u32], weights: &[f32]) -> Vec3 {
        // (object, Σ w, Σ w uv, Σ w part)
        let mut acc: [(u32, f32, glam::Vec2, Vec3); TEXTURED_PER_PIXEL] =
            [(u32::MAX, 0.0, glam::Vec2::ZERO, Vec3::ZERO); TEXTURED_PER_PIXEL];
        for (&v, &w) in vertices.iter().zip(weights) {
            let part = self.part[v as usize];
            if part == Vec3::ZERO {
                continue;
            }
            let o = self.object[v as usize];
            let k = acc.iter().position(|a| a.0 == o || a.0 == u32::MAX).unwrap_or(TEXTURED_PER_PIXEL - 1);
            let a = &mut acc[k];
            *a = (o, a.1 + w, a.2 + self.scene.uvs[v as usize] * w, a.3 + part * w);
        }
        let mut sum = Vec3::ZERO;
        for &(o, w, uv, part) in acc.iter().take_while(|a| a.0 != u32::MAX) {
            let map = self.scene.objects.get(o as usize).and_then(|obj| obj.maps.kd.as_ref());
            sum += match map {
                Some(m) if w > 0.0 => part * m.lookup(uv / w),
                _ => part,
            };
        }
        sum
    }
}

#[node(category = "ptt", version = 4, caching = Keyed, metrics = ["weights"], outputs = [image])]
impl RasterizeVertexColors {
    fn run(&self, hits: &ScreenHits, colors: &VertexColors, scene: &Scene, cx: &RunCtx) -> Result<Image, NodeError> {
        let (hits, colors_in, colors) = (hits, colors, &colors.colors);
        if colors.len() != hits.vertices as usize {
            return Err(NodeError::input(
                "colors",
                format!("holds {} colours but the hits' scene has {} vertices (one colour per vertex)", colors.len(), hits.vertices),
            ));
        }
        let (w, h) = (hits.width as usize, hits.height as usize);
        let bytes = PortSize::image(w, h).bytes;
        if bytes > cx.memory_budget() {
            return Err(NodeError::over_limit(format!(
                "the image of {w} × {h} pixels would hold {}, over the {} budget",
                fmt_bytes(bytes),
                fmt_bytes(cx.memory_budget())
            )));
        }
        let textured = Textured::of(scene, colors_in)?;
        let mut image = Image::try_new(w, h)?;
        cx.par_chunks_mut(&mut image.pixels, w * 8, |band, px| {
            let first = band * w * 8;
            // The sky of the band's pixels with missing samples, looked up together.
            let (mut missing, mut dirs, mut sky) = (Vec::new(), Vec::new(), Vec::new());
            if self.background {
                for p in first..first + px.len() {
                    if hits.miss[p] > 0.0 {
                        missing.push(p);
                        dirs.push(hits.miss_dir[p]);
                    }
                }
                scene.environment_radiance_many_fast(&dirs, &mut sky);
            }
            let mut sky_of = missing.iter().zip(&sky).peekable();
            for (k, out) in px.iter_mut().enumerate() {
                let p = first + k;
                let r = hits.offsets[p] as usize..hits.offsets[p + 1] as usize;
                let mut sum = match sky_of.next_if(|(&m, _)| m == p) {
                    Some((_, l)) => *l * hits.miss[p],
                    None => Vec3::ZERO,
                };
                for (v, wt) in hits.vertex[r.clone()].iter().zip(&hits.weight[r.clone()]) {
                    sum += colors[*v as usize] * *wt;
                }
                if let Some(t) = &textured {
                    sum += t.pixel(&hits.vertex[r.clone()], &hits.weight[r]);
                }
                *out = sum.to_array();
            }
        })?;
        cx.metric("weights", hits.weight.len() as f64);
        Ok(image)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera_hits::CameraHits;
    use glam::Vec3;
    use relume_base::render::camera::CameraRays;
    use relume_base::render::zbuffer::sample_pattern;
    use relume_base::scene::builder::SceneBuilder;
    use relume_base::testing::{cancels_midway, first, i, run_on};
    use relume_base::types::accel::BuildQuality;
    use relume_base::types::{Accel, Environment, Material, Scene};
    use relume_core::{ParamValue, PortValue, Value};

    const SKY: Vec3 = Vec3::new(0.2, 0.3, 0.4);
    const BLACK: Material = Material::Lambert { albedo: Vec3::ZERO };

    /// A 32² camera at z = 3 looking down −z (fov 40°) under a constant sky.
    fn camera() -> SceneBuilder {
        SceneBuilder::new(Vec3::new(0.0, 0.0, 3.0), Vec3::ZERO, 40.0, 32, 32).environment(Environment::Constant(SKY))
    }

    /// A quad in the plane z = 0 facing the camera, from x = `x0` rightwards past the view.
    fn right_of(x0: f32) -> Scene {
        camera().quad("q", Vec3::new(x0, -5.0, 0.0), Vec3::new(10.0, 0.0, 0.0), Vec3::new(0.0, 10.0, 0.0), BLACK, Vec3::ZERO).build()
    }

    fn hits(s: &Scene, params: &[(&str, ParamValue)]) -> ScreenHits {
        first(&run_on::<CameraHits>(params, vec![Value::new(s.clone()), Value::new(s.camera.clone())]).expect("hits"))
    }

    /// The image of `colors` on `s`: `params` for `CameraHits`, except `background`, which
    /// is the rasteriser's.
    fn raster(s: &Scene, colors: Vec<Vec3>, params: &[(&str, ParamValue)]) -> Image {
        let (own, hit): (Vec<_>, Vec<_>) = params.iter().cloned().partition(|(k, _)| *k == "background");
        let inputs = vec![Value::new(hits(s, &hit)), Value::new(VertexColors::plain(colors)), Value::new(s.clone())];
        first(&run_on::<RasterizeVertexColors>(&own, inputs).expect("runs"))
    }

    fn close(a: [f32; 3], b: Vec3, tol: f32) -> bool {
        (Vec3::from_array(a) - b).abs().max_element() <= tol
    }

    #[test]
    fn constant_colours_fill_the_covered_pixels_and_the_sky_the_rest() {
        let s = camera().sphere("ball", Vec3::ZERO, 0.6, BLACK, Vec3::ZERO, false).build();
        let c = Vec3::new(1.0, 0.5, 0.25);
        let n = s.positions.len();
        let img = raster(&s, vec![c; n], &[("spp", i(1))]);
        let covered = img.pixels.iter().filter(|p| close(**p, c, 1e-6)).count();
        let sky = img.pixels.iter().filter(|p| **p == SKY.to_array()).count();
        assert_eq!(covered + sky, 32 * 32, "every pixel is the colour or the sky");
        assert!(covered > 100 && sky > 100, "{covered} {sky}");
        assert!(close(img.get(16, 16), c, 1e-6) && img.get(0, 0) == SKY.to_array());
        // Without the background the sky is black; with many samples each pixel mixes the two.
        let dark = raster(&s, vec![c; n], &[("spp", i(1)), ("background", ParamValue::Bool(false))]);
        assert!(dark.pixels.iter().all(|p| close(*p, c, 1e-6) || *p == [0.0; 3]));
        let aa = raster(&s, vec![c; n], &[("spp", i(16))]);
        for p in &aa.pixels {
            let a = (p[0] - SKY.x) / (c.x - SKY.x);
            assert!((-1e-5..=1.0 + 1e-5).contains(&a) && close(*p, SKY + (c - SKY) * a, 1e-5), "{p:?}");
        }
    }

    #[test]
    fn a_linear_function_at_the_vertices_comes_back_linear() {
        // A tilted, coarsely tessellated sheet (5 × 5 vertices) with f(p) = a + M p stored at
        // its vertices: every sample must see f at its own hit point (found here by tracing
        // the sample's ray), so every pixel is the mean of f (or the sky) over the samples.
        let mut pos = vec![];
        let mut tris = vec![];
        for j in 0..5u32 {
            for k in 0..5u32 {
                let (x, y) = (-1.0 + 0.5 * k as f32, -1.0 + 0.5 * j as f32);
                pos.push(Vec3::new(x, y, -0.6 * x + 0.3 * y));
                if j < 4 && k < 4 {
                    let a = j * 5 + k;
                    tris.push([a, a + 1, a + 6]);
                    tris.push([a, a + 6, a + 5]);
                }
            }
        }
        let s = camera().mesh("sheet", pos, None, tris, BLACK, Vec3::ZERO).build();
        let f = |p: Vec3| Vec3::new(0.5 + 0.3 * p.x, 0.4 + 0.2 * p.y - 0.1 * p.z, 0.6 - 0.15 * p.x + 0.25 * p.z);
        let colors: Vec<Vec3> = s.positions.iter().map(|p| f(*p)).collect();
        let (spp, seed) = (4, 9);
        let img = raster(&s, colors, &[("spp", i(spp)), ("seed", i(seed))]);
        let accel = Accel::build(&s, BuildQuality::Fast);
        let cam = CameraRays::new(&s.camera);
        let pattern = sample_pattern(spp as u32, seed as u64);
        let (mut worst, mut interior) = (0.0f32, 0);
        for y in 0..32 {
            for x in 0..32 {
                let mut want = Vec3::ZERO;
                let mut all_hit = true;
                for &(ox, oy) in &pattern {
                    let (o, d) = cam.ray(x as f32 + ox, y as f32 + oy);
                    want += match accel.intersect(o, d, 0.0, f32::INFINITY) {
                        Some(hit) => f(o + d * hit.t),
                        None => {
                            all_hit = false;
                            SKY
                        }
                    };
                }
                want /= spp as f32;
                let err = (Vec3::from_array(img.get(x, y)) - want).abs().max_element();
                worst = worst.max(err);
                interior += all_hit as usize;
            }
        }
        eprintln!("linear: {interior} interior pixels, worst error {worst:e}");
        assert!(interior > 300, "{interior}");
        assert!(worst < 1e-5, "{worst}");
    }

    #[test]
    fn a_quad_over_half_the_view_covers_half_the_pixels_and_an_edge_antialiases() {
        // The quad's edge x = 0 projects onto the image's centre line: columns 16.. are
        // covered and 0..16 not, whatever the samples.
        let c = Vec3::new(0.9, 0.1, 0.1);
        let img = raster(&right_of(0.0), vec![c; 4], &[("spp", i(1))]);
        for y in 0..32 {
            for x in 0..32 {
                let want = if x >= 16 { c } else { SKY };
                assert!(close(img.get(x, y), want, 1e-6), "({x}, {y}): {:?}", img.get(x, y));
            }
        }
        // An edge at image x = 20.5 covers half of column 20: with 16 samples per pixel
        // (one in each sixteenth of the pixel's width) exactly 8 of them.
        let half = 3.0 * (20f32.to_radians()).tan();
        let img = raster(&right_of(half * (2.0 * 20.5 / 32.0 - 1.0)), vec![c; 4], &[("spp", i(16)), ("seed", i(3))]);
        for y in 0..32 {
            assert!(close(img.get(20, y), (c + SKY) * 0.5, 1e-5), "{:?}", img.get(20, y));
            assert!(close(img.get(19, y), SKY, 1e-6) && close(img.get(21, y), c, 1e-6));
        }
    }

    #[test]
    fn a_textured_part_is_multiplied_by_the_map_at_each_pixels_uv_and_the_rest_added() {
        use relume_base::types::{MaterialMaps, Texture};
        // The right half of the view, UVs linear in position, a 16² map of (u, v, 0.5) ramps.
        let mut s = right_of(0.0);
        let uv = |p: Vec3| glam::Vec2::new(p.x / 1.1, (p.y + 1.1) / 2.2);
        s.uvs = s.positions.iter().map(|p| uv(*p)).collect();
        let tex = Texture::new(16, 16, (0..256).map(|k| Vec3::new((k % 16) as f32 / 16.0, (k / 16) as f32 / 16.0, 0.5)).collect());
        s.objects[0].maps = Box::new(MaterialMaps { kd: tex.clone(), ..Default::default() });
        let (part, rest) = (Vec3::new(2.0, 1.0, 4.0), Vec3::new(0.1, 0.2, 0.3));
        let colors = VertexColors { colors: vec![rest; 4], textured: vec![part; 4] };
        let sample = [("spp", i(1)), ("seed", i(9))];
        let inputs = vec![Value::new(hits(&s, &sample)), Value::new(colors), Value::new(s.clone())];
        let img: Image = first(&run_on::<RasterizeVertexColors>(&[], inputs).expect("runs"));
        let (ox, oy) = sample_pattern(1, 9)[0];
        let (accel, cam, tex) = (Accel::build(&s, BuildQuality::Fast), CameraRays::new(&s.camera), tex.expect("texture"));
        let mut textured = 0;
        for y in 0..32 {
            for x in 16..32 {
                let (o, d) = cam.ray(x as f32 + ox, y as f32 + oy);
                let hit = accel.intersect(o, d, 0.0, f32::INFINITY).expect("the quad");
                let want = rest + part * tex.lookup(uv(o + d * hit.t));
                assert!(close(img.get(x, y), want, 1e-4), "({x}, {y}): {:?} against {want}", img.get(x, y));
                textured += 1;
            }
        }
        assert_eq!(textured, 512);
        // A textured part of another length is refused.
        let wrong = VertexColors { colors: vec![rest; 4], textured: vec![part; 3] };
        let e = run_on::<RasterizeVertexColors>(&[], vec![Value::new(hits(&s, &sample)), Value::new(wrong), Value::new(s)]);
        assert!(e.is_err());
    }

    #[test]
    fn the_same_bytes_on_one_and_two_threads() {
        let s = camera().sphere("ball", Vec3::new(0.2, 0.1, 0.0), 0.7, BLACK, Vec3::ZERO, false).build();
        let colors: Vec<Vec3> = s.positions.iter().map(|p| Vec3::new(p.x.abs(), p.y * p.y, 0.3 + 0.1 * p.z)).collect();
        let on = |t| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(t).build().expect("pool");
            pool.install(|| raster(&s, colors.clone(), &[("spp", i(8)), ("seed", i(5))]))
        };
        let (one, two) = (on(1), on(2));
        assert_eq!(bytemuck::cast_slice::<f32, u8>(one.as_floats()), bytemuck::cast_slice::<f32, u8>(two.as_floats()));
    }

    #[test]
    fn a_wrong_colour_count_and_an_oversized_image_are_refused() {
        let s = right_of(0.0);
        let h = hits(&s, &[("spp", i(1))]);
        let colors = |n| Value::new(VertexColors::plain(vec![Vec3::ONE; n]));
        let e = run_on::<RasterizeVertexColors>(&[], vec![Value::new(h.clone()), colors(3), Value::new(s.clone())]).expect_err("refused");
        assert!(e.to_string().contains('3') && e.to_string().contains("4 vertices"), "{e}");
        let mut big = h;
        (big.width, big.height) = (1 << 20, 1 << 20);
        let e = run_on::<RasterizeVertexColors>(&[], vec![Value::new(big), colors(4), Value::new(s)]).expect_err("refused");
        assert!(e.is_over_limit() && e.to_string().contains("1048576 × 1048576"), "{e}");
    }

    #[test]
    fn the_node_stops_midway_when_cancelled() {
        let mut s = camera().sphere("ball", Vec3::ZERO, 0.6, BLACK, Vec3::ZERO, false).build();
        (s.camera.width, s.camera.height) = (512, 512);
        let n = s.positions.len();
        let h = hits(&s, &[("spp", i(1))]);
        assert!(h.byte_size() > 0);
        cancels_midway::<RasterizeVertexColors>(
            &[],
            vec![Value::new(h), Value::new(VertexColors::plain(vec![Vec3::ONE; n])), Value::new(s)],
        );
    }

    #[test]
    fn a_mapped_sky_is_the_maps_radiance_where_the_samples_miss() {
        // A 64 × 32 map of noise; black vertices, so that each pixel is its missed fraction
        // of the sky in the direction of its missed samples.
        let texels = (0..64 * 32).map(|k| Vec3::new(1.0 + (k % 7) as f32, 1.0 + (k % 5) as f32, 1.0 + (k % 3) as f32)).collect();
        let mut s = camera().sphere("ball", Vec3::ZERO, 0.6, BLACK, Vec3::ZERO, false).build();
        s.environment = Some(Environment::Map(relume_base::types::EnvMap::new(64, 32, texels).unwrap()));
        let h = hits(&s, &[("spp", i(4))]);
        let inputs =
            vec![Value::new(h.clone()), Value::new(VertexColors::plain(vec![Vec3::ZERO; s.positions.len()])), Value::new(s.clone())];
        let img: Image = first(&run_on::<RasterizeVertexColors>(&[], inputs).expect("runs"));
        let mut sky = 0;
        for p in 0..32 * 32 {
            let want = s.environment_radiance(h.miss_dir[p]) * h.miss[p];
            assert!(close(img.pixels[p], want, 1e-4), "pixel {p}: {:?} against {want}", img.pixels[p]);
            sky += (h.miss[p] > 0.0) as usize;
        }
        assert!(sky > 100, "{sky} pixels see the sky");
    }

    #[test]
    fn another_sky_on_the_same_hits_changes_only_what_the_misses_see() {
        // The hits of the loaded scene, rasterised under a sky four times as bright with a
        // blue band: covered samples keep their colours, the missed ones see the new sky.
        let s = camera().sphere("ball", Vec3::ZERO, 0.6, BLACK, Vec3::ZERO, false).build();
        let h = hits(&s, &[("spp", i(4))]);
        let colors = vec![Vec3::new(1.0, 0.5, 0.25); s.positions.len()];
        let with = |scene: &Scene| -> Image {
            let inputs = vec![Value::new(h.clone()), Value::new(VertexColors::plain(colors.clone())), Value::new(scene.clone())];
            first(&run_on::<RasterizeVertexColors>(&[], inputs).expect("runs"))
        };
        let mut bright = s.clone();
        bright.environment = Some(Environment::Constant(SKY * 4.0));
        let (a, b) = (with(&s), with(&bright));
        let mut mixed = 0;
        for p in 0..32 * 32 {
            let (x, y) = (p % 32, p / 32);
            let (pa, pb) = (Vec3::from_array(a.get(x, y)), Vec3::from_array(b.get(x, y)));
            // The difference is three times the old sky's share of the pixel.
            assert!(((pb - pa) - SKY * 3.0 * h.miss[p]).abs().max_element() < 1e-5, "({x}, {y})");
            mixed += (h.miss[p] > 0.0 && h.miss[p] < 1.0) as usize;
        }
        assert!(mixed > 10, "{mixed} pixels on the ball's edge");
    }
}
