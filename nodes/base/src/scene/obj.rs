//! OBJ (+ MTL) loading. A line-by-line pass over the OBJ names the line of anything wrong
//! (unknown statements, malformed or non-finite numbers, face indices out of range, a
//! missing material library, an undefined `usemtl`); the MTL files are read and checked here
//! too (colours finite and in range, with their line); tobj then builds the meshes from text
//! that is known to be good, with the materials handed to it from this pass.

use crate::types::Material;
use glam::{Vec2, Vec3};
use std::cell::Cell;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

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

/// An OBJ file's groups and the material libraries it read (path and content), which are
/// dependencies of whatever is made from it.
pub struct ObjFile {
    pub models: Vec<ObjModel>,
    pub libraries: Vec<(PathBuf, Vec<u8>)>,
}

/// One `newmtl` of an MTL file, with what relume uses of it.
#[derive(Clone, Debug, PartialEq)]
pub struct MtlMaterial {
    pub name: String,
    /// Kd, in [0, 1].
    pub diffuse: Option<Vec3>,
    /// Ke, in [0, 1e9].
    pub emission: Option<Vec3>,
}

/// The most an MTL emission (Ke) may be: the same bound a scene file puts on `emission`.
const MAX_EMISSION: f32 = 1e9;

/// Statements of the OBJ format that relume reads or deliberately ignores.
/// `s` (smoothing groups) is ignored because normals come from `crease_angle`; `vp`, `p`
/// and `l` have no area; the rest are display and rendering hints.
const IGNORED_OBJ: &[&str] =
    &["s", "vp", "p", "l", "mg", "lod", "bevel", "c_interp", "d_interp", "shadow_obj", "trace_obj", "usemap", "maplib"];
const FREE_FORM_OBJ: &[&str] =
    &["cstype", "deg", "bmat", "step", "curv", "curv2", "surf", "parm", "trim", "hole", "scrv", "sp", "end", "con", "ctech", "stech"];

/// Parses one number of `tag`; the error names the line.
fn number(at: &dyn Fn() -> String, tag: &str, w: &str) -> Result<f32, String> {
    match w.parse::<f32>() {
        Ok(x) if x.is_finite() => Ok(x),
        Ok(_) => Err(format!("{}: `{tag}` has a non-finite value {}", at(), word(w))),
        Err(_) => Err(format!("{}: {} in `{tag}` is not a number", at(), word(w))),
    }
}

/// Reads an MTL file's text. Colours must be `r g b` (or one grey value) of finite numbers;
/// Kd must lie in [0, 1] and Ke in [0, 1e9], as albedo and emission do in a scene file.
/// Errors read `file:line: message`.
pub fn parse_mtl(path: &Path, text: &str) -> Result<Vec<MtlMaterial>, String> {
    let mut out: Vec<MtlMaterial> = Vec::new();
    let mut defined_at: HashMap<String, usize> = HashMap::new();
    for (i, line) in text.lines().enumerate() {
        let at = || format!("{}:{}", path.display(), i + 1);
        let line = line.trim();
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else { continue };
        if tag.starts_with('#') {
            continue;
        }
        if tag == "newmtl" {
            let name = line[tag.len()..].trim();
            if name.is_empty() {
                return Err(format!("{}: `newmtl` needs a material name", at()));
            }
            if let Some(first) = defined_at.insert(name.to_string(), i + 1) {
                return Err(format!("{}: material \"{name}\" is defined twice (first at line {first}); rename one", at()));
            }
            out.push(MtlMaterial { name: name.to_string(), diffuse: None, emission: None });
            continue;
        }
        let lower = tag.to_ascii_lowercase();
        let known_colour = matches!(lower.as_str(), "ka" | "kd" | "ks" | "ke" | "tf");
        let known_scalar = matches!(
            lower.as_str(),
            "ns" | "ni" | "d" | "tr" | "sharpness" | "illum" | "pr" | "pm" | "ps" | "pc" | "pcr" | "aniso" | "anisor"
        );
        let known_map = lower.starts_with("map_") || matches!(lower.as_str(), "bump" | "disp" | "decal" | "refl" | "norm");
        if !(known_colour || known_scalar || known_map) {
            return Err(format!(
                "{}: {} is not an MTL statement (known: newmtl, Kd, Ke, Ka, Ks, Tf, Ns, Ni, d, Tr, illum, map_…, bump, disp, refl)",
                at(),
                word(tag)
            ));
        }
        let Some(cur) = out.last_mut() else {
            return Err(format!("{}: `{tag}` comes before any `newmtl NAME`", at()));
        };
        let args: Vec<&str> = words.collect();
        if known_colour {
            if let Some(&w @ ("spectral" | "xyz")) = args.first() {
                return Err(format!("{}: `{tag} {w} …` colours are not supported: write `{tag} r g b`", at()));
            }
            let c = match args.as_slice() {
                [g] => Vec3::splat(number(&at, tag, g)?),
                [r, g, b] => Vec3::new(number(&at, tag, r)?, number(&at, tag, g)?, number(&at, tag, b)?),
                _ => return Err(format!("{}: `{tag}` takes r g b (or one grey value), found {} values", at(), args.len())),
            };
            let max = match lower.as_str() {
                "kd" => 1.0,
                "ke" => MAX_EMISSION,
                _ => f32::INFINITY,
            };
            if c.min_element() < 0.0 || c.max_element() > max {
                let range = if max == f32::INFINITY { "[0, ∞)".to_string() } else { format!("[0, {max}]") };
                return Err(format!("{}: `{tag}` = {} {} {} must lie in {range}", at(), c.x, c.y, c.z));
            }
            match lower.as_str() {
                "kd" => cur.diffuse = Some(c),
                "ke" => cur.emission = Some(c),
                _ => {}
            }
        } else if known_scalar {
            match args.as_slice() {
                [w] => {
                    number(&at, tag, w)?;
                }
                _ => return Err(format!("{}: `{tag}` takes one number, found {} values", at(), args.len())),
            }
        } else if args.is_empty() {
            return Err(format!("{}: `{tag}` needs a file name", at()));
        }
    }
    Ok(out)
}

/// The material libraries named on an `mtllib` line: the whole rest of the line when such a
/// file exists (names with spaces), otherwise each whitespace-separated name.
fn library_names(rest: &str, dir: &Path, exists: &dyn Fn(&Path) -> bool) -> Vec<String> {
    if exists(&dir.join(rest)) || !rest.contains(char::is_whitespace) {
        vec![rest.to_string()]
    } else {
        rest.split_whitespace().map(str::to_string).collect()
    }
}

/// What the line-by-line pass learned: the materials of each `mtllib` line in order (tobj
/// asks for them in that order), the libraries read, and the text to give tobj (with lines
/// it would misread rewritten; borrowed when none are).
struct Checked<'t> {
    per_mtllib: Vec<Vec<MtlMaterial>>,
    libraries: Vec<(PathBuf, Vec<u8>)>,
    text: std::borrow::Cow<'t, str>,
}

/// Checks an OBJ text line by line; every error names the file and line. Material libraries
/// are read with `read` (relative to the OBJ's folder) and checked with `parse_mtl`.
fn check_obj<'t>(path: &Path, text: &'t str, read: &dyn Fn(&Path) -> std::io::Result<Vec<u8>>) -> Result<Checked<'t>, String> {
    let dir = path.parent().unwrap_or(Path::new("."));
    let (mut nv, mut nvt, mut nvn) = (0i64, 0i64, 0i64);
    let mut per_mtllib: Vec<Vec<MtlMaterial>> = Vec::new();
    let mut libraries: Vec<(PathBuf, Vec<u8>)> = Vec::new();
    // Lines tobj would misread (leading blanks or a tab after the keyword of `o`, `g`,
    // `usemtl`, `mtllib`; `l` polylines, which it turns into faces; vertex colours on only
    // some vertices, which fail): (index, replacement).
    let mut rewrite: Vec<(usize, String)> = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let at = || format!("{}:{}", path.display(), i + 1);
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else { continue };
        match tag {
            "v" => {
                let nums = words.map(|w| number(&at, tag, w)).collect::<Result<Vec<f32>, String>>()?;
                match nums.len() {
                    3 => {}
                    // Vertex colours: relume does not use them, and tobj fails on a file
                    // where only some vertices have them; keep x y z.
                    6 => rewrite.push((i, format!("v {} {} {}", nums[0], nums[1], nums[2]))),
                    4 => {
                        let w = nums[3];
                        if w == 0.0 || nums[..3].iter().any(|x| !(x / w).is_finite()) {
                            return Err(format!("{}: `v` with w = {w} gives a non-finite position", at()));
                        }
                    }
                    n => return Err(format!("{}: `v` takes x y z (or x y z w, or x y z r g b), found {} numbers", at(), n)),
                }
                nv += 1;
            }
            "vt" | "vn" => {
                let nums = words.map(|w| number(&at, tag, w)).collect::<Result<Vec<f32>, String>>()?;
                let ok = if tag == "vt" { (2..=3).contains(&nums.len()) } else { nums.len() == 3 };
                if !ok {
                    let want = if tag == "vt" { "u v (or u v w)" } else { "x y z" };
                    return Err(format!("{}: `{tag}` takes {want}, found {} numbers", at(), nums.len()));
                }
                if tag == "vt" {
                    nvt += 1
                } else {
                    nvn += 1
                }
            }
            "f" => {
                let corners: Vec<&str> = words.collect();
                if corners.len() < 3 {
                    return Err(format!("{}: a face needs at least 3 corners, found {}", at(), corners.len()));
                }
                for c in corners {
                    for (k, p) in c.split('/').enumerate() {
                        if k > 2 {
                            return Err(format!("{}: face corner {} has more than v/vt/vn", at(), word(c)));
                        }
                        if p.is_empty() && k > 0 {
                            continue;
                        }
                        let idx: i64 = p.parse().map_err(|_| format!("{}: face index {} is not a number", at(), word(c)))?;
                        let (limit, what) = [(nv, "vertex"), (nvt, "texture coordinate"), (nvn, "normal")][k];
                        let ok = (idx > 0 && idx <= limit) || (idx < 0 && idx.checked_neg().is_some_and(|n| n <= limit));
                        if !ok {
                            return Err(format!("{}: face index {idx} refers to a {what} that does not exist (only {limit} so far)", at()));
                        }
                    }
                }
            }
            "#" => {}
            _ if tag.starts_with('#') => {}
            "o" | "g" | "usemtl" | "mtllib" => {
                let rest = line.trim()[tag.len()..].trim();
                if !line.starts_with(&format!("{tag} ")) {
                    rewrite.push((i, format!("{tag} {rest}")));
                }
                if tag == "usemtl" {
                    if rest.is_empty() {
                        return Err(format!("{}: `usemtl` needs a material name", at()));
                    }
                    let defined: Vec<&str> = per_mtllib.iter().flatten().map(|m| m.name.as_str()).collect();
                    if !defined.contains(&rest) {
                        return Err(if libraries.is_empty() {
                            format!(
                                "{}: `usemtl {rest}`: material \"{rest}\" is not defined: no material library is loaded above this line (add `mtllib FILE.mtl` before it)",
                                at()
                            )
                        } else {
                            let libs: Vec<String> =
                                libraries.iter().map(|(p, _)| p.file_name().unwrap_or_default().to_string_lossy().into_owned()).collect();
                            format!(
                                "{}: `usemtl {rest}`: material \"{rest}\" is not defined in {} (it defines: {})",
                                at(),
                                libs.join(", "),
                                if defined.is_empty() { "nothing".to_string() } else { defined.join(", ") }
                            )
                        });
                    }
                } else if tag == "mtllib" {
                    if rest.is_empty() {
                        return Err(format!("{}: `mtllib` needs a file name", at()));
                    }
                    let mut mats = Vec::new();
                    for name in library_names(rest, dir, &|p| p.is_file()) {
                        let p = dir.join(&name);
                        let bytes = read(&p).map_err(|e| {
                            let full = if p == Path::new(&name) { String::new() } else { format!(" ({})", p.display()) };
                            format!(
                                "{}: cannot read the material library \"{name}\"{full}: {e}; put it beside the OBJ, or remove the `mtllib` line and give each object a `material:` in the scene file",
                                at()
                            )
                        })?;
                        let mtl = std::str::from_utf8(&bytes).map_err(|_| format!("{}: not UTF-8 text", p.display()))?;
                        mats.extend(parse_mtl(&p, mtl)?);
                        libraries.push((p, bytes));
                    }
                    per_mtllib.push(mats);
                }
            }
            "l" => rewrite.push((i, String::new())),
            _ if IGNORED_OBJ.contains(&tag) => {}
            _ if FREE_FORM_OBJ.contains(&tag) => {
                return Err(format!(
                    "{}: free-form geometry (`{tag}`) is not supported: export the model as polygons (triangles or quads)",
                    at()
                ))
            }
            _ => {
                return Err(format!(
                    "{}: {} is not an OBJ statement (expected v, vt, vn, f, o, g, usemtl, mtllib, s or a # comment)",
                    at(),
                    word(tag)
                ));
            }
        }
    }
    if nv == 0 {
        return Err(format!("{}: no vertices: not an OBJ mesh", path.display()));
    }
    let text = if rewrite.is_empty() {
        std::borrow::Cow::Borrowed(text)
    } else {
        let mut lines: Vec<&str> = text.lines().collect();
        for (i, r) in &rewrite {
            lines[*i] = r;
        }
        std::borrow::Cow::Owned(lines.join("\n"))
    };
    Ok(Checked { per_mtllib, libraries, text })
}

/// Checks an OBJ text line by line (reading its MTL files from disk); the error names the
/// file and line.
pub fn check_obj_text(path: &Path, text: &str) -> Result<(), String> {
    check_obj(path, text, &|p| relume_core::read_input(p)).map(|_| ())
}

/// Loads every group of an OBJ file. `text` is the file's content (already read, so that the
/// caller can hash it).
pub fn load_obj(path: &Path, text: &str) -> Result<Vec<ObjModel>, String> {
    load_obj_file(path, text).map(|f| f.models)
}

/// As `load_obj`, also returning the material libraries it read.
pub fn load_obj_file(path: &Path, text: &str) -> Result<ObjFile, String> {
    let checked = check_obj(path, text, &|p| relume_core::read_input(p))?;
    let opts = tobj::LoadOptions { triangulate: true, single_index: true, ignore_points: true, ignore_lines: true };
    let mut reader = std::io::BufReader::new(checked.text.as_bytes());
    // tobj asks for the libraries in the order of the `mtllib` lines; hand it the materials
    // this pass already read and checked.
    let next = Cell::new(0);
    let all: Vec<&MtlMaterial> = checked.per_mtllib.iter().flatten().collect();
    let (models, mats) = tobj::load_obj_buf(&mut reader, &opts, |_| {
        let k = next.get();
        next.set(k + 1);
        let mats = checked.per_mtllib.get(k).map(Vec::as_slice).unwrap_or_default();
        let map = mats.iter().enumerate().map(|(i, m)| (m.name.clone(), i)).collect();
        Ok((mats.iter().map(|m| tobj::Material { name: m.name.clone(), ..Default::default() }).collect(), map))
    })
    .map_err(|e| format!("{}: {e}", path.display()))?;
    let mats = mats.map_err(|e| format!("{}: its material library: {e}", path.display()))?;
    debug_assert_eq!(mats.len(), all.len());
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let mut out = Vec::new();
    for m in models {
        let mesh = m.mesh;
        let positions: Vec<Vec3> = mesh.positions.chunks_exact(3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let uvs = mesh.texcoords.chunks_exact(2).map(|c| Vec2::new(c[0], c[1])).collect();
        let triangles = mesh.indices.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
        let mtl = mesh.material_id.and_then(|i| all.get(i));
        let material = mtl.and_then(|m| m.diffuse).map(|kd| Material::Lambert { albedo: kd });
        let emission = mtl.and_then(|m| m.emission).unwrap_or(Vec3::ZERO);
        let name = if m.name.is_empty() || m.name == "unnamed_object" { stem.clone() } else { m.name };
        out.push(ObjModel { name, positions, uvs, triangles, material, emission });
    }
    Ok(ObjFile { models: out, libraries: checked.libraries })
}

/// How a message quotes a word taken from the file: whole when it is short and plain (a
/// misspelt keyword, a number), else only its length, so that an error never repeats what a
/// file holds (a graph may point a mesh at a file that is not one).
fn word(w: &str) -> String {
    if w.len() <= 12 && w.chars().all(|c| c.is_ascii_alphanumeric() || "_-+./".contains(c)) {
        format!("`{w}`")
    } else {
        format!("a word of {} characters", w.chars().count())
    }
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

    /// Writes `m.obj` (and `m.mtl` when given) into a fresh folder and loads the OBJ.
    fn load(obj: &str, mtl: Option<&str>) -> Result<ObjFile, String> {
        let dir = tempfile::tempdir().unwrap();
        if let Some(m) = mtl {
            std::fs::write(dir.path().join("m.mtl"), m).unwrap();
        }
        let p = dir.path().join("m.obj");
        load_obj_file(&p, obj).map_err(|e| e.replace(&format!("{}/", dir.path().display()), ""))
    }

    const TRI: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

    #[test]
    fn mtl_colours_must_be_finite_and_in_range_with_the_mtl_line() {
        let obj = format!("mtllib m.mtl\n{TRI}usemtl a\nf 1 2 3\n");
        let e = load(&obj, Some("newmtl a\n# albedo\nKd -5 nan 2\n")).err().unwrap();
        assert_eq!(e, "m.mtl:3: `Kd` has a non-finite value `nan`");
        let e = load(&obj, Some("newmtl a\nKd 0.5 0.5 0.5\nKe inf 0 0\n")).err().unwrap();
        assert_eq!(e, "m.mtl:3: `Ke` has a non-finite value `inf`");
        let e = load(&obj, Some("newmtl a\nKd -5 0 2\n")).err().unwrap();
        assert_eq!(e, "m.mtl:2: `Kd` = -5 0 2 must lie in [0, 1]");
        let e = load(&obj, Some("newmtl a\nKd 0.5 0.5 0.5\nKe 1e10 0 0\n")).err().unwrap();
        assert_eq!(e, "m.mtl:3: `Ke` = 10000000000 0 0 must lie in [0, 1000000000]");
        // One value is a grey.
        let f = load(&obj, Some("newmtl a\nKd 0.25\n")).unwrap();
        assert_eq!(f.models[0].material, Some(Material::Lambert { albedo: Vec3::splat(0.25) }));
        assert!(f.libraries[0].0.ends_with("m.mtl"), "the MTL is reported as read");
    }

    /// Found by `cargo fuzz run obj_loader`: tobj's MTL reader unwraps a colour of fewer
    /// than three numbers (`Ks` alone, `Kd 0.5 0.5`) and panics. Minimised crash input:
    /// `mtllib m.mtl\nv -0 0 1` NUL `Ks`.
    #[test]
    fn fuzz_crash_mtl_colour_with_too_few_numbers_is_an_error() {
        let e = load("mtllib m.mtl\nv -0 0 1", Some("Ks")).err().unwrap();
        assert_eq!(e, "m.mtl:1: `Ks` comes before any `newmtl NAME`");
        let obj = format!("mtllib m.mtl\n{TRI}usemtl a\nf 1 2 3\n");
        let e = load(&obj, Some("newmtl a\nKs\n")).err().unwrap();
        assert_eq!(e, "m.mtl:2: `Ks` takes r g b (or one grey value), found 0 values");
        let e = load(&obj, Some("newmtl a\nKd 0.5 0.5\n")).err().unwrap();
        assert_eq!(e, "m.mtl:2: `Kd` takes r g b (or one grey value), found 2 values");
    }

    #[test]
    fn garbage_lines_are_reported_with_their_line() {
        let e = load(&format!("{TRI}hello world\nf 1 2 3\n"), None).err().unwrap();
        assert_eq!(e, "m.obj:4: `hello` is not an OBJ statement (expected v, vt, vn, f, o, g, usemtl, mtllib, s or a # comment)");
        // A line from a file that is not a mesh is never repeated.
        let e = load("root:x:0:0:root:/root:/bin/bash\n", None).err().unwrap();
        assert!(e.starts_with("m.obj:1: a word of 31 characters is not an OBJ statement"), "{e}");
        let e = load(&format!("{TRI}curv 0 1 1 2\n"), None).err().unwrap();
        assert!(e.starts_with("m.obj:4: free-form geometry (`curv`) is not supported"), "{e}");
        let e = load(&format!("{TRI}v 1 2\n"), None).err().unwrap();
        assert_eq!(e, "m.obj:4: `v` takes x y z (or x y z w, or x y z r g b), found 2 numbers");
        let e = load(&format!("{TRI}v 1 2 3 1e-40\n"), None).err().unwrap();
        assert!(e.starts_with("m.obj:4: `v` with w = "), "{e}");
        // Statements relume ignores on purpose still load.
        let f = load(&format!("{TRI}s 1\nl 1 2 3\np 1\nf 1 2 3\n"), None).unwrap();
        assert_eq!(f.models[0].triangles.len(), 1, "a polyline does not become a triangle");
    }

    #[test]
    fn a_missing_mtl_is_named() {
        let e = load(&format!("mtllib gone.mtl\n{TRI}f 1 2 3\n"), None).err().unwrap();
        assert!(e.starts_with("m.obj:1: cannot read the material library \"gone.mtl\" (gone.mtl): No such file"), "{e}");
        assert!(e.contains("remove the `mtllib` line"), "{e}");
    }

    #[test]
    fn a_bad_normal_index_names_its_line() {
        let e = load(&format!("{TRI}vn 0 0 1\nf 1//1 2//1 3//1\nf 1//1 2//1 3//2\n"), None).err().unwrap();
        assert_eq!(e, "m.obj:6: face index 2 refers to a normal that does not exist (only 1 so far)");
        let e = load(&format!("{TRI}vt 0 0\nvn 0 0 1\nf 1/1/1/1 2 3\n"), None).err().unwrap();
        assert_eq!(e, "m.obj:6: face corner `1/1/1/1` has more than v/vt/vn");
    }

    #[test]
    fn an_undefined_usemtl_names_the_material_and_what_the_mtl_defines() {
        let e = load(&format!("mtllib m.mtl\n{TRI}usemtl gold\nf 1 2 3\n"), Some("newmtl white\nKd 1 1 1\nnewmtl red\nKd 1 0 0\n"))
            .err()
            .unwrap();
        assert_eq!(e, "m.obj:5: `usemtl gold`: material \"gold\" is not defined in m.mtl (it defines: white, red)");
        let e = load(&format!("{TRI}usemtl gold\nf 1 2 3\n"), None).err().unwrap();
        assert!(e.starts_with("m.obj:4: `usemtl gold`: material \"gold\" is not defined: no material library is loaded"), "{e}");
        // A tab after the keyword is read as tobj would read a space.
        let f = load(&format!("mtllib\tm.mtl\n{TRI}usemtl\tred\nf 1 2 3\n"), Some("newmtl red\nKd 1 0 0\n")).unwrap();
        assert_eq!(f.models[0].material, Some(Material::Lambert { albedo: Vec3::X }));
    }
}
