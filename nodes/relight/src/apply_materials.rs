use glam::Vec3;
use relume_base::types::{Material, ObjectMaterials, Scene, Specular};
use relume_core::{node, NodeError, Params, RunCtx};

/// The scene with its dynamic objects' materials replaced by `materials` (Blinn-Phong (Kd, Ks,
/// s), or Cook-Torrance (Kd, Ks, m, F0) for a material whose specular lobe is Cook-Torrance,
/// and its texture maps per dynamic object, every member of a group alike): what a path tracer renders to compare
/// with a relit image after a material edit, so that the error figures follow the edit. Objects
/// that are not dynamic are untouched. Materials of other objects than the scene's dynamic ones
/// are an input error.
#[derive(Params)]
pub struct ApplyMaterials {}

/// `scene` with the materials of its dynamic objects from `materials` (see the node's doc).
pub fn apply_materials(scene: &Scene, materials: &ObjectMaterials) -> Result<Scene, String> {
    let groups = scene.dynamic_groups();
    let names: Vec<&str> = groups.iter().map(|g| g.0.as_str()).collect();
    if materials.0.iter().map(|m| m.name.as_str()).ne(names.iter().copied()) {
        let given: Vec<&str> = materials.0.iter().map(|m| m.name.as_str()).collect();
        return Err(format!("the materials are for [{}], the scene's dynamic objects are [{}]", given.join(", "), names.join(", ")));
    }
    let mut out = scene.clone();
    for ((_, members), m) in groups.iter().zip(&materials.0) {
        for &o in members {
            let (kd, ks) = (Vec3::from(m.kd), Vec3::from(m.ks));
            out.objects[o as usize].material = match m.specular {
                Specular::BlinnPhong => Material::BlinnPhong { kd, ks, exponent: m.s },
                Specular::CookTorrance { m, f0 } => Material::CookTorrance { kd, ks, roughness: m, f0 },
            };
            *out.objects[o as usize].maps = m.maps.clone();
        }
    }
    Ok(out)
}

#[node(category = "relight", outputs = [scene])]
impl ApplyMaterials {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        relume_core::MemoryEstimate { outputs: vec![inputs[0]], working: 0 }
    }

    fn run(&self, scene: &Scene, materials: &ObjectMaterials, _cx: &RunCtx) -> Result<Scene, NodeError> {
        let scene = apply_materials(scene, materials).map_err(|m| NodeError::input("materials", m))?;
        Ok(scene)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_support::scene;
    use relume_base::brdf_space::scene_materials::scene_materials;
    use relume_base::testing::{first, run_on};
    use relume_core::Value;

    #[test]
    fn an_edited_material_reaches_every_member_of_its_group_and_nothing_else() {
        let s = scene(8);
        let mut m = scene_materials(&s).unwrap();
        let mats = |s: &Scene| s.objects.iter().map(|o| o.material).collect::<Vec<_>>();
        assert_eq!(mats(&apply_materials(&s, &m).unwrap()), mats(&s), "the scene's own materials change nothing");
        m.0[0].kd = [0.7, 0.1, 0.1];
        m.0[0].s = 90.0;
        let out: Scene = first(&run_on::<ApplyMaterials>(&[], vec![Value::new(s.clone()), Value::new(m)]).unwrap());
        let want = Material::BlinnPhong { kd: Vec3::new(0.7, 0.1, 0.1), ks: Vec3::splat(0.4), exponent: 90.0 };
        // Spheres a and b are the group "glossy"; c and the fixed floor and lamp keep theirs.
        assert_eq!((out.objects[0].material, out.objects[1].material), (want, want));
        for k in 2..s.objects.len() {
            assert_eq!(out.objects[k].material, s.objects[k].material, "{}", s.objects[k].name);
        }
        // A Cook-Torrance material (the transfer tensors' edit) reaches the scene as one.
        let mut ct = scene_materials(&s).unwrap();
        ct.0[0].specular = Specular::CookTorrance { m: 0.3, f0: 0.5 };
        let out = apply_materials(&s, &ct).unwrap();
        let want = Material::CookTorrance { kd: Vec3::from(ct.0[0].kd), ks: Vec3::from(ct.0[0].ks), roughness: 0.3, f0: 0.5 };
        assert_eq!((out.objects[0].material, out.objects[1].material), (want, want));
    }

    #[test]
    fn materials_of_another_scene_are_an_input_error() {
        let s = scene(8);
        let mut m = scene_materials(&s).unwrap();
        m.0.swap(0, 1);
        let e = run_on::<ApplyMaterials>(&[], vec![Value::new(s), Value::new(m)]).unwrap_err().to_string();
        assert!(e.contains("[c, glossy]") && e.contains("[glossy, c]"), "{e}");
    }
}
