use crate::types::Scene;
use glam::Vec3;
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// Translates one object of a scene (an area light, the bunny) by a vector: the
    /// interactive "move the light" edit. Nodes wired to the scene before this node (surface
    /// sampling that leaves emitters out) are not re-run when the translation changes.
    pub struct MoveObject {
        /// name of the object to move
        pub object: String = "light";
        /// offset added to its vertices (scene units)
        pub translation: Vec3 = (0.0, 0.0, 0.0);
    }
}

/// The scene with object `name` moved by `t`.
pub fn move_object(scene: &Scene, name: &str, t: Vec3) -> Result<Scene, NodeError> {
    let Some(o) = scene.objects.iter().position(|o| o.name == name) else {
        let names: Vec<_> = scene.objects.iter().map(|o| o.name.as_str()).collect();
        return Err(NodeError::param("object", format!("no object \"{name}\" (objects: {})", names.join(", "))));
    };
    let mut s = scene.clone();
    let mut moved = vec![false; s.positions.len()];
    for tri in s.objects[o].triangles.clone() {
        for &v in &s.triangles[tri as usize] {
            if !std::mem::replace(&mut moved[v as usize], true) {
                s.positions[v as usize] += t;
            }
        }
    }
    Ok(s)
}

#[node(category = "scene", version = 2, outputs = [scene])]
impl MoveObject {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        relume_core::MemoryEstimate { outputs: vec![inputs[0]], working: 0 }
    }

    fn run(&self, scene: &Scene, _cx: &RunCtx) -> Result<Scene, NodeError> {
        move_object(scene, &self.object, self.translation)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::test_scene;

    #[test]
    fn moves_only_the_named_object_and_names_the_choices_otherwise() {
        let s = test_scene::spheres();
        let m = move_object(&s, "b", Vec3::new(0.0, 1.0, 0.0)).unwrap();
        let b = &s.objects[1];
        for t in b.triangles.clone() {
            let (c0, c1) = (s.corners(t as usize), m.corners(t as usize));
            assert!((c1[0] - c0[0] - Vec3::Y).length() < 1e-6);
        }
        let a = s.objects[0].triangles.start as usize;
        assert_eq!(s.corners(a), m.corners(a));
        let e = move_object(&s, "zz", Vec3::ZERO).unwrap_err().to_string();
        assert!(e.contains("objects: a, b, c, floor"), "{e}");
    }
}
