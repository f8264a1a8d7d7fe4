//! The whole transfer chain on small scenes, made by the nodes themselves, for the relighting
//! nodes' unit tests.

use super::brdf_factors::test_support::small_brdf;
use super::compress_t2::CompressT2;
use super::cta_compress::CtaCompress;
use super::env_lighting::EnvLighting;
use super::incident_projection::IncidentProjection;
use super::ptt_bounce_light::PttBounceLight;
use super::ptt_direct::PttDirect;
use super::ptt_incident::PttIncident;
use super::ptt_relight::PttRelight;
use super::screen_hits::ScreenHits;
use super::transfer_t0::TransferT0;
use super::transfer_t1::TransferT1;
use super::transfer_t2::TransferT2;
use super::types::brdf::{SpecularLobes, TuckerBrdf};
use super::types::BounceLight;
use super::types::DirectLight;
use super::types::VertexIncident;
use super::types::{EnvLight, VertexColors, Visibility};
use super::vertex_visibility::tests::{grid, visibility};
use glam::{Vec2, Vec3};
use relume_base::brdf_space::material_project::MaterialProject;
use relume_base::brdf_space::scene_materials::SceneMaterials;
use relume_base::math::latlong::uv_to_dir;
use relume_base::testing::{first, i, run_on};
use relume_base::types::accel::BuildQuality;
use relume_base::types::{Accel, EnvMap, Environment, Material, ObjectMaterials, Scene};
use relume_core::{ParamValue, Value};

/// The glossy material of the tests' dynamic objects.
pub const GLOSSY: Material = Material::BlinnPhong { kd: Vec3::new(0.5, 0.3, 0.2), ks: Vec3::splat(0.3), exponent: 40.0 };

/// A sky brightening toward +y with a bright blob toward `blob` (a 64 × 32 lat-long map).
pub fn blob_sky(blob: Vec3) -> Environment {
    let (w, h) = (64, 32);
    let texels = (0..w * h)
        .map(|k| {
            let d = uv_to_dir(Vec2::new(((k % w) as f32 + 0.5) / w as f32, ((k / w) as f32 + 0.5) / h as f32));
            let sky = Vec3::new(0.4, 0.5, 0.7) * (0.6 + 0.4 * d.y);
            sky + Vec3::new(300.0, 250.0, 200.0) * (d.dot(blob.normalize()) - 0.97).max(0.0) * 33.0
        })
        .collect();
    Environment::Map(EnvMap::new(w, h, texels).expect("map"))
}

/// A 2 × 2 plane at y = 0 (9 × 9 vertices) of `material`, dynamic or not, under `env`,
/// with the camera above it looking down at 45°.
pub fn plane(material: Material, dynamic: bool, env: Environment) -> Scene {
    let (pos, nrm, tris) = grid(Vec3::new(-1.0, 0.0, -1.0), Vec3::X * 2.0, Vec3::Z * 2.0, Vec3::Y);
    let mut s = relume_base::scene::builder::SceneBuilder::new(Vec3::new(0.0, 2.0, 2.0), Vec3::ZERO, 40.0, 16, 16)
        .mesh("plane", pos, Some(nrm), tris, material, Vec3::ZERO)
        .environment(env)
        .build();
    s.objects[0].dynamic = dynamic;
    s
}

/// Everything the relighting reads, for one scene.
#[derive(Clone)]
pub struct Chain {
    pub scene: Scene,
    pub vis: Visibility,
    pub env: EnvLight,
    pub values: Vec<(&'static str, Value)>,
}

impl Chain {
    /// The precompute of `scene` at small sizes (visibility 16 / coarse 2, full-rank clusters,
    /// bounce rays 6 × 8², the test BRDF tensor).
    pub fn new(scene: Scene) -> Chain {
        Chain::with(scene, small_brdf(), &[])
    }

    /// [`Chain::new`] with the BRDF tensor and lobes `brdf` and the materials edited by a
    /// `MaterialProject` with `edit`.
    pub fn with(scene: Scene, brdf: &(TuckerBrdf, SpecularLobes), edit: &[(&str, ParamValue)]) -> Chain {
        let accel = Value::new(Accel::build(&scene, BuildQuality::Fast));
        let vis = visibility(&scene, 16, 2);
        let (brdf, lobes) = brdf.clone();
        let basis =
            relume_base::brdf_space::test_support::basis(&relume_base::brdf_space::test_support::space(6, 6, 12, 12, 1.0, 100.0), 3).0;
        let sv = Value::new(scene.clone());
        let plan: Value = run_on::<CtaCompress>(
            &[("clusters", i(1)), ("eigenvectors", i(200)), ("lighting", i(24))],
            vec![sv.clone(), Value::new(vis.clone())],
        )
        .expect("plan")
        .remove(0);
        let t1 = run_on::<TransferT1>(
            &[("rays_side", i(8))],
            vec![sv.clone(), accel.clone(), Value::new(vis.clone()), Value::new(basis.clone()), plan],
        )
        .expect("t1")
        .remove(0);
        let t2 = run_on::<TransferT2>(
            &[("side", i(1)), ("rays_side", i(8))],
            vec![sv.clone(), accel, Value::new(vis.clone()), Value::new(basis.clone()), t1.clone()],
        )
        .expect("t2")
        .remove(0);
        // Every direction kept: the packed rows are the traced ones to f32 rounding.
        let packed = run_on::<CompressT2>(&[("clusters", i(2)), ("eigenvectors", i(512))], vec![t2.clone()]).expect("packed T2").remove(0);
        let t0 = run_on::<TransferT0>(&[], vec![Value::new(vis.clone()), Value::new(brdf.clone()), Value::new(lobes.clone())]).expect("t0");
        let env: EnvLight = first(&run_on::<EnvLighting>(&[("side", i(16))], vec![sv.clone()]).expect("env"));
        let mats = run_on::<SceneMaterials>(&[], vec![sv.clone()]).expect("materials").remove(0);
        let mats = run_on::<MaterialProject>(edit, vec![Value::new(basis), mats]).expect("projected").remove(0);
        let proj = run_on::<IncidentProjection>(&[], vec![sv.clone(), Value::new(vis.clone()), Value::new(brdf.clone())])
            .expect("projection")
            .remove(0);
        let values = vec![
            ("direct", t0[0].clone()),
            ("lobe_visibility", t0[1].clone()),
            ("bounce", t1),
            ("two_raw", t2),
            ("two", packed),
            ("projection", proj),
            ("materials", mats),
            ("brdf", Value::new(brdf)),
            ("lobes", Value::new(lobes)),
        ];
        Chain { scene, vis, env, values }
    }

    pub fn get(&self, name: &str) -> Value {
        self.values.iter().find(|(n, _)| *n == name).map(|(_, v)| v.clone()).expect("a chain value")
    }

    pub fn materials(&self) -> ObjectMaterials {
        self.get("materials").get::<ObjectMaterials>().expect("materials").clone()
    }

    /// `PttDirect` under `env`.
    pub fn direct_light(&self, env: &EnvLight) -> DirectLight {
        first(&run_on::<PttDirect>(&[], vec![Value::new(env.clone()), self.get("direct"), self.get("projection")]).expect("direct light"))
    }

    /// `PttBounceLight`'s inputs under `env`.
    pub fn bounce_light_inputs(&self, env: &EnvLight) -> Vec<Value> {
        vec![Value::new(env.clone()), self.get("bounce"), self.get("two")]
    }

    /// `PttBounceLight` under `env` with `bounces`.
    pub fn bounce_light(&self, env: &EnvLight, bounces: i64) -> BounceLight {
        first(&run_on::<PttBounceLight>(&[("bounces", i(bounces))], self.bounce_light_inputs(env)).expect("bounce light"))
    }

    /// `PttIncident`'s inputs with `env`, `materials` and `bounces`.
    pub fn incident_inputs_with(&self, env: &EnvLight, materials: &ObjectMaterials, bounces: i64) -> Vec<Value> {
        vec![
            Value::new(self.direct_light(env)),
            self.get("bounce"),
            Value::new(self.bounce_light(env, bounces)),
            self.get("projection"),
            Value::new(materials.clone()),
        ]
    }

    /// `PttIncident`'s inputs with `env` and `materials`, two bounces.
    pub fn incident_inputs(&self, env: &EnvLight, materials: &ObjectMaterials) -> Vec<Value> {
        self.incident_inputs_with(env, materials, 2)
    }

    /// `PttIncident` with `bounces`.
    pub fn incident(&self, env: &EnvLight, materials: &ObjectMaterials, bounces: i64) -> VertexIncident {
        first(&run_on::<PttIncident>(&[], self.incident_inputs_with(env, materials, bounces)).expect("incident"))
    }

    /// `PttRelight`'s inputs for `scene` (its camera and objects), the incident light and
    /// `materials`.
    pub fn relight_inputs(&self, scene: &Scene, incident: &VertexIncident, env: &EnvLight, materials: &ObjectMaterials) -> Vec<Value> {
        vec![
            Value::new(scene.clone()),
            Value::new(scene.camera.clone()),
            Value::new(sees_all(scene)),
            Value::new(self.vis.clone()),
            self.get("projection"),
            Value::new(incident.clone()),
            self.get("brdf"),
            self.get("lobes"),
            self.get("lobe_visibility"),
            Value::new(env.clone()),
            Value::new(materials.clone()),
        ]
    }

    /// The colours after `bounces` under the chain's environment and materials.
    pub fn colors(&self, bounces: i64, params: &[(&str, ParamValue)]) -> Vec<Vec3> {
        let m = self.materials();
        let inc = self.incident(&self.env, &m, bounces);
        let c: VertexColors = first(&run_on::<PttRelight>(params, self.relight_inputs(&self.scene, &inc, &self.env, &m)).expect("relight"));
        c.colors
    }
}

/// Hits of a one-pixel camera that lists every vertex of `scene` as seen: `PttRelight` then
/// shades them all.
pub fn sees_all(scene: &Scene) -> ScreenHits {
    let n = scene.positions.len() as u32;
    ScreenHits {
        width: 1,
        height: 1,
        vertices: n,
        offsets: vec![0, 0],
        vertex: vec![],
        weight: vec![],
        miss: vec![0.0],
        miss_dir: vec![Vec3::ZERO],
        seen: (0..n).collect(),
    }
}
