use relume_base::types::{Material, Scene};
use relume_core::{node, params, MemoryEstimate, NodeError, PortSize, RunCtx};

params! {
    /// Readies a scene for the transfer tensors when some of its fixed objects are glossy: each
    /// fixed object whose material is not Lambertian becomes a dynamic object (of its own, or
    /// with the others sharing its named material), keeping its material, which no edit changes
    /// unless a `MaterialProject` names it. The transfer shades a fixed object by its irradiance
    /// alone, a diffuse reflector; a glossy one needs what a dynamic object has: the BRDF tensor
    /// toward the eye (its specular lobes included) and, as a reflector, its material's
    /// projection on the BRDF basis in the one- and two-bounce transfer. Each object so turned
    /// costs one group of basis channels (`BrdfPca`'s bases, 5 in the graphs), and T2 grows with
    /// the square of the channel count. Lambertian fixed objects and the dynamic ones pass
    /// unchanged; a scene without glossy fixed objects comes out identical.
    ///
    /// Metrics: `turned` (objects made dynamic).
    pub struct GlossyAsDynamic {}
}

#[node(category = "ptt", metrics = ["turned"], outputs = [scene])]
impl GlossyAsDynamic {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        MemoryEstimate { outputs: vec![inputs[0]], working: 0 }
    }

    fn run(&self, scene: &Scene, cx: &RunCtx) -> Result<Scene, NodeError> {
        let mut out = scene.clone();
        let mut turned = Vec::new();
        for o in out.objects.iter_mut().filter(|o| !o.dynamic && !matches!(o.material, Material::Lambert { .. })) {
            o.dynamic = true;
            turned.push(o.name.clone());
        }
        if !turned.is_empty() {
            cx.note(format!("glossy fixed objects shaded as dynamic ones (unedited): {}", turned.join(", ")));
        }
        cx.metric("turned", turned.len() as f64);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::{plane, GLOSSY};
    use relume_base::testing::{first, run_full, run_on};
    use relume_base::types::Environment;
    use relume_core::Value;
    use std::path::Path;

    #[test]
    fn glossy_fixed_objects_turn_dynamic_and_the_rest_pass_unchanged() {
        let env = Environment::Constant(glam::Vec3::ONE);
        let glossy = plane(GLOSSY, false, env.clone());
        let e = run_full::<GlossyAsDynamic>(&[], Path::new("."), vec![Value::new(glossy.clone())]).expect("runs");
        let out: Scene = first(&e.outputs);
        assert!(out.objects[0].dynamic && out.objects[0].material == GLOSSY);
        assert_eq!(out.dynamic_groups(), vec![("plane".to_string(), vec![0])]);
        assert!(e.notes.iter().any(|n| n.contains("plane")), "{:?}", e.notes);
        // Lambertian fixed objects and dynamic ones are left as they are.
        for s in [plane(Material::Lambert { albedo: glam::Vec3::splat(0.5) }, false, env.clone()), plane(GLOSSY, true, env)] {
            let same: Scene = first(&run_on::<GlossyAsDynamic>(&[], vec![Value::new(s.clone())]).expect("runs"));
            assert_eq!(same.objects, s.objects);
        }
    }
}
