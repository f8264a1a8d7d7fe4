//! Writing a run's outputs to files: images as EXR + tone-mapped PNG, metrics and the
//! dynamic objects' materials as JSON.

use relume_base::image::io::{write_exr, write_png};
use relume_base::image::tonemap::{tonemap_channel, Operator};
use relume_base::types::{Image, Metrics, ObjectMaterials};
use relume_core::{Graph, Plan, Registry, Value};
use std::path::{Path, PathBuf};

/// The files `write_outputs` writes for an output `name` of the port type `ty` in `dir`: an
/// image as EXR and PNG, metrics and materials as JSON, nothing for other types.
fn files_for(dir: &Path, name: &str, ty: &str) -> Vec<PathBuf> {
    let ext: &[&str] = match ty {
        "Image" => &["exr", "png"],
        "Metrics" | "ObjectMaterials" => &["json"],
        _ => &[],
    };
    ext.iter().map(|e| dir.join(format!("{name}.{e}"))).collect()
}

/// The files a run of `plan` will write in `dir` for its outputs, from the output ports' types,
/// known before it runs: (output name, file).
pub(crate) fn planned_outputs(reg: &Registry, graph: &Graph, plan: &Plan, dir: &Path) -> Vec<(String, PathBuf)> {
    let mut out = Vec::new();
    for (name, node, port) in &plan.outputs {
        let Some(kind) = reg.node(&graph.nodes[*node].kind) else { continue };
        let Some(decl) = kind.ports().outputs.get(*port) else { continue };
        out.extend(files_for(dir, name, decl.ty.name).into_iter().map(|f| (name.clone(), f)));
    }
    out
}

/// Writes every output it has a format for; returns the files written.
pub(crate) fn write_outputs(dir: &Path, outputs: &[(String, Value)]) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let mut files = Vec::new();
    for (name, v) in outputs {
        let paths = files_for(dir, name, v.type_name());
        if let (Some(img), [exr, png]) = (v.get::<Image>(), paths.as_slice()) {
            if let Some(w) = nonfinite_warning(name, img) {
                say_err!("{w}");
            }
            write_exr(exr, img)?;
            write_png(png, &preview(img))?;
            files.extend([exr.clone(), png.clone()]);
        } else if let (Some(m), [json]) = (v.get::<Metrics>(), paths.as_slice()) {
            relume_core::graph::write_atomic(json, m.to_json().as_bytes()).map_err(|e| format!("cannot write {}: {e}", json.display()))?;
            files.push(json.clone());
        } else if let (Some(c), [json]) = (v.get::<ObjectMaterials>(), paths.as_slice()) {
            // A JSON list of the dynamic objects' materials with their RGB coefficients, the
            // diffuse basis first; texture maps by their size (their texels are not text).
            let size = |t: &Option<relume_base::types::Texture>| t.as_ref().map(|t| format!("{} × {} texture", t.width, t.height));
            let list: Vec<serde_json::Value> =
                c.0.iter()
                    .map(|m| {
                        let mut v = serde_json::json!({ "name": m.name, "kd": m.kd, "ks": m.ks, "s": m.s, "coefficients": m.coefficients });
                        for (key, t) in [("kd_map", &m.maps.kd), ("ks_map", &m.maps.ks), ("exponent_map", &m.maps.exponent)] {
                            if let Some(text) = size(t) {
                                v[key] = serde_json::Value::String(text);
                            }
                        }
                        v
                    })
                    .collect();
            let text = serde_json::to_string_pretty(&list).map_err(|e| format!("cannot encode {name}: {e}"))?;
            relume_core::graph::write_atomic(json, text.as_bytes()).map_err(|e| format!("cannot write {}: {e}", json.display()))?;
            files.push(json.clone());
        } else {
            say_err!("note: output \"{name}\" ({}) has no file format; not written", v.type_name());
        }
    }
    Ok(files)
}

/// A warning for an image holding values that are not finite (a sum that overflowed f32, a
/// division by zero upstream): the EXR keeps them, the PNG shows them black (NaN) or white
/// (+∞), and a run that made them still succeeds, so the person should hear of it.
fn nonfinite_warning(name: &str, img: &Image) -> Option<String> {
    let bad: Vec<usize> = img.pixels.iter().enumerate().filter(|(_, p)| p.iter().any(|c| !c.is_finite())).map(|(i, _)| i).collect();
    let first = *bad.first()?;
    let (x, y) = (first % img.width, first / img.width);
    Some(format!(
        "warning: output \"{name}\" has {} of {} pixels that are not finite (∞ or NaN; the first at ({x}, {y}) is {:?}): an upstream value left the range of f32",
        bad.len(),
        img.pixels.len(),
        img.pixels[first]
    ))
}

/// The PNG preview: ACES at exposure 0 (an image already in [0, 1] is left as it is).
fn preview(img: &Image) -> Image {
    let ldr = img.as_floats().iter().all(|x| (0.0..=1.0).contains(x));
    if ldr {
        return img.clone();
    }
    Image {
        width: img.width,
        height: img.height,
        pixels: img.pixels.iter().map(|p| p.map(|x| tonemap_channel(x, 1.0, Operator::Aces))).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_image_with_values_past_f32_is_warned_about_once_with_the_first_pixel() {
        let ok = Image::from_fn(3, 2, |x, y| [x as f32, y as f32, 1e30]);
        assert_eq!(nonfinite_warning("image", &ok), None);
        let bad = Image::from_fn(3, 2, |x, y| if y == 1 && x > 0 { [f32::INFINITY, 0.0, f32::NAN] } else { [0.5; 3] });
        assert_eq!(
            nonfinite_warning("image", &bad).unwrap(),
            "warning: output \"image\" has 2 of 6 pixels that are not finite (∞ or NaN; the first at (1, 1) is [inf, 0.0, NaN]): an upstream value left the range of f32"
        );
    }
}
