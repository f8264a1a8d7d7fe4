//! OBJ (+ MTL) loading through tobj, after a line-by-line check that names the line of any
//! malformed or non-finite vertex and any face index out of range.

use crate::types::Material;
use glam::{Vec2, Vec3};
use std::path::Path;

/// One `o`/`g` group of an OBJ file, in the file's own coordinates.
pub struct ObjModel {
    pub name: String,
    pub positions: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    pub triangles: Vec<[u32; 3]>,
    /// Material from the MTL file (Kd → Lambert), if any.
    pub material: Option<Material>,
    /// Ke from the MTL file.
    pub emission: Vec3,
}

/// Checks `v`, `vt` and `f` lines; the error names the line.
pub fn check_obj_text(path: &Path, text: &str) -> Result<(), String> {
    let (mut nv, mut nvt) = (0i64, 0i64);
    for (i, line) in text.lines().enumerate() {
        let at = || format!("{}:{}", path.display(), i + 1);
        let mut words = line.split_whitespace();
        match words.next() {
            Some(tag @ ("v" | "vt" | "vn")) => {
                let nums: Vec<&str> = words.collect();
                let need = if tag == "vt" { 2 } else { 3 };
                if nums.len() < need {
                    return Err(format!("{}: `{tag}` needs {need} numbers, found {}", at(), nums.len()));
                }
                for w in &nums[..need] {
                    match w.parse::<f32>() {
                        Ok(x) if x.is_finite() => {}
                        Ok(_) => return Err(format!("{}: `{tag}` has a non-finite value `{w}`", at())),
                        Err(_) => return Err(format!("{}: `{w}` in `{tag}` is not a number", at())),
                    }
                }
                match tag {
                    "v" => nv += 1,
                    "vt" => nvt += 1,
                    _ => {}
                }
            }
            Some("f") => {
                let corners: Vec<&str> = words.collect();
                if corners.len() < 3 {
                    return Err(format!("{}: a face needs at least 3 corners, found {}", at(), corners.len()));
                }
                for c in corners {
                    let mut parts = c.split('/');
                    for (k, limit) in [(0, nv), (1, nvt)] {
                        let Some(p) = parts.next() else { break };
                        if p.is_empty() && k > 0 {
                            continue;
                        }
                        let idx: i64 = p.parse().map_err(|_| format!("{}: face index `{c}` is not a number", at()))?;
                        let ok = (idx > 0 && idx <= limit) || (idx < 0 && -idx <= limit);
                        if !ok {
                            return Err(format!(
                                "{}: face index {idx} refers to a {} that does not exist (only {limit} so far)",
                                at(),
                                if k == 0 { "vertex" } else { "texture coordinate" }
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    if nv == 0 {
        return Err(format!("{}: no vertices: not an OBJ mesh", path.display()));
    }
    Ok(())
}

/// Loads every group of an OBJ file. `text` is the file's content (already read, so that the
/// caller can hash it).
pub fn load_obj(path: &Path, text: &str) -> Result<Vec<ObjModel>, String> {
    check_obj_text(path, text)?;
    let opts = tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true };
    let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
    let mut reader = std::io::BufReader::new(text.as_bytes());
    let (models, mats) =
        tobj::load_obj_buf(&mut reader, &opts, |mtl| tobj::load_mtl(dir.join(mtl))).map_err(|e| format!("{}: {e}", path.display()))?;
    let mats = mats.map_err(|e| format!("{}: its material library: {e}", path.display()))?;
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let mut out = Vec::new();
    for m in models {
        let mesh = m.mesh;
        let positions: Vec<Vec3> = mesh.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let uvs = mesh.texcoords.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])).collect();
        let triangles = mesh.indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let mtl = mesh.material_id.and_then(|i| mats.get(i));
        let material = mtl.and_then(|m| m.diffuse).map(|kd| Material::Lambert { albedo: Vec3::from(kd) });
        let emission = mtl.and_then(|m| m.emissive).map(Vec3::from).unwrap_or(Vec3::ZERO);
        let name = if m.name.is_empty() || m.name == "unnamed_object" { stem.clone() } else { m.name };
        out.push(ObjModel { name, positions, uvs, triangles, material, emission });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn malformed_lines_are_named_by_line_number() {
        let p = Path::new("m.obj");
        assert!(check_obj_text(p, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").is_ok());
        let e = check_obj_text(p, "v 0 0 0\nv 1 nan 0\n").unwrap_err();
        assert!(e.starts_with("m.obj:2: `v` has a non-finite value"), "{e}");
        let e = check_obj_text(p, "v 0 0 0\nv 1 x 0\n").unwrap_err();
        assert!(e.contains("m.obj:2: `x` in `v` is not a number"), "{e}");
        let e = check_obj_text(p, "v 0 0 0\nv 1 0 0\nf 1 2 7\n").unwrap_err();
        assert!(e.contains("m.obj:3: face index 7 refers to a vertex that does not exist"), "{e}");
        assert!(check_obj_text(p, "# nothing\n").unwrap_err().contains("no vertices"));
    }

    #[test]
    fn groups_become_models_with_their_mtl_colours_and_emission() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("m.mtl"), "newmtl a\nKd 0.5 0.25 0.125\nnewmtl lamp\nKd 0.1 0.1 0.1\nKe 4 5 6\n").unwrap();
        let text = "mtllib m.mtl\no one\nusemtl a\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nf 1 2 4 3\no two\nusemtl lamp\nf 1 2 3\n";
        let models = load_obj(&dir.path().join("m.obj"), text).unwrap();
        assert_eq!(models.len(), 2);
        assert_eq!(models[0].name, "one");
        assert_eq!(models[0].triangles.len(), 2, "the quad is triangulated");
        assert_eq!(models[0].material, Some(Material::Lambert { albedo: Vec3::new(0.5, 0.25, 0.125) }));
        assert_eq!(models[1].emission, Vec3::new(4.0, 5.0, 6.0));
    }
}
