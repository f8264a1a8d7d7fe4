//! Writing a run's outputs to files: images as EXR + tone-mapped PNG, metrics and the
//! dynamic objects' materials as JSON.

use relume_base::image::io::{write_exr, write_png};
use relume_base::image::tonemap::{tonemap_channel, Operator};
use relume_base::types::{Image, Metrics, ObjectMaterials};
use relume_core::Value;
use std::path::{Path, PathBuf};

/// Writes every output it has a format for; returns the files written.
pub(crate) fn write_outputs(dir: &Path, outputs: &[(String, Value)]) -> Result<Vec<PathBuf>, String> {
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    let mut files = Vec::new();
    for (name, v) in outputs {
        if let Some(img) = v.get::<Image>() {
            let exr = dir.join(format!("{name}.exr"));
            write_exr(&exr, img)?;
            let png = dir.join(format!("{name}.png"));
            write_png(&png, &preview(img))?;
            files.extend([exr, png]);
        } else if let Some(m) = v.get::<Metrics>() {
            let json = dir.join(format!("{name}.json"));
            relume_core::graph::write_atomic(&json, m.to_json().as_bytes()).map_err(|e| format!("cannot write {}: {e}", json.display()))?;
            files.push(json);
        } else if let Some(c) = v.get::<ObjectMaterials>() {
            // A JSON list of the dynamic objects' materials with their RGB coefficients, the
            // diffuse basis first; texture maps by their size (their texels are not text).
            let json = dir.join(format!("{name}.json"));
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
            relume_core::graph::write_atomic(&json, text.as_bytes()).map_err(|e| format!("cannot write {}: {e}", json.display()))?;
            files.push(json);
        } else {
            say_err!("note: output \"{name}\" ({}) has no file format; not written", v.type_name());
        }
    }
    Ok(files)
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
