use crate::types::{Material, ObjectMaterial, ObjectMaterials, Scene};
use relume_core::{node, NodeError, Params, RunCtx};

/// The materials of a scene's dynamic objects, as pixel relighting edits them: one entry per
/// dynamic object (`Scene::dynamic_groups`: dynamic shapes sharing a named material are one
/// object, the thesis' "white walls"), with its Blinn-Phong (Kd, Ks, s). A Lambert material is
/// (Kd = albedo, Ks = 0). Other materials cannot be dynamic here (the BRDF space is
/// Blinn-Phong's): an error names the object. Not yet projected: `MaterialProject` adds the
/// basis coefficients and applies edits.
#[derive(Params)]
pub struct SceneMaterials {}

/// The dynamic objects' materials of `scene` (see the node's doc).
pub fn scene_materials(scene: &Scene) -> Result<ObjectMaterials, String> {
    let mut out = Vec::new();
    for (name, members) in scene.dynamic_groups() {
        let o = &scene.objects[members[0] as usize];
        let (kd, ks, s) = match o.material {
            Material::BlinnPhong { kd, ks, exponent } => (kd.to_array(), ks.to_array(), exponent),
            Material::Lambert { albedo } => (albedo.to_array(), [0.0; 3], 1.0),
            _ => {
                return Err(format!(
                    "dynamic object \"{name}\" ({}) is not Blinn-Phong or Lambert: pixel relighting's BRDF space is Blinn-Phong's",
                    o.name
                ))
            }
        };
        out.push(ObjectMaterial { name, kd, ks, s, coefficients: vec![], maps: (*o.maps).clone(), specular: Default::default() });
    }
    Ok(ObjectMaterials(out))
}

#[node(category = "relight", version = 2, metrics = ["dynamic_objects"], outputs = [materials])]
impl SceneMaterials {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // A few numbers per dynamic object and copies of their texture maps, which are part of
        // the scene's bytes: the scene's size bounds the output.
        relume_core::MemoryEstimate { outputs: vec![inputs[0].map(|s| relume_core::PortSize { bytes: s.bytes, dims: None })], working: 0 }
    }

    fn run(&self, scene: &Scene, cx: &RunCtx) -> Result<ObjectMaterials, NodeError> {
        let materials = scene_materials(scene).map_err(|m| NodeError::input("scene", m))?;
        if materials.0.is_empty() {
            cx.note("the scene has no dynamic object: there is no material to edit");
        }
        cx.metric("dynamic_objects", materials.0.len() as f64);
        Ok(materials)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{first, run_on, test_scene};
    use glam::Vec3;
    use relume_core::Value;

    #[test]
    fn dynamic_objects_sharing_a_named_material_are_one_object() {
        let mut scene = test_scene::spheres();
        let n = scene.objects.len();
        assert!(n >= 3);
        for (i, o) in scene.objects.iter_mut().enumerate().take(3) {
            o.dynamic = true;
            o.material = Material::BlinnPhong { kd: Vec3::splat(0.1 * i as f32), ks: Vec3::splat(0.3), exponent: 40.0 };
            o.material_name = if i < 2 { "shared".into() } else { String::new() };
        }
        let m = first::<ObjectMaterials>(&run_on::<SceneMaterials>(&[], vec![Value::new(scene.clone())]).unwrap());
        assert_eq!(m.0.len(), 2);
        assert_eq!(m.0[0].name, "shared");
        assert_eq!(m.0[0].kd, [0.0; 3], "the group takes its first member's material");
        assert_eq!((m.0[1].name.as_str(), m.0[1].s), (scene.objects[2].name.as_str(), 40.0));
        assert_eq!(scene.dynamic_groups()[0].1, vec![0, 1]);
    }

    #[test]
    fn the_memory_estimate_bounds_the_materials_with_their_maps() {
        use crate::types::Texture;
        use relume_core::{Node, PortValue};
        let mut scene = test_scene::spheres();
        scene.objects[0].dynamic = true;
        scene.objects[0].maps.kd = Texture::new(64, 32, vec![Vec3::ONE; 64 * 32]);
        let m = first::<ObjectMaterials>(&run_on::<SceneMaterials>(&[], vec![Value::new(scene.clone())]).unwrap());
        let e = SceneMaterials {}.memory(&[Some(scene.size())]);
        let bytes = e.outputs[0].unwrap().bytes;
        assert!(bytes >= m.byte_size() as u64 && m.byte_size() > 64 * 32 * 12, "{bytes} against {}", m.byte_size());
        assert_eq!(e.working, 0);
    }

    #[test]
    fn a_dielectric_cannot_be_dynamic_and_the_error_names_it() {
        let mut scene = test_scene::spheres();
        scene.objects[0].dynamic = true;
        scene.objects[0].material = Material::Dielectric { ior: 1.5, medium: None };
        let e = run_on::<SceneMaterials>(&[], vec![Value::new(scene.clone())]).unwrap_err();
        assert!(e.to_string().contains(&scene.objects[0].name), "{e}");
    }
}
