use super::types::{Visibility, VisibilityChunk};
use super::vertices::{ray_offset, vertex_normals};
use glam::Vec3;
use relume_base::math::cubemap::CubeMap;
use relume_base::types::{Accel, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, params, MemoryEstimate, NodeError, PortSize, RunCtx, ShardSpec};
use std::ops::Range;

params! {
    /// Per vertex, the binary visibility of the environment ([S] 5.2.3.1, 5.3.3.3: T⁰, the
    /// visibility function over the 6 × 64 × 64 cube-map directions, stored losslessly as
    /// bitsets): one shadow ray through each texel's centre above the vertex's tangent plane,
    /// from the vertex lifted 10⁻⁴ of the scene's extent along its shading normal; texels below
    /// the plane are not visible (no ray). With it, per texel of a coarse `coarse`² cube map, the
    /// visible cosine-weighted solid angle Σ V (ω · n) Ω over the fine texels it covers: a hit
    /// point's direct light from each box lighting basis, interpolated from its triangle's
    /// vertices ([S] 5.3.3.6). Sharded over vertices (`relume shard`, `--processes`); the same
    /// bytes on any thread count and any sharding. The held bytes are checked against the budget
    /// before anything is allocated.
    ///
    /// Metrics: vertices, rays traced, the mean visible fraction of the upper hemisphere's
    /// texels, bytes.
    pub struct VertexVisibility {
        /// texels along a cube face ([S]: 64)
        pub side: usize = 64, range = 4..=256, test = 8;
        /// texels along a face of the coarse map of the bounce lighting bases ([S] 5.3.3.4: 8)
        pub coarse: usize = 8, range = 1..=64, test = 2;
    }
}

inputs!(pub VertexVisibilityIn { scene: Scene, accel: Accel });
outputs!(pub VertexVisibilityOut { visibility: Visibility });

/// Vertices per chunk of the sharded run.
const CHUNK: u64 = 512;

impl VertexVisibility {
    fn check(&self, scene: &Scene, budget: u64) -> Result<(), NodeError> {
        if !self.side.is_multiple_of(self.coarse) {
            return Err(NodeError::param("coarse", format!("must divide `side` ({}); {} does not", self.side, self.coarse)));
        }
        let bytes = Visibility::bytes_for(scene.positions.len() as u64, self.side as u32, self.coarse as u32);
        if bytes > budget {
            return Err(NodeError::over_limit_param(
                "side",
                format!(
                    "the visibility of {} vertices at 6 × {}² would hold {}, over the {} budget",
                    scene.positions.len(),
                    self.side,
                    fmt_bytes(bytes),
                    fmt_bytes(budget)
                ),
            ));
        }
        Ok(())
    }
}

/// The visibility words and coarse cosine sums of the vertices `range`, with the rays traced.
pub fn visibility_of(
    scene: &Scene,
    accel: &Accel,
    side: usize,
    coarse: usize,
    range: Range<usize>,
    cx: &RunCtx,
) -> Result<(VisibilityChunk, u64), NodeError> {
    let normals = vertex_normals(scene);
    let cube = CubeMap::constant(side, Vec3::ZERO);
    let texels = 6 * side * side;
    let dirs: Vec<Vec3> = (0..texels).map(|k| cube.direction(k)).collect();
    let omega: Vec<f32> = (0..texels).map(|k| cube.solid_angle(k)).collect();
    let coarse_of: Vec<u32> = (0..texels).map(|k| cube.coarse_of(k, coarse) as u32).collect();
    let (words, cells) = (Visibility::words(side as u32), 6 * coarse * coarse);
    let eps = ray_offset(scene);
    let per_vertex = cx.par_map(range.len(), |r| {
        let v = range.start + r;
        let n = normals[v];
        let mut bits = vec![0u32; words];
        let mut sums = vec![0.0f64; cells];
        let mut rays = 0u64;
        if n != Vec3::ZERO {
            let o = scene.positions[v] + n * eps;
            for (k, d) in dirs.iter().enumerate() {
                let c = d.dot(n);
                if c <= 0.0 {
                    continue;
                }
                rays += 1;
                if !accel.occluded(o, *d, eps, f32::INFINITY) {
                    bits[k / 32] |= 1 << (k % 32);
                    sums[coarse_of[k] as usize] += (c * omega[k]) as f64;
                }
            }
        }
        (bits, sums.into_iter().map(|s| s as f32).collect::<Vec<f32>>(), rays)
    })?;
    let mut chunk = VisibilityChunk {
        first: range.start as u64,
        count: range.len() as u64,
        bits: Vec::with_capacity(range.len() * words),
        coarse_cos: Vec::with_capacity(range.len() * cells),
    };
    let mut rays = 0;
    for (b, c, r) in per_vertex {
        chunk.bits.extend(b);
        chunk.coarse_cos.extend(c);
        rays += r;
    }
    Ok((chunk, rays))
}

#[node(category = "ptt", sharded, metrics = ["vertices", "visible_fraction", "bytes"])]
impl VertexVisibility {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        // The vertices are known only from the scene: the node checks its bytes itself.
        let _ = inputs;
        MemoryEstimate { outputs: vec![None], working: CubeMap::bytes_for(self.side) }
    }

    fn shard(&self, i: &VertexVisibilityIn) -> Result<ShardSpec, NodeError> {
        self.check(i.scene, relume_core::limits::default_budget())?;
        Ok(ShardSpec::new(i.scene.positions.len() as u64, CHUNK))
    }

    fn run_items(&self, i: &VertexVisibilityIn, items: Range<u64>, cx: &RunCtx) -> Result<VisibilityChunk, NodeError> {
        self.check(i.scene, cx.memory_budget())?;
        Ok(visibility_of(i.scene, i.accel, self.side, self.coarse, items.start as usize..items.end as usize, cx)?.0)
    }

    fn gather(&self, i: &VertexVisibilityIn, parts: &[&VisibilityChunk], cx: &RunCtx) -> Result<VertexVisibilityOut, NodeError> {
        self.check(i.scene, cx.memory_budget())?;
        let n = i.scene.positions.len();
        let (words, cells) = (Visibility::words(self.side as u32), 6 * self.coarse * self.coarse);
        let mut vis = Visibility {
            n: self.side as u32,
            coarse: self.coarse as u32,
            normals: vertex_normals(i.scene),
            bits: Vec::with_capacity(n * words),
            coarse_cos: Vec::with_capacity(n * cells),
        };
        for p in parts {
            if p.first as usize * words != vis.bits.len()
                || p.bits.len() != p.count as usize * words
                || p.coarse_cos.len() != p.count as usize * cells
            {
                return Err(NodeError::failed(format!(
                    "a chunk of vertices {}..{} does not continue the visibility",
                    p.first,
                    p.first + p.count
                )));
            }
            vis.bits.extend_from_slice(&p.bits);
            vis.coarse_cos.extend_from_slice(&p.coarse_cos);
        }
        if vis.bits.len() != n * words {
            return Err(NodeError::failed(format!("the chunks cover {} of {n} vertices", vis.bits.len() / words.max(1))));
        }
        let upper = 3 * self.side * self.side;
        let visible: u64 = vis.bits.iter().map(|w| w.count_ones() as u64).sum();
        let used = vis.normals.iter().filter(|n| **n != Vec3::ZERO).count();
        cx.metric("vertices", n as f64);
        cx.metric("visible_fraction", if used > 0 { visible as f64 / (used * upper) as f64 } else { 0.0 });
        cx.metric("bytes", Visibility::bytes_for(n as u64, self.side as u32, self.coarse as u32) as f64);
        Ok(VertexVisibilityOut { visibility: vis })
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use relume_base::testing::{i, run_on};
    use relume_base::types::accel::BuildQuality;
    use relume_base::types::{Environment, Material};
    use relume_core::Value;

    /// A 9 × 9-vertex grid from `corner` spanned by `a` and `b`, facing `normal` (the
    /// winding follows it).
    pub(crate) fn grid(corner: Vec3, a: Vec3, b: Vec3, normal: Vec3) -> (Vec<Vec3>, Vec<Vec3>, Vec<[u32; 3]>) {
        let mut pos = vec![];
        let mut tris = vec![];
        for j in 0..9 {
            for k in 0..9 {
                pos.push(corner + a * (k as f32 / 8.0) + b * (j as f32 / 8.0));
            }
        }
        let flip = a.cross(b).dot(normal) > 0.0;
        for j in 0..8u32 {
            for k in 0..8u32 {
                let q = j * 9 + k;
                let (t0, t1) = ([q, q + 1, q + 9], [q + 1, q + 10, q + 9]);
                tris.extend(if flip { [t0, t1] } else { [[t0[0], t0[2], t0[1]], [t1[0], t1[2], t1[1]]] });
            }
        }
        (pos, vec![normal; 81], tris)
    }

    /// A 2 × 2 floor (9 × 9 vertices, ρ 0.5) at y = 0 and, over its +x half and far beyond, a
    /// downward-facing roof (one quad) at height h, under a uniform sky of radiance 1.
    pub(crate) fn floor_and_roof(h: f32) -> Scene {
        let lambert = Material::Lambert { albedo: Vec3::splat(0.5) };
        let (pos, nrm, tris) = grid(Vec3::new(-1.0, 0.0, -1.0), Vec3::X * 2.0, Vec3::Z * 2.0, Vec3::Y);
        relume_base::scene::builder::SceneBuilder::new(Vec3::new(0.0, 3.0, 3.0), Vec3::ZERO, 40.0, 16, 16)
            .mesh("floor", pos, Some(nrm), tris, lambert, Vec3::ZERO)
            .quad("roof", Vec3::new(0.0, h, 50.0), Vec3::new(0.0, 0.0, -100.0), Vec3::new(50.0, 0.0, 0.0), lambert, Vec3::ZERO)
            .environment(Environment::Constant(Vec3::ONE))
            .build()
    }

    /// The floor of `floor_and_roof` under a tessellated roof (9 × 9 vertices, facing down)
    /// over x ∈ [0, 2] at height h: the roof's vertices see the sunlit open floor.
    pub(crate) fn floor_and_tiled_roof(h: f32) -> Scene {
        let lambert = Material::Lambert { albedo: Vec3::splat(0.5) };
        let (pos, nrm, tris) = grid(Vec3::new(-1.0, 0.0, -1.0), Vec3::X * 2.0, Vec3::Z * 2.0, Vec3::Y);
        let (rp, rn, rt) = grid(Vec3::new(0.0, h, -1.0), Vec3::X * 2.0, Vec3::Z * 2.0, Vec3::NEG_Y);
        relume_base::scene::builder::SceneBuilder::new(Vec3::new(0.0, 3.0, 3.0), Vec3::ZERO, 40.0, 16, 16)
            .mesh("floor", pos, Some(nrm), tris, lambert, Vec3::ZERO)
            .mesh("roof", rp, Some(rn), rt, lambert, Vec3::ZERO)
            .environment(Environment::Constant(Vec3::ONE))
            .build()
    }

    pub(crate) fn visibility(s: &Scene, side: i64, coarse: i64) -> Visibility {
        let accel = Accel::build(s, BuildQuality::Fast);
        let out = run_on::<VertexVisibility>(&[("side", i(side)), ("coarse", i(coarse))], vec![Value::new(s.clone()), Value::new(accel)])
            .expect("runs");
        relume_base::testing::first(&out)
    }

    #[test]
    fn an_open_vertex_sees_its_hemisphere_and_a_roofed_one_the_open_side_only() {
        let s = floor_and_roof(0.5);
        let v = visibility(&s, 16, 4);
        assert_eq!(v.vertices(), 81 + 4);
        let cube = CubeMap::constant(16, Vec3::ZERO);
        // Vertex 0 at (−1, 0, −1): the roof starts 1 to its +x at height 0.5, so a direction
        // with x/y > 2 is open; far-left vertex sees the whole sky above x/y < 2.
        for k in 0..6 * 256 {
            let d = cube.direction(k);
            let open = d.y > 0.0 && (d.x <= 0.0 || d.x / d.y < 1.0 / 0.5 - 1e-3);
            let blocked = d.y <= 0.0 || (d.x > 0.0 && d.x / d.y > 1.0 / 0.5 + 1e-3);
            if open {
                assert!(v.visible(0, k), "texel {k} {d:?} should be open");
            }
            if blocked {
                assert!(!v.visible(0, k), "texel {k} {d:?} should be blocked");
            }
        }
        // The coarse cosine sums add up to the visible cosine-weighted solid angle; for a
        // vertex under the roof (x = 0.5) and the unroofed one the projected solid angle is
        // at most π, and the unroofed floor edge sees more.
        let total = |v: &Visibility, i: usize| v.coarse_of(i).iter().map(|c| *c as f64).sum::<f64>();
        let open = total(&v, 0);
        let covered = total(&v, 4 * 9 + 6);
        assert!(open <= std::f64::consts::PI * 1.0001 && covered < open, "{open} {covered}");
        // The roof's vertices face down: no bit above them, and the sky below past the
        // small floor is open to them.
        assert!((0..6 * 256).all(|k| cube.direction(k).y < 0.0 || !v.visible(81, k)));
        assert!((0..6 * 256).any(|k| v.visible(81, k)));
    }

    #[test]
    fn an_unoccluded_vertex_has_projected_solid_angle_pi() {
        let s = floor_and_roof(1.0e3);
        let v = visibility(&s, 32, 8);
        // Under a roof 1000 high the floor vertices see their hemisphere up to the texels
        // whose centres pass under the roof's edge ~1000 away: ∫ cos dω = π within 1 %.
        let sum: f64 = v.coarse_of(40).iter().map(|c| *c as f64).sum();
        assert!((sum / std::f64::consts::PI - 1.0).abs() < 0.01, "{sum}");
        // Bits only above the tangent plane: the upper hemisphere's 3 × 32² texels less the
        // few the roof cuts.
        let bits: u32 = v.of(40).iter().map(|w| w.count_ones()).sum();
        let cut = cut_by_roof(&v, 40);
        assert_eq!(bits as usize, 3 * 32 * 32 - cut);
        assert!(cut < 20, "{cut}");
    }

    /// Upper-hemisphere texels of vertex `i` that the roof blocks (their bits clear).
    fn cut_by_roof(v: &Visibility, i: usize) -> usize {
        let cube = CubeMap::constant(v.n as usize, Vec3::ZERO);
        (0..cube.texels.len()).filter(|&k| cube.direction(k).dot(Vec3::Y) > 0.0 && !v.visible(i, k)).count()
    }

    #[test]
    fn the_same_bytes_on_any_thread_count_and_bad_settings_are_refused() {
        let s = floor_and_roof(0.5);
        let v = visibility(&s, 8, 2);
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("pool").install(|| visibility(&s, 8, 2));
        assert_eq!(one, v);
        use relume_core::PortValue;
        assert_eq!(Visibility::decode(&v.encode()).as_ref(), Some(&v));
        let accel = Accel::build(&s, BuildQuality::Fast);
        let e = run_on::<VertexVisibility>(&[("side", i(16)), ("coarse", i(3))], vec![Value::new(s.clone()), Value::new(accel)])
            .expect_err("refused");
        assert!(e.to_string().contains("must divide"), "{e}");
    }
}
