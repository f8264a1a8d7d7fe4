use glam::Vec3;
use relume_base::types::{ObjectMaterials, Texture};
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

params! {
    /// One brush stroke on a dynamic object's material texture ([S] 4.2.3: materials are edited
    /// as Kd, Ks and s maps): the texels within `radius` (in UV units) of (`u`, `v`) move toward
    /// `value` by `strength` × a smooth falloff (1 − (d / radius)²)². A map the object lacks is
    /// first made white (the object's own parameter everywhere) at `size`². Maps multiply the
    /// object's Kd, Ks or s (the exponent map reads its first channel). Chain one node per stroke:
    /// each stroke is a parameter set, saved with the graph and undone with it; a stroke re-runs
    /// only what reads the materials (`SvRelight`, and the reference through `ApplyMaterials`).
    pub struct PaintMaterial {
        /// the dynamic object to paint (empty: paint none)
        pub object: String = "";
        /// which map the stroke paints
        pub map: PaintedMap = Kd;
        /// centre of the stroke, U
        pub u: f32 = 0.5, range = -4.0..=4.0;
        /// centre of the stroke, V
        pub v: f32 = 0.5, range = -4.0..=4.0;
        /// radius of the stroke in UV units
        pub radius: f32 = 0.1, range = 0.0001..=2.0;
        /// the map's value the stroke paints toward (a multiplier of Kd, Ks or s)
        pub value: [f32; 3] = (1.0, 0.2, 0.2), rgb, range = 0.0..=1000.0;
        /// how far the texels under the brush's centre move toward the value
        pub strength: f32 = 1.0, range = 0.0..=1.0;
        /// side of a map made for the stroke when the object has none
        pub size: u32 = 256, range = 1..=4096, unit = "texels";
    }
}

/// The material map a stroke paints.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum PaintedMap {
    /// the diffuse reflectance Kd
    Kd,
    /// the specular reflectance Ks
    Ks,
    /// the Blinn-Phong exponent s (first channel)
    Exponent,
}

/// Paints the stroke of `p` into `t` (see the node's doc); returns the texels it changed.
pub fn paint(t: &mut Texture, p: &PaintMaterial) -> usize {
    let (w, h) = (t.width as usize, t.height as usize);
    let target = Vec3::from(p.value);
    let mut changed = 0;
    for y in 0..h {
        for x in 0..w {
            // The texel's centre in UV (row 0 at the top, as `Texture::lookup`).
            let (tu, tv) = ((x as f32 + 0.5) / w as f32, 1.0 - (y as f32 + 0.5) / h as f32);
            let d2 = ((tu - p.u).powi(2) + (tv - p.v).powi(2)) / (p.radius * p.radius);
            if d2 >= 1.0 {
                continue;
            }
            let a = p.strength * (1.0 - d2).powi(2);
            let texel = &mut t.texels[y * w + x];
            let new = texel.lerp(target, a);
            changed += (new != *texel) as usize;
            *texel = new;
        }
    }
    changed
}

#[node(category = "relight", version = 2, metrics = ["texels_painted"], outputs = [materials])]
impl PaintMaterial {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let made = self.size as u64 * self.size as u64 * 12;
        relume_core::MemoryEstimate { outputs: vec![inputs[0].map(|s| relume_core::PortSize::bytes(s.bytes + made))], working: 0 }
    }

    fn run(&self, materials: &ObjectMaterials, cx: &RunCtx) -> Result<ObjectMaterials, NodeError> {
        let mut out = materials.clone();
        if self.object.is_empty() {
            return Ok(out);
        }
        let names: Vec<&str> = materials.0.iter().map(|m| m.name.as_str()).collect();
        let m = out.0.iter_mut().find(|m| m.name == self.object).ok_or_else(|| {
            NodeError::param("object", format!("no dynamic object \"{}\" (dynamic objects: {})", self.object, names.join(", ")))
        })?;
        let slot = match self.map {
            PaintedMap::Kd => &mut m.maps.kd,
            PaintedMap::Ks => &mut m.maps.ks,
            PaintedMap::Exponent => &mut m.maps.exponent,
        };
        let n = self.size as usize;
        let t = slot.get_or_insert_with(|| Texture::new(n, n, vec![Vec3::ONE; n * n]).expect("a square of size ≥ 1"));
        let changed = paint(t, self);
        cx.metric("texels_painted", changed as f64);
        if changed == 0 {
            cx.note("the stroke covers no texel centre: widen the radius");
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::scene;
    use relume_base::brdf_space::scene_materials::scene_materials;
    use relume_base::testing::{f, first, i, id, rgb, run_on, t};
    use relume_core::Value;

    fn stroke(params: &[(&str, relume_core::ParamValue)]) -> Result<ObjectMaterials, NodeError> {
        let m = scene_materials(&scene(8)).unwrap();
        run_on::<PaintMaterial>(params, vec![Value::new(m)]).map(|o| first(&o))
    }

    #[test]
    fn a_stroke_makes_a_white_map_and_paints_a_disc_with_a_smooth_edge() {
        let m = stroke(&[
            ("object", t("c")),
            ("u", f(0.5)),
            ("v", f(0.5)),
            ("radius", f(0.25)),
            ("value", rgb([1.0, 0.0, 0.0])),
            ("size", i(16)),
        ])
        .unwrap();
        let c = &m.0[1];
        assert_eq!(c.name, "c");
        let kd = c.maps.kd.as_ref().expect("a Kd map was made");
        assert_eq!((kd.width, kd.height), (16, 16));
        assert!(c.maps.ks.is_none() && c.maps.exponent.is_none());
        // The centre is nearly the value, the corner untouched, the edge in between.
        let at = |u: f32, v: f32| kd.lookup(glam::Vec2::new(u, v));
        assert!(at(0.5, 0.5).y < 0.1 && at(0.5, 0.5).x == 1.0, "{}", at(0.5, 0.5));
        assert_eq!(at(0.03, 0.03), Vec3::ONE);
        let edge = at(0.5 + 0.2, 0.5);
        assert!(edge.y > 0.2 && edge.y < 0.9, "{edge}");
        assert!(m.0[0].maps.is_empty(), "the other object is not painted");
    }

    #[test]
    fn strokes_chain_and_an_unknown_object_is_a_parameter_error() {
        let one = stroke(&[
            ("object", t("glossy")),
            ("map", id("Exponent")),
            ("radius", f(0.3)),
            ("value", rgb([3.0, 3.0, 3.0])),
            ("size", i(8)),
        ])
        .unwrap();
        let e = one.0[0].maps.exponent.as_ref().unwrap();
        assert!(e.texels.iter().any(|t| t.x > 2.0), "the exponent map multiplies s by up to 3");
        let e = stroke(&[("object", t("nope"))]).unwrap_err().to_string();
        assert!(e.contains("no dynamic object \"nope\"") && e.contains("glossy, c"), "{e}");
        let none = stroke(&[]).unwrap();
        assert_eq!(none, scene_materials(&scene(8)).unwrap(), "no object: nothing painted");
    }
}
