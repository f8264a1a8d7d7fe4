use super::bounce::SH;
use super::channels::Channels;
use super::types::BounceTransfer;
use super::types::Visibility;
use super::vertices::ray_offset;
use crate::types::TwoBounce;
use glam::Vec3;
use relume_base::math::cubemap::CubeMap;
use relume_base::math::sh::{sh_basis_into, sh_clamped_cosine};
use relume_base::types::{Accel, BrdfBasis, BrdfGrid, Material, Scene};
use relume_core::memory::fmt_bytes;
use relume_core::{inputs, node, outputs, params, NodeError, PortValue, RunCtx, ShardSpec};
use std::f32::consts::PI;
use std::ops::Range;

params! {
    /// The two-bounce transfer T²(l, c₁, c₂) of every vertex ([S] 5-10, 5-11, 5.3.3.5): a scalar
    /// per box lighting basis l of a coarse 6 × `side`² cube map (box sums of `TransferT1`'s
    /// bases, [S]: 6 × 2 × 2), first reflector channel c₁ and second reflector channel c₂: the
    /// incident radiance after two reflections, taken as uniform over the hemisphere ([S]: "假设
    /// …均匀分布"), i.e. (1/π) ∫ I² cos dω. Rays leave each vertex through the centres of a
    /// 6 × `rays_side`² cube map above its tangent plane; at a hit y, the one-bounce transfer of
    /// the hit triangle's vertices (rebuilt from their clusters at the coarse lighting,
    /// interpolated barycentrically: [S] 5.3.3.6, "T¹ speeds up T²") is reflected toward the
    /// vertex by y's channel: exactly for diffuse ones (the clamped cosine in SH), and for a
    /// basis BRDF's specular part by its directional albedo times the incident light at the
    /// mirror direction (the one-bounce light is 4-band SH, far smoother than the lobes; stated
    /// approximation). Fixed objects must be Lambertian here (others are refused, not guessed).
    /// Sharded over vertices; the same bytes on any sharding and thread count.
    ///
    /// Metrics: bytes, channels, lighting bases.
    pub struct TransferT2 {
        /// texels along a face of the coarse lighting map ([S]: 2); must divide T¹'s side
        pub side: usize = 2, range = 1..=64, test = 1;
        /// texels along a face of the cube map whose centres the rays go through
        pub rays_side: usize = 8, range = 2..=64, test = 2;
    }
}

inputs!(pub TransferT2In { scene: Scene, accel: Accel, visibility: Visibility, basis: BrdfBasis, bounce: BounceTransfer });
outputs!(pub TransferT2Out { transfer: TwoBounce });

/// Vertices per chunk (each chunk rebuilds the coarse one-bounce transfer of every vertex).
const CHUNK: u64 = 8192;

/// θo bins of the basis BRDFs' directional albedo.
const ALBEDO_BINS: usize = 32;

/// Per vertex, the one-bounce transfer box-summed to side `side` (6 side² × S floats each).
pub fn coarse_bounce(t1: &BounceTransfer, side: usize, vertices: usize) -> Vec<f32> {
    let (m, s) = (t1.coarse as usize, t1.channels() * SH);
    let fine = CubeMap::constant(m, Vec3::ZERO);
    let (l, l2) = (6 * m * m, 6 * side * side);
    let mut out = vec![0.0f32; vertices * l2 * s];
    for (tensor, members) in t1.clusters.iter().zip(&t1.plan.members) {
        let (rv, rl) = (tensor.rank_v as usize, tensor.rank_l as usize);
        // B'(b, l2) = Σ_{l in l2} B(b, l); G2(a, l2, ·) = Σ_b G(a, b, ·) B'(b, l2).
        let mut bsum = vec![0.0f32; rl * l2];
        for b in 0..rl {
            for k in 0..l {
                bsum[b * l2 + fine.coarse_of(k, side)] += tensor.b[b * l + k];
            }
        }
        let mut g2 = vec![0.0f32; rv * l2 * s];
        for a in 0..rv {
            for b in 0..rl {
                let g = &tensor.core[(a * rl + b) * s..(a * rl + b + 1) * s];
                for q in 0..l2 {
                    let w = bsum[b * l2 + q];
                    g2[(a * l2 + q) * s..(a * l2 + q + 1) * s].iter_mut().zip(g).for_each(|(o, x)| *o += w * x);
                }
            }
        }
        for (k, &v) in members.iter().enumerate() {
            let row = &mut out[v as usize * l2 * s..(v as usize + 1) * l2 * s];
            for a in 0..rv {
                let w = tensor.a[k * rv + a];
                row.iter_mut().zip(&g2[a * l2 * s..(a + 1) * l2 * s]).for_each(|(o, x)| *o += w * x);
            }
        }
    }
    out
}

/// Directional albedo ∫ f_p(ωi, ωo) cos θi dωi of each basis BRDF over θo bins, by a
/// midpoint rule on 32 × 64 (θi, φ) cells.
fn basis_albedo(basis: &BrdfBasis) -> Vec<[f32; ALBEDO_BINS]> {
    let (nt, np) = (32usize, 64usize);
    (0..basis.bases())
        .map(|p| {
            std::array::from_fn(|b| {
                let to = (b as f64 + 0.5) / ALBEDO_BINS as f64 * std::f64::consts::FRAC_PI_2;
                let mut sum = 0.0f64;
                for i in 0..nt {
                    let ti = (i as f64 + 0.5) / nt as f64 * std::f64::consts::FRAC_PI_2;
                    for j in 0..np {
                        let phi = (j as f64 + 0.5) / np as f64 * 2.0 * std::f64::consts::PI;
                        let (wi, wo) = BrdfGrid::directions(ti, to, phi);
                        let f = basis.grid.trilinear(wi.as_vec3(), wo.as_vec3()).map_or(0.0, |t| t.apply(basis.table(p)));
                        let d_omega = ti.sin() * (std::f64::consts::FRAC_PI_2 / nt as f64) * (2.0 * std::f64::consts::PI / np as f64);
                        sum += f * ti.cos() * d_omega;
                    }
                }
                sum as f32
            })
        })
        .collect()
}

impl TransferT2 {
    fn check(&self, i: &TransferT2In, budget: u64) -> Result<Channels, NodeError> {
        let ch = Channels::new(i.scene, i.basis.bases()).map_err(|m| NodeError::input("scene", m))?;
        if let Some(o) = i.scene.objects.iter().find(|o| !o.dynamic && !matches!(o.material, Material::Lambert { .. })) {
            return Err(NodeError::input("scene", format!("fixed object \"{}\" is not Lambertian: the two-bounce transfer reflects fixed objects diffusely only (make it dynamic, or pass the scene through GlossyAsDynamic)", o.name)));
        }
        let t1 = i.bounce;
        if t1.channels() != ch.count() || t1.plan.vertices() != i.scene.positions.len() {
            return Err(NodeError::input("bounce", "the one-bounce transfer is not of this scene and basis"));
        }
        if !(t1.coarse as usize).is_multiple_of(self.side) {
            return Err(NodeError::param(
                "side",
                format!("must divide the one-bounce lighting side {}; {} does not", t1.coarse, self.side),
            ));
        }
        let n = i.scene.positions.len() as u64;
        let coarse = n * 6 * (self.side as u64).pow(2) * (ch.count() * SH) as u64 * 4;
        let out = n * 6 * (self.side as u64).pow(2) * (ch.count() as u64).pow(2) * 4;
        if coarse + out > budget {
            return Err(NodeError::over_limit(format!(
                "the two-bounce transfer would hold {} (with the coarse one-bounce rows), over the {} budget",
                fmt_bytes(coarse + out),
                fmt_bytes(budget)
            )));
        }
        Ok(ch)
    }
}

#[node(category = "ptt", sharded, metrics = ["bytes", "channels", "lighting_bases"])]
impl TransferT2 {
    fn shard(&self, i: &TransferT2In) -> Result<ShardSpec, NodeError> {
        self.check(i, relume_core::limits::default_budget())?;
        Ok(ShardSpec::new(i.scene.positions.len() as u64, CHUNK))
    }

    fn run_items(&self, i: &TransferT2In, items: Range<u64>, cx: &RunCtx) -> Result<TwoBounce, NodeError> {
        let ch = self.check(i, cx.memory_budget())?;
        let (scene, vis) = (i.scene, i.visibility);
        let n = scene.positions.len();
        cx.phase(0.0, 0.2);
        let rows = coarse_bounce(i.bounce, self.side, n);
        let albedo = basis_albedo(i.basis);
        cx.phase(0.2, 1.0);
        let (cc, l2) = (ch.count(), 6 * self.side * self.side);
        let (s_len, stride) = (l2 * cc * SH, l2 * cc * cc);
        let cube = CubeMap::constant(self.rays_side, Vec3::ZERO);
        let rays: Vec<(Vec3, f32)> = (0..cube.texels.len()).map(|k| (cube.direction(k), cube.solid_angle(k))).collect();
        let eps = ray_offset(scene);
        let per_vertex = cx.par_map((items.end - items.start) as usize, |r| {
            let v = items.start as usize + r;
            let mut out = vec![0.0f32; stride];
            let nv = vis.normals[v];
            if nv == Vec3::ZERO {
                return (out, 0u64);
            }
            let o = scene.positions[v] + nv * eps;
            let (mut t1y, mut rho, mut y) = (vec![0.0f32; s_len], vec![[0.0f32; SH]; cc], [0.0f32; SH]);
            let mut count = 0u64;
            for &(d, omega) in &rays {
                let c = d.dot(nv);
                if c <= 0.0 {
                    continue;
                }
                count += 1;
                let Some(hit) = i.accel.intersect(o, d, eps, f32::INFINITY) else { continue };
                let tri = scene.triangles[hit.tri as usize];
                let b = [1.0 - hit.b1 - hit.b2, hit.b1, hit.b2];
                let ny = (0..3).map(|k| vis.normals[tri[k] as usize] * b[k]).sum::<Vec3>().normalize_or_zero();
                let wo = -d;
                let cos_o = ny.dot(wo);
                if cos_o <= 0.0 {
                    continue;
                }
                t1y.fill(0.0);
                for k in 0..3 {
                    let row = &rows[tri[k] as usize * s_len..(tri[k] as usize + 1) * s_len];
                    t1y.iter_mut().zip(row).for_each(|(a, x)| *a += b[k] * x);
                }
                // ρ_c(ωo) in SH for the channels of y's object.
                let object = scene.tri_object[hit.tri as usize] as usize;
                let chans = ch.of_object(object);
                let cosine = sh_clamped_cosine(4, ny);
                let mirror = (2.0 * cos_o * ny - wo).normalize_or_zero();
                sh_basis_into(mirror, &mut y);
                let bin = ((cos_o.clamp(0.0, 1.0).acos() / std::f32::consts::FRAC_PI_2 * ALBEDO_BINS as f32) as usize).min(ALBEDO_BINS - 1);
                // Each channel's reflectance toward the vertex: a fixed object's albedo at the
                // hit (its maps applied there); a dynamic group's basis p, a textured group's
                // diffuse basis spread over r, g, b channels times its map's colours there.
                let group = ch.object_group[object];
                let material = group.is_none().then(|| scene.material_on(hit.tri as usize, b));
                let map = group.filter(|&g| ch.textured[g]).map(|_| scene.kd_map_on(hit.tri as usize, b).unwrap_or(Vec3::ONE));
                for (k, cidx) in chans.clone().enumerate() {
                    let r = &mut rho[cidx];
                    match &material {
                        Some(Material::Lambert { albedo }) => {
                            let a = if ch.fixed == 1 { albedo.x } else { albedo[k] };
                            r.iter_mut().zip(&cosine).for_each(|(o, c)| *o = a / PI * c);
                        }
                        Some(_) => r.fill(0.0),
                        None => {
                            let (p, colour) = match map {
                                Some(t) if k < 3 => (0, t[k]),
                                Some(_) => (k - 2, 1.0),
                                None => (k, 1.0),
                            };
                            if p == 0 {
                                r.iter_mut().zip(&cosine).for_each(|(o, c)| *o = colour * c / PI);
                            } else {
                                r.iter_mut().zip(&y).for_each(|(o, yy)| *o = albedo[p][bin] * yy);
                            }
                        }
                    }
                }
                let w = omega * c / PI;
                for q in 0..l2 {
                    for c1 in 0..cc {
                        let inc = &t1y[(q * cc + c1) * SH..(q * cc + c1 + 1) * SH];
                        for c2 in chans.clone() {
                            let rr: f32 = inc.iter().zip(&rho[c2]).map(|(a, b)| a * b).sum();
                            out[(q * cc + c1) * cc + c2] += w * rr;
                        }
                    }
                }
            }
            (out, count)
        })?;
        let mut values = Vec::with_capacity(per_vertex.len() * stride);
        for (o, _) in &per_vertex {
            values.extend_from_slice(o);
        }
        Ok(TwoBounce { side: self.side as u32, channels: cc as u32, values })
    }

    fn gather(&self, i: &TransferT2In, parts: &[&TwoBounce], cx: &RunCtx) -> Result<TransferT2Out, NodeError> {
        let ch = self.check(i, cx.memory_budget())?;
        let mut t = TwoBounce { side: self.side as u32, channels: ch.count() as u32, values: Vec::new() };
        for p in parts {
            t.values.extend_from_slice(&p.values);
        }
        if t.values.len() != i.scene.positions.len() * t.stride() {
            return Err(NodeError::failed("the chunks do not cover the vertices once"));
        }
        cx.metric("bytes", t.byte_size() as f64);
        cx.metric("channels", ch.count() as f64);
        cx.metric("lighting_bases", (6 * self.side * self.side) as f64);
        Ok(TransferT2Out { transfer: t })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cta_compress::CtaCompress;
    use crate::transfer_t1::TransferT1;
    use crate::vertex_visibility::tests::{floor_and_tiled_roof, visibility};
    use relume_base::testing::{first, i, run_on};
    use relume_base::types::accel::BuildQuality;
    use relume_core::Value;

    fn setup() -> (Scene, Value, Visibility, BrdfBasis, BounceTransfer) {
        let s = floor_and_tiled_roof(0.5);
        let accel = Value::new(Accel::build(&s, BuildQuality::Fast));
        let vis = visibility(&s, 16, 2);
        let basis =
            relume_base::brdf_space::test_support::basis(&relume_base::brdf_space::test_support::space(6, 6, 12, 12, 1.0, 100.0), 3).0;
        let plan: crate::types::CtaPlan = first(
            &run_on::<CtaCompress>(
                &[("clusters", i(2)), ("eigenvectors", i(100)), ("lighting", i(24))],
                vec![Value::new(s.clone()), Value::new(vis.clone())],
            )
            .expect("plan"),
        );
        let t1: BounceTransfer = first(
            &run_on::<TransferT1>(
                &[("rays_side", i(8))],
                vec![Value::new(s.clone()), accel.clone(), Value::new(vis.clone()), Value::new(basis.clone()), Value::new(plan)],
            )
            .expect("t1"),
        );
        (s, accel, vis, basis, t1)
    }

    #[test]
    fn coarse_rows_at_the_same_side_are_the_clusters_rebuilt_and_box_sums_keep_totals() {
        let (s, _, _, _, t1) = setup();
        let n = s.positions.len();
        let same = coarse_bounce(&t1, 2, n);
        let sl = 24 * t1.channels() * SH;
        for (tensor, members) in t1.clusters.iter().zip(&t1.plan.members) {
            for (k, &v) in members.iter().enumerate() {
                let want = tensor.vertex(k);
                let got = &same[v as usize * sl..(v as usize + 1) * sl];
                let peak = want.iter().fold(1e-6f32, |m, x| m.max(x.abs()));
                assert!(got.iter().zip(&want).all(|(a, b)| (a - b).abs() < 1e-4 * peak), "vertex {v}");
            }
        }
        // Side 1: each face's sum; totals over all bases agree.
        let one = coarse_bounce(&t1, 1, n);
        let s1 = 6 * t1.channels() * SH;
        let total = |rows: &[f32], len: usize, v: usize| rows[v * len..(v + 1) * len].iter().map(|x| *x as f64).sum::<f64>();
        for v in 0..n {
            assert!((total(&one, s1, v) - total(&same, sl, v)).abs() < 1e-4 * (1.0 + total(&same, sl, v).abs()));
        }
    }

    #[test]
    fn floor_vertices_under_the_roof_get_two_bounces_and_the_bytes_do_not_depend_on_threads() {
        let (s, accel, vis, basis, t1) = setup();
        let inputs = vec![Value::new(s.clone()), accel, Value::new(vis), Value::new(basis), Value::new(t1)];
        let t: TwoBounce = first(&run_on::<TransferT2>(&[("side", i(1)), ("rays_side", i(8))], inputs.clone()).expect("t2"));
        assert_eq!(t.stride(), 6);
        assert!(t.values.iter().all(|x| x.is_finite() && *x >= -1e-6), "fixed Lambert channels are non-negative");
        // Sky → open floor → roof → floor under the roof: light arrives at vertex (0.5, 0, 0).
        let under = t.of(4 * 9 + 6).iter().sum::<f32>();
        assert!(under > 1e-4, "{under}");
        let one: TwoBounce = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .expect("pool")
            .install(|| first(&run_on::<TransferT2>(&[("side", i(1)), ("rays_side", i(8))], inputs.clone()).expect("t2")));
        assert_eq!(one, t);
        let e = run_on::<TransferT2>(&[("side", i(3))], inputs).expect_err("refused");
        assert!(e.to_string().contains("must divide"), "{e}");
    }
}
