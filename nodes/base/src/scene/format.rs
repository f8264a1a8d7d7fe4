//! The scene file format (RON) and its loader. Every error names the file and line.
//!
//! ```ron
//! Scene(
//!     camera: (origin: (0, 0, 3.9), target: (0, 0, 0), up: (0, 1, 0), fov: 39.3077, width: 256, height: 256),
//!     materials: { "glossy": BlinnPhong(kd: 0.3, ks: 0.3, exponent: 180) },
//!     shapes: [
//!         Obj(path: "../assets/cornell/cornell_box.obj", exclude: ["small-box"]),
//!         Obj(path: "../assets/meshes/stanford-bunny.obj", name: "bunny", material: "glossy",
//!             dynamic: true, transform: [Translate((0.101, -1.198, -0.09)), Scale(6.0)]),
//!         Sphere(name: "ball", center: (0, 0.6, 0), radius: 0.5, material: "glass"),
//!     ],
//!     objects: { "floor": (material: "glossy", dynamic: true) },
//!     lights: [ Point(position: (-3, 1.2, 0), intensity: 40) ],
//!     environment: Map(path: "../assets/envlit/sky.exr", scale: 1.0),
//! )
//! ```
//! Transforms compose like matrices, left to right: `[Translate(t), Scale(s)]` is T · S
//! (scale first), as docs/SCENES.md writes `translate(…) · scale(…)`.

use super::envmap::Sky;
use super::obj::load_obj_file;
use super::shapes::{crease_normals, sphere};
use super::subdivide::{subdivide, subdivided_count, MAX_LEVELS};
use crate::image::io::decode_image;
use crate::types::accel::Accel;
use crate::types::{Camera, EnvMap, Environment, Light, Material, MaterialMaps, Medium, Object, Scene, Texture};
use glam::{Mat3, Mat4, Vec2, Vec3};
use relume_core::ron::fields::{bool_of, f64_in, f64_of, list_of, map_of, str_of, triple, usize_in, variant, Fields};
use relume_core::ron::{parse, Ron, SyntaxError};
use relume_core::Hash;
use std::path::{Path, PathBuf};

/// A loaded scene, the files it read (with content hashes) and remarks for the report.
pub struct LoadedScene {
    pub scene: Scene,
    pub files: Vec<(PathBuf, Hash)>,
    pub notes: Vec<String>,
}

/// Loads a scene file; errors read `file:line:col: message`.
pub fn load_scene_file(path: &Path) -> Result<LoadedScene, String> {
    let bytes = relume_core::read_input(path).map_err(|e| format!("cannot read scene {}: {e}", path.display()))?;
    let text = String::from_utf8(bytes).map_err(|_| format!("{}: not UTF-8 text", path.display()))?;
    let at = |e: SyntaxError| format!("{}:{}:{}: {}", path.display(), e.pos.line, e.pos.col, e.msg);
    let doc = parse(&text).map_err(|e| at(SyntaxError { msg: format!("malformed RON: {}", e.msg), ..e }))?;
    let mut b =
        Builder { dir: path.parent().unwrap_or(Path::new(".")).to_path_buf(), scene_file: path.to_path_buf(), ..Default::default() };
    b.read(&doc).map_err(|e| match e {
        LoadError::At(e) => at(e),
        LoadError::Plain(m) => m,
    })?;
    b.finish()
}

/// The files a scene file names (meshes, texture maps, the environment map), relative paths
/// joined to its folder, found without reading them: what a run must not write onto. Empty
/// when the scene cannot be read or parsed (loading it will say why).
pub fn scene_file_paths(path: &Path) -> Vec<PathBuf> {
    fn walk(v: &Ron, dir: &Path, out: &mut Vec<PathBuf>) {
        use relume_core::ron::RonKind;
        match &v.kind {
            RonKind::Struct(_, fields) => {
                for f in fields {
                    match (&f.value.kind, f.name.as_str()) {
                        (RonKind::Str(s), "path" | "kd_map" | "ks_map" | "exponent_map") => out.push(dir.join(s)),
                        _ => walk(&f.value, dir, out),
                    }
                }
            }
            RonKind::List(items) | RonKind::Tuple(_, items) => items.iter().for_each(|x| walk(x, dir, out)),
            RonKind::Map(entries) => entries.iter().for_each(|(_, x)| walk(x, dir, out)),
            _ => {}
        }
    }
    let Ok(bytes) = relume_core::read_input(path) else { return Vec::new() };
    let Ok(doc) = std::str::from_utf8(&bytes).map_err(|_| ()).and_then(|t| parse(t).map_err(|_| ())) else { return Vec::new() };
    let mut out = Vec::new();
    walk(&doc, path.parent().unwrap_or(Path::new(".")), &mut out);
    out
}

enum LoadError {
    At(SyntaxError),
    Plain(String),
}

impl From<SyntaxError> for LoadError {
    fn from(e: SyntaxError) -> Self {
        LoadError::At(e)
    }
}

fn at(v: &Ron, msg: impl Into<String>) -> LoadError {
    LoadError::At(SyntaxError { pos: v.pos, msg: msg.into() })
}

fn vec3(v: &Ron, what: &str, scalar: bool) -> Result<Vec3, SyntaxError> {
    triple(v, what, scalar).map(|t| Vec3::new(t[0] as f32, t[1] as f32, t[2] as f32))
}

/// An RGB in [0, max].
fn rgb(v: &Ron, what: &str, max: f32) -> Result<Vec3, LoadError> {
    let c = vec3(v, what, true)?;
    if c.min_element() < 0.0 || c.max_element() > max {
        return Err(at(v, format!("{what} = {c} must lie in [0, {max}]")));
    }
    Ok(c)
}

#[derive(Default)]
struct Builder {
    dir: PathBuf,
    scene_file: PathBuf,
    materials: Vec<(String, Material)>,
    /// Texture maps by material name (only materials that have some).
    maps: Vec<(String, MaterialMaps)>,
    /// Whether each object came with UVs.
    object_uvs: Vec<bool>,
    objects: Vec<Object>,
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    uvs: Vec<Vec2>,
    has_uvs: bool,
    triangles: Vec<[u32; 3]>,
    lights: Vec<Light>,
    environment: Option<Environment>,
    camera: Option<Camera>,
    files: Vec<(PathBuf, Hash)>,
    dropped: usize,
}

const TOP: &[&str] = &["camera", "materials", "shapes", "objects", "lights", "environment"];

impl Builder {
    fn read(&mut self, doc: &Ron) -> Result<(), LoadError> {
        if !matches!(&doc.kind, relume_core::ron::RonKind::Struct(Some(n), _) if n == "Scene")
            && !matches!(&doc.kind, relume_core::ron::RonKind::Struct(None, _))
        {
            return Err(at(doc, format!("expected `Scene( camera: …, shapes: […], … )`, found {}", doc.what())));
        }
        let mut f = Fields::new(doc, "Scene")?;
        let camera = f.req("camera")?;
        self.camera = Some(read_camera(camera)?);
        if let Some(m) = f.opt("materials") {
            for (name, _, v) in map_of(m, "materials")? {
                let (mat, map_fields) = read_material(v)?;
                let maps = self.read_maps(name, &mat, map_fields)?;
                if !maps.is_empty() {
                    self.maps.push((name.to_string(), maps));
                }
                self.materials.push((name.to_string(), mat));
            }
        }
        for s in list_of(f.req("shapes")?, "shapes")? {
            self.read_shape(s)?;
        }
        if let Some(o) = f.opt("objects") {
            for (name, _, v) in map_of(o, "objects")? {
                self.override_object(name, v)?;
            }
        }
        if let Some(l) = f.opt("lights") {
            for v in list_of(l, "lights")? {
                self.lights.push(read_light(v)?);
            }
        }
        if let Some(e) = f.opt("environment") {
            self.environment = Some(self.read_environment(e)?);
        }
        f.finish(TOP)?;
        self.assign_maps(doc)
    }

    /// The textures of a material's `kd_map` / `ks_map` / `exponent_map` (image files, paths
    /// relative to the scene file; dependencies of the scene).
    fn read_maps(&mut self, name: &str, m: &Material, fields: [Option<&Ron>; 3]) -> Result<MaterialMaps, LoadError> {
        let mut maps = MaterialMaps::default();
        for (k, field) in fields.into_iter().enumerate() {
            let Some(v) = field else { continue };
            let allowed = match m {
                Material::Lambert { .. } => k == 0,
                Material::BlinnPhong { .. } => true,
                Material::CookTorrance { .. } => k < 2,
                _ => false,
            };
            let key = ["kd_map", "ks_map", "exponent_map"][k];
            if !allowed {
                return Err(at(v, format!("material \"{name}\": `{key}` does not apply to this kind of material")));
            }
            let (p, bytes) = self.read_file(v)?;
            let img = decode_image(&p, &bytes).map_err(|e| at(v, e))?;
            // As the environment map: a texel that is not finite and ≥ 0 would shade as NaN or
            // infinity, or darken or drop samples with nothing said.
            if let Some(i) = img.pixels.iter().position(|t| t.iter().any(|c| !c.is_finite() || *c < 0.0)) {
                return Err(at(
                    v,
                    format!(
                        "material \"{name}\": `{key}` {}: texel ({}, {}) is {:?}; a texture map's texels must be finite and ≥ 0",
                        p.display(),
                        i % img.width,
                        i / img.width,
                        img.pixels[i]
                    ),
                ));
            }
            let tex = Texture::new(img.width, img.height, img.pixels.iter().map(|p| Vec3::from(*p)).collect())
                .ok_or_else(|| at(v, format!("{}: an empty image", p.display())))?;
            *[&mut maps.kd, &mut maps.ks, &mut maps.exponent][k] = Some(tex);
        }
        Ok(maps)
    }

    /// Gives every object the maps of its named material; an object with maps needs UVs.
    fn assign_maps(&mut self, doc: &Ron) -> Result<(), LoadError> {
        for (i, o) in self.objects.iter_mut().enumerate() {
            let Some((_, maps)) = self.maps.iter().find(|(n, _)| *n == o.material_name) else { continue };
            if !self.object_uvs[i] {
                return Err(at(
                    doc,
                    format!("object \"{}\" has no UVs, but its material \"{}\" has texture maps", o.name, o.material_name),
                ));
            }
            *o.maps = maps.clone();
        }
        Ok(())
    }

    fn material(&self, v: &Ron) -> Result<Material, LoadError> {
        let name = str_of(v, "material")?;
        self.materials.iter().find(|(n, _)| n == name).map(|(_, m)| *m).ok_or_else(|| {
            let known: Vec<_> = self.materials.iter().map(|(n, _)| n.as_str()).collect();
            at(v, format!("unknown material \"{name}\" (materials: {})", if known.is_empty() { "none".into() } else { known.join(", ") }))
        })
    }

    fn read_file(&mut self, v: &Ron) -> Result<(PathBuf, Vec<u8>), LoadError> {
        let rel = str_of(v, "path")?;
        let p = self.dir.join(rel);
        let bytes = relume_core::read_input(&p).map_err(|e| at(v, format!("cannot read {}: {e}", p.display())))?;
        self.files.push((p.clone(), Hash::of_bytes(&bytes)));
        Ok((p, bytes))
    }

    fn read_shape(&mut self, v: &Ron) -> Result<(), LoadError> {
        let (kind, v) = variant(v, "shape", &["Obj", "Sphere"])?;
        let mut f = Fields::new(v, &format!("{kind} shape"))?;
        let material = f.opt("material").map(|m| self.material(m)).transpose()?;
        let material_name = f.opt("material").map(|m| str_of(m, "material")).transpose()?.unwrap_or("").to_string();
        let emission = f.opt("emission").map(|e| rgb(e, "emission", 1e9)).transpose()?;
        let dynamic = f.opt("dynamic").map(|d| bool_of(d, "dynamic")).transpose()?.unwrap_or(false);
        let name = f.opt("name").map(|n| str_of(n, "name")).transpose()?.map(str::to_string);
        let transform = f.opt("transform").map(read_transform).transpose()?.unwrap_or(Mat4::IDENTITY);
        // Normals are smoothed across edges flatter than this angle and kept sharp across
        // steeper ones (a box stays flat-shaded, a scanned bunny smooth).
        let crease = f.opt("crease_angle").map(|c| f64_in(c, "crease_angle", 0.0, 180.0)).transpose()?.unwrap_or(30.0) as f32;
        // Midpoint subdivision levels (4× the triangles each, the same surface).
        let levels = f.opt("subdivide").map(|l| usize_in(l, "subdivide", 0, MAX_LEVELS as usize)).transpose()?.unwrap_or(0) as u32;
        match kind {
            "Obj" => {
                let pv = f.req("path")?;
                let exclude: Vec<String> = match f.opt("exclude") {
                    Some(e) => list_of(e, "exclude")?
                        .iter()
                        .map(|x| str_of(x, "an excluded object").map(str::to_string))
                        .collect::<Result<_, _>>()?,
                    None => vec![],
                };
                let (p, bytes) = self.read_file(pv)?;
                let text = String::from_utf8(bytes).map_err(|_| at(pv, format!("{}: not UTF-8 text", p.display())))?;
                let obj = load_obj_file(&p, &text).map_err(LoadError::Plain)?;
                // The material libraries are dependencies too.
                for (mp, b) in &obj.libraries {
                    self.files.push((mp.clone(), Hash::of_bytes(b)));
                }
                let models = obj.models;
                if name.is_some() && models.len() != 1 {
                    return Err(at(v, format!("`name` renames a single object, but {} has {}", p.display(), models.len())));
                }
                for x in &exclude {
                    if !models.iter().any(|m| &m.name == x) {
                        return Err(at(v, format!("exclude: {} has no object \"{x}\"", p.display())));
                    }
                }
                for mut m in models.into_iter().filter(|m| !exclude.contains(&m.name)) {
                    if levels > 0 {
                        // Refused before the finer mesh is allocated: no scene may pass what
                        // the ray tracer's tree indexes.
                        let n = subdivided_count(m.triangles.len(), levels).filter(|&n| n <= Accel::MAX_TRIANGLES as u64);
                        if n.is_none() {
                            return Err(at(
                                v,
                                format!(
                                    "subdivide: {levels} levels of \"{}\" ({} triangles) would pass the {} triangles a scene may hold",
                                    m.name,
                                    m.triangles.len(),
                                    Accel::MAX_TRIANGLES
                                ),
                            ));
                        }
                        subdivide(&mut m.positions, &mut m.uvs, &mut m.triangles, levels);
                    }
                    let mat = material
                        .or(m.material)
                        .ok_or_else(|| at(v, format!("object \"{}\" has no material (give `material:` or a usemtl)", m.name)))?;
                    let (pos, normals, tris, origin) = crease_normals(&m.positions, &m.triangles, crease);
                    let uvs = (m.uvs.len() == m.positions.len()).then(|| origin.iter().map(|&i| m.uvs[i as usize]).collect());
                    let obj_name = name.clone().unwrap_or(m.name);
                    self.push_object(obj_name, mat, emission.unwrap_or(m.emission), dynamic, &transform, pos, normals, uvs, tris);
                    self.objects.last_mut().expect("just pushed").material_name = material_name.clone();
                }
            }
            _ => {
                let center = vec3(f.req("center")?, "center", false)?;
                let radius = f64_in(f.req("radius")?, "radius", 1e-9, 1e9)? as f32;
                let rings = f.opt("rings").map(|r| usize_in(r, "rings", 2, 4096)).transpose()?.unwrap_or(96);
                let mat = material.ok_or_else(|| at(v, "a Sphere needs `material`"))?;
                if levels > 0 {
                    return Err(at(v, "a Sphere is made as fine as `rings` says; `subdivide` is for Obj shapes"));
                }
                let (pos, nrm, tris) = sphere(center, radius, rings, 2 * rings);
                self.push_object(
                    name.unwrap_or_else(|| format!("sphere{}", self.objects.len())),
                    mat,
                    emission.unwrap_or(Vec3::ZERO),
                    dynamic,
                    &transform,
                    pos,
                    nrm,
                    None,
                    tris,
                );
                self.objects.last_mut().expect("just pushed").material_name = material_name;
            }
        }
        f.finish(&[
            "path",
            "name",
            "material",
            "emission",
            "dynamic",
            "transform",
            "exclude",
            "crease_angle",
            "subdivide",
            "center",
            "radius",
            "rings",
        ])?;
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn push_object(
        &mut self,
        name: String,
        material: Material,
        emission: Vec3,
        dynamic: bool,
        m: &Mat4,
        pos: Vec<Vec3>,
        nrm: Vec<Vec3>,
        uvs: Option<Vec<Vec2>>,
        tris: Vec<[u32; 3]>,
    ) {
        let base = self.positions.len() as u32;
        self.object_uvs.push(uvs.is_some());
        let normal_m = Mat3::from_mat4(*m).inverse().transpose();
        let flip = Mat3::from_mat4(*m).determinant() < 0.0;
        self.positions.extend(pos.iter().map(|p| m.transform_point3(*p)));
        self.normals.extend(nrm.iter().map(|n| (normal_m * *n).normalize_or_zero()));
        match uvs {
            Some(u) => {
                if !self.has_uvs {
                    self.uvs.resize(base as usize, Vec2::ZERO);
                    self.has_uvs = true;
                }
                self.uvs.extend(u);
            }
            None if self.has_uvs => self.uvs.resize(self.positions.len(), Vec2::ZERO),
            None => {}
        }
        let start = self.triangles.len() as u32;
        for t in tris {
            let t = if flip { [t[0], t[2], t[1]] } else { t };
            let p = t.map(|i| self.positions[(base + i) as usize]);
            if (p[1] - p[0]).cross(p[2] - p[0]).length_squared() <= 0.0 {
                self.dropped += 1;
                continue;
            }
            self.triangles.push(t.map(|i| base + i));
        }
        self.objects.push(Object {
            name,
            material,
            emission,
            dynamic,
            triangles: start..self.triangles.len() as u32,
            material_name: String::new(),
            maps: Box::default(),
        });
    }

    fn override_object(&mut self, name: &str, v: &Ron) -> Result<(), LoadError> {
        let mut f = Fields::new(v, &format!("object \"{name}\""))?;
        let material = f.opt("material").map(|m| self.material(m)).transpose()?;
        let name_of_material = f.opt("material").map(|m| str_of(m, "material").map(str::to_string)).transpose()?;
        let emission = f.opt("emission").map(|e| rgb(e, "emission", 1e9)).transpose()?;
        let dynamic = f.opt("dynamic").map(|d| bool_of(d, "dynamic")).transpose()?;
        f.finish(&["material", "emission", "dynamic"])?;
        let known: Vec<String> = self.objects.iter().map(|o| o.name.clone()).collect();
        let obj = self
            .objects
            .iter_mut()
            .find(|o| o.name == name)
            .ok_or_else(|| at(v, format!("no object \"{name}\" (objects: {})", known.join(", "))))?;
        if let Some(m) = material {
            obj.material = m;
            obj.material_name = name_of_material.unwrap_or_default();
        }
        if let Some(e) = emission {
            obj.emission = e;
        }
        if let Some(d) = dynamic {
            obj.dynamic = d;
        }
        Ok(())
    }

    fn read_environment(&mut self, v: &Ron) -> Result<Environment, LoadError> {
        let (kind, v) = variant(v, "environment", &["Constant", "Map", "Sky"])?;
        let mut f = Fields::new(v, &format!("{kind} environment"))?;
        let env = match kind {
            "Constant" => Environment::Constant(rgb(f.req("radiance")?, "radiance", 1e9)?),
            "Map" => {
                let pv = f.req("path")?;
                let scale = f.opt("scale").map(|s| f64_in(s, "scale", 0.0, 1e9)).transpose()?.unwrap_or(1.0) as f32;
                let (p, bytes) = self.read_file(pv)?;
                let img = decode_image(&p, &bytes).map_err(|m| at(pv, m))?;
                Environment::Map(EnvMap::from_image(&img, scale).map_err(|m| at(pv, format!("{}: {m}", p.display())))?)
            }
            _ => {
                let sky = Sky {
                    zenith: rgb(f.req("zenith")?, "zenith", 1e9)?,
                    horizon: rgb(f.req("horizon")?, "horizon", 1e9)?,
                    ground: f.opt("ground").map(|g| rgb(g, "ground", 1e9)).transpose()?.unwrap_or(Vec3::ZERO),
                    sun_direction: f.opt("sun_direction").map(|d| vec3(d, "sun_direction", false)).transpose()?.unwrap_or(Vec3::Y),
                    sun_radiance: f.opt("sun_radiance").map(|s| rgb(s, "sun_radiance", 1e9)).transpose()?.unwrap_or(Vec3::ZERO),
                    sun_radius_deg: f.opt("sun_radius").map(|s| f64_in(s, "sun_radius", 0.01, 45.0)).transpose()?.unwrap_or(1.5) as f32,
                    width: f.opt("width").map(|w| usize_in(w, "width", 8, 8192)).transpose()?.unwrap_or(512),
                };
                Environment::Map(sky.bake().map_err(|m| at(v, m))?)
            }
        };
        f.finish(&["radiance", "path", "scale", "zenith", "horizon", "ground", "sun_direction", "sun_radiance", "sun_radius", "width"])?;
        Ok(env)
    }

    fn finish(self) -> Result<LoadedScene, String> {
        let mut notes = Vec::new();
        if self.dropped > 0 {
            notes.push(format!("{} zero-area triangles dropped", self.dropped));
        }
        if self.triangles.is_empty() {
            return Err(format!("{}: the scene has no triangles", self.scene_file.display()));
        }
        let tri_object = self.objects.iter().enumerate().flat_map(|(i, o)| o.triangles.clone().map(move |_| i as u32)).collect();
        let scene = Scene {
            objects: self.objects,
            positions: self.positions,
            normals: self.normals,
            uvs: self.uvs,
            triangles: self.triangles,
            tri_object,
            lights: self.lights,
            environment: self.environment,
            camera: self.camera.expect("camera is required"),
            derived: Default::default(),
        };
        if !scene.has_lights() {
            notes.push("the scene has no light: every image of it is black".into());
        }
        Ok(LoadedScene { scene, files: self.files, notes })
    }
}

fn read_camera(v: &Ron) -> Result<Camera, LoadError> {
    let mut f = Fields::new(v, "camera")?;
    let cam = Camera {
        origin: vec3(f.req("origin")?, "origin", false)?,
        target: vec3(f.req("target")?, "target", false)?,
        up: vec3(f.req("up")?, "up", false)?,
        fov_deg: f64_in(f.req("fov")?, "fov", 0.01, 179.0)? as f32,
        width: usize_in(f.req("width")?, "width", 1, 16384)?,
        height: usize_in(f.req("height")?, "height", 1, 16384)?,
    };
    f.finish(&["origin", "target", "up", "fov", "width", "height"])?;
    let dir = cam.target - cam.origin;
    if dir.length_squared() == 0.0 || dir.cross(cam.up).length_squared() == 0.0 {
        return Err(at(v, "camera: origin equals target, or up is parallel to the view direction"));
    }
    Ok(cam)
}

/// A material and its texture-map fields (`kd_map`, `ks_map`, `exponent_map`: image paths).
fn read_material(v: &Ron) -> Result<(Material, [Option<&Ron>; 3]), LoadError> {
    let (kind, v) = variant(v, "material", &["Lambert", "BlinnPhong", "CookTorrance", "Dielectric"])?;
    let mut f = Fields::new(v, kind)?;
    let maps = [f.opt("kd_map"), f.opt("ks_map"), f.opt("exponent_map")];
    let m = match kind {
        "Lambert" => Material::Lambert { albedo: rgb(f.req("albedo")?, "albedo", 1.0)? },
        "BlinnPhong" | "CookTorrance" => {
            let kd = rgb(f.req("kd")?, "kd", 1.0)?;
            let ks = rgb(f.req("ks")?, "ks", 1.0)?;
            if (kd + ks).max_element() > 1.0 + 1e-6 {
                return Err(at(v, format!("kd + ks = {} exceeds 1: the material would create energy", kd + ks)));
            }
            if kind == "BlinnPhong" {
                Material::BlinnPhong { kd, ks, exponent: f64_in(f.req("exponent")?, "exponent", 1.0, 1e6)? as f32 }
            } else {
                let roughness = f64_in(f.req("roughness")?, "roughness", 1e-4, 1.0)? as f32;
                let f0 = f.opt("f0").map(|x| f64_in(x, "f0", 0.0, 1.0)).transpose()?.unwrap_or(0.04) as f32;
                Material::CookTorrance { kd, ks, roughness, f0 }
            }
        }
        _ => {
            // The index inside over the index around: below 1 for an object of lower index
            // nested in a denser one (a bubble in glass).
            let ior = f64_in(f.req("ior")?, "ior", 0.25, 4.0)? as f32;
            let sa = f.opt("sigma_a").map(|x| rgb(x, "sigma_a", 1e6)).transpose()?;
            let ss = f.opt("sigma_s").map(|x| rgb(x, "sigma_s", 1e6)).transpose()?;
            let medium =
                (sa.is_some() || ss.is_some()).then(|| Medium { sigma_a: sa.unwrap_or(Vec3::ZERO), sigma_s: ss.unwrap_or(Vec3::ZERO) });
            Material::Dielectric { ior, medium }
        }
    };
    f.finish(&["albedo", "kd", "ks", "exponent", "roughness", "f0", "ior", "sigma_a", "sigma_s", "kd_map", "ks_map", "exponent_map"])?;
    Ok((m, maps))
}

fn read_light(v: &Ron) -> Result<Light, LoadError> {
    let (kind, v) = variant(v, "light", &["Point", "Spot", "Directional"])?;
    let mut f = Fields::new(v, kind)?;
    let l = match kind {
        "Point" => {
            Light::Point { position: vec3(f.req("position")?, "position", false)?, intensity: rgb(f.req("intensity")?, "intensity", 1e12)? }
        }
        "Spot" => {
            let position = vec3(f.req("position")?, "position", false)?;
            let target = vec3(f.req("target")?, "target", false)?;
            let cutoff = f64_in(f.req("cutoff")?, "cutoff", 0.1, 90.0)?;
            let beam = f.opt("beam_width").map(|b| f64_in(b, "beam_width", 0.0, cutoff)).transpose()?.unwrap_or(cutoff * 0.75);
            let direction = (target - position).try_normalize().ok_or_else(|| at(v, "spot: target equals position"))?;
            Light::Spot {
                position,
                direction,
                intensity: rgb(f.req("intensity")?, "intensity", 1e12)?,
                cos_inner: beam.to_radians().cos() as f32,
                cos_outer: cutoff.to_radians().cos() as f32,
            }
        }
        _ => {
            let d = vec3(f.req("direction")?, "direction", false)?;
            Light::Directional {
                direction: d.try_normalize().ok_or_else(|| at(v, "direction must not be zero"))?,
                irradiance: rgb(f.req("irradiance")?, "irradiance", 1e12)?,
            }
        }
    };
    f.finish(&["position", "intensity", "target", "cutoff", "beam_width", "direction", "irradiance"])?;
    Ok(l)
}

fn read_transform(v: &Ron) -> Result<Mat4, LoadError> {
    let mut m = Mat4::IDENTITY;
    for op in list_of(v, "transform")? {
        let (kind, op) = variant(op, "transform", &["Translate", "Scale", "Rotate"])?;
        let relume_core::ron::RonKind::Tuple(_, args) = &op.kind else {
            return Err(at(op, format!("write {kind}(…) with its arguments in parentheses")));
        };
        let step = match (kind, args.as_slice()) {
            ("Translate", [t]) => Mat4::from_translation(vec3(t, "Translate", false)?),
            ("Scale", [s]) => {
                let s = vec3(s, "Scale", true)?;
                if s.x * s.y * s.z == 0.0 {
                    return Err(at(op, "a zero scale flattens the shape"));
                }
                Mat4::from_scale(s)
            }
            ("Rotate", [axis, deg]) => {
                let a = vec3(axis, "Rotate axis", false)?.try_normalize().ok_or_else(|| at(axis, "rotation axis must not be zero"))?;
                Mat4::from_axis_angle(a, (f64_of(deg, "Rotate angle")? as f32).to_radians())
            }
            _ => return Err(at(op, format!("{kind} takes {}", if kind == "Rotate" { "(axis, degrees)" } else { "one argument" }))),
        };
        m *= step;
    }
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_radiance_hdr_environment_and_a_procedural_sky_load() {
        let dir = tempfile::tempdir().unwrap();
        let texels: Vec<image::Rgb<f32>> = (0..8 * 4).map(|i| image::Rgb([i as f32 * 0.5, 1.0, 2.0])).collect();
        let f = std::fs::File::create(dir.path().join("sky.hdr")).unwrap();
        image::codecs::hdr::HdrEncoder::new(f).encode(&texels, 8, 4).unwrap();
        std::fs::write(dir.path().join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let head = "Scene(camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8), materials: { \"m\": Lambert(albedo: 0.5) }, shapes: [Obj(path: \"tri.obj\", material: \"m\")],";
        std::fs::write(dir.path().join("a.ron"), format!("{head} environment: Map(path: \"sky.hdr\", scale: 2))")).unwrap();
        let s = load_scene_file(&dir.path().join("a.ron")).unwrap();
        let Some(Environment::Map(m)) = &s.scene.environment else { panic!("a map") };
        assert_eq!((m.width, m.height), (8, 4));
        let top_left = m.texels[0];
        assert!((top_left - Vec3::new(0.0, 2.0, 4.0)).length() < 0.05, "scaled by 2: {top_left}");
        assert!(s.files.iter().any(|(p, _)| p.ends_with("sky.hdr")), "the map is a cache dependency");
        std::fs::write(
            dir.path().join("b.ron"),
            format!(
                "{head} environment: Sky(zenith: (0.1, 0.2, 0.6), horizon: 1, sun_radiance: 1000, sun_direction: (0, 1, 1), width: 64))"
            ),
        )
        .unwrap();
        let s = load_scene_file(&dir.path().join("b.ron")).unwrap();
        let Some(Environment::Map(m)) = &s.scene.environment else { panic!("a baked sky") };
        let brightest = m.texels.iter().map(|t| t.x).fold(0.0, f32::max);
        assert!(brightest > 10.0, "the sun is baked in even when smaller than a texel: {brightest}");
    }

    #[test]
    fn a_dielectric_nested_in_a_denser_one_has_an_index_below_one_down_to_a_quarter() {
        let dir = tempfile::tempdir().unwrap();
        let scene = |ior: &str| {
            let text = format!(
                "Scene(camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8), materials: {{ \"glass\": Dielectric(ior: 1.5), \"bubble\": Dielectric(ior: {ior}) }}, shapes: [Sphere(center: (0, 0, 0), radius: 1, material: \"glass\"), Sphere(center: (0, 0, 0), radius: 0.5, material: \"bubble\")])"
            );
            std::fs::write(dir.path().join("a.ron"), text).unwrap();
            load_scene_file(&dir.path().join("a.ron")).map(|s| s.scene)
        };
        let s = scene("0.6667").unwrap();
        assert!(s.objects.iter().any(|o| matches!(o.material, Material::Dielectric { ior, .. } if (ior - 0.6667).abs() < 1e-6)));
        let err = scene("0.2").unwrap_err();
        assert!(err.contains("ior"), "{err}");
    }
}

#[cfg(test)]
mod subdivide_tests {
    use super::*;

    fn load(shape: &str) -> Result<Scene, String> {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("quad.obj"), "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3\nf 1 3 4\n").unwrap();
        let text = format!(
            "Scene(camera: (origin: (0, 0, 3), target: (0, 0, 0), up: (0, 1, 0), fov: 40, width: 8, height: 8), materials: {{ \"m\": Lambert(albedo: 0.5) }}, shapes: [{shape}])"
        );
        std::fs::write(dir.path().join("a.ron"), text).unwrap();
        load_scene_file(&dir.path().join("a.ron")).map(|s| s.scene)
    }

    #[test]
    fn an_obj_shape_subdivides_into_four_times_the_triangles_a_level() {
        let plain = load("Obj(path: \"quad.obj\", material: \"m\")").unwrap();
        let fine = load("Obj(path: \"quad.obj\", material: \"m\", subdivide: 3)").unwrap();
        assert_eq!((plain.triangles.len(), fine.triangles.len()), (2, 2 * 64));
        let area = |s: &Scene| (0..s.triangles.len()).map(|t| s.normal_area(t).1).sum::<f32>();
        assert!((area(&fine) - area(&plain)).abs() < 1e-5, "the same surface");
    }

    #[test]
    fn subdivision_past_its_levels_or_on_a_sphere_is_refused() {
        let err = load("Obj(path: \"quad.obj\", material: \"m\", subdivide: 5)").unwrap_err();
        assert!(err.contains("subdivide"), "{err}");
        let err = load("Sphere(center: (0, 0, 0), radius: 1, material: \"m\", subdivide: 1)").unwrap_err();
        assert!(err.contains("rings"), "{err}");
    }
}
