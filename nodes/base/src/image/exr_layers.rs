//! One multi-layer OpenEXR per run: every image output as a named layer (`image.R`,
//! `image.G`, `image.B`, `variance.R`, …: the channel-name grouping that tev, the OpenEXR
//! tools and Mitsuba's `Bitmap` all list as layers), half or full float, with the run's
//! provenance in the header: relume's version, the graph file, and per layer the output
//! name, the node that made it, its kind and every parameter value. Outputs of different
//! sizes go into separate parts, one per size. Written through the `exr` crate.

use crate::types::Image;
use exr::prelude::*;
use std::path::Path;

/// One image output and where it came from.
pub struct LayerSource<'a> {
    /// The output's name: the layer name.
    pub name: &'a str,
    pub image: &'a Image,
    /// The producing node's id, kind and parameters (canonical RON text, defaults included).
    pub node: &'a str,
    pub kind: &'a str,
    pub params: String,
}

/// Header attribute text, UTF-8 bytes kept as they are.
fn text(s: &str) -> Text {
    Text::from_bytes_unchecked(SmallVec::from_slice(s.as_bytes()))
}

fn json_str(s: &str) -> String {
    serde_json::Value::String(s.to_string()).to_string()
}

/// Writes `layers` to `path` (half floats when `half`); `graph` names the graph file.
pub fn write_layers(path: &Path, graph: &str, layers: &[LayerSource], half: bool) -> std::result::Result<(), String> {
    if layers.is_empty() {
        return Err("the run produced no image output to write as EXR layers".into());
    }
    let mut sizes: Vec<(usize, usize)> = layers.iter().map(|l| (l.image.width, l.image.height)).collect();
    sizes.dedup();
    sizes.sort_unstable();
    sizes.dedup();
    let mut parts = Vec::new();
    for &(w, h) in &sizes {
        let here: Vec<&LayerSource> = layers.iter().filter(|l| (l.image.width, l.image.height) == (w, h)).collect();
        let mut channels = SmallVec::<[AnyChannel<FlatSamples>; 4]>::new();
        for l in &here {
            for (c, suffix) in ["R", "G", "B"].iter().enumerate() {
                let values = l.image.pixels.iter().map(|p| p[c]);
                let samples = if half { FlatSamples::F16(values.map(f16::from_f32).collect()) } else { FlatSamples::F32(values.collect()) };
                channels.push(AnyChannel::new(format!("{}.{suffix}", l.name).as_str(), samples));
            }
        }
        let mut attributes =
            LayerAttributes::named(if sizes.len() == 1 { "relume".to_string() } else { format!("relume {w}x{h}") }.as_str());
        attributes.software_name = Some(text(&format!("relume {}", env!("CARGO_PKG_VERSION"))));
        attributes.comments = Some(text(&format!("graph {graph}; layers {}", here.iter().map(|l| l.name).collect::<Vec<_>>().join(", "))));
        let provenance: Vec<String> = here
            .iter()
            .map(|l| {
                format!(
                    "{{\"layer\":{},\"node\":{},\"kind\":{},\"params\":{}}}",
                    json_str(l.name),
                    json_str(l.node),
                    json_str(l.kind),
                    json_str(&l.params)
                )
            })
            .collect();
        attributes.other.insert(text("relume.graph"), AttributeValue::Text(text(graph)));
        attributes.other.insert(text("relume.layers"), AttributeValue::Text(text(&format!("[{}]", provenance.join(",")))));
        parts.push(Layer::new((w, h), attributes, Encoding::SMALL_LOSSLESS, AnyChannels::sort(channels)));
    }
    let (w, h) = sizes[0];
    let image = exr::image::Image::from_layers(ImageAttributes::new(IntegerBounds::from_dimensions((w, h))), parts);
    let tmp = path.with_extension("exr.tmp");
    // One thread, blocks in order: the same layers give the same bytes.
    image.write().non_parallel().to_file(&tmp).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    std::fs::rename(&tmp, path).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Where `write_run_layers` writes: `OUT/<graph stem>.layers.exr`.
pub fn layers_path(graph: &relume_core::Graph, out: &Path) -> std::path::PathBuf {
    let stem = graph.file.as_ref().and_then(|f| f.file_stem()).map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "run".into());
    out.join(format!("{stem}.layers.exr"))
}

/// Writes a run's image outputs (those `graph.outputs` names; others are skipped) as one
/// multi-layer EXR, `OUT/GRAPH.layers.exr`, and returns its path.
pub fn write_run_layers(
    reg: &relume_core::Registry,
    graph: &relume_core::Graph,
    outputs: &[(String, relume_core::Value)],
    out: &Path,
    half: bool,
) -> std::result::Result<std::path::PathBuf, String> {
    let mut layers = Vec::new();
    for (name, v) in outputs {
        let Some(image) = v.get::<Image>() else { continue };
        let Some(node) = graph.outputs.iter().find(|o| &o.name == name).map(|o| o.port.node.as_str()) else { continue };
        let decl = graph.node(node).ok_or_else(|| format!("output \"{name}\" names no node"))?;
        let kind = reg.node(&decl.kind).ok_or_else(|| format!("unknown node kind \"{}\"", decl.kind))?;
        let params = relume_core::ParamValues::resolve(kind.schema(), &decl.params, &graph.base_dir)
            .map(|p| p.to_text())
            .map_err(|missing| format!("node \"{node}\": missing parameters {missing:?}"))?;
        layers.push(LayerSource { name, image, node, kind: kind.kind(), params });
    }
    let path = layers_path(graph, out);
    let graph_name = graph.file.as_ref().map(|f| f.display().to_string()).unwrap_or_default();
    write_layers(&path, &graph_name, &layers, half)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    type Read = exr::image::Image<exr::image::Layers<AnyChannels<FlatSamples>>>;

    /// Reads every layer and channel back with the `exr` crate, as a researcher's tool would.
    pub(crate) fn read(path: &Path) -> Read {
        exr::prelude::read().no_deep_data().largest_resolution_level().all_channels().all_layers().all_attributes().from_file(path).unwrap()
    }

    #[test]
    fn layers_come_back_bit_identical_with_their_provenance_in_full_float_and_close_in_half() {
        let dir = tempfile::tempdir().unwrap();
        let a = Image::from_fn(5, 3, |x, y| [x as f32 * 0.1, y as f32 + 1e-7, -2.5e5]);
        let b = Image::from_fn(5, 3, |x, _| [f32::INFINITY, 0.0, x as f32]);
        let small = Image::from_fn(2, 2, |x, y| [x as f32, y as f32, 0.5]);
        let src = |name, image, node| LayerSource { name, image, node, kind: "K", params: "(n: 1, path: \"ü.exr\")".into() };
        let layers = [src("image", &a, "pt"), src("variance", &b, "pt"), src("thumb", &small, "blur")];
        let path = dir.path().join("run.exr");
        write_layers(&path, "graphs/g.ron", &layers, false).unwrap();
        let img = read(&path);
        assert_eq!(img.layer_data.len(), 2, "one part per image size");
        let big = img.layer_data.iter().find(|l| l.size == Vec2(5, 3)).unwrap();
        let names: Vec<String> = big.channel_data.list.iter().map(|c| c.name.to_string()).collect();
        assert_eq!(names, ["image.B", "image.G", "image.R", "variance.B", "variance.G", "variance.R"]);
        let chan = |l: &exr::image::Layer<AnyChannels<FlatSamples>>, n: &str| -> Vec<f32> {
            l.channel_data.list.iter().find(|c| c.name.to_string() == n).unwrap().sample_data.values_as_f32().collect()
        };
        for (name, img) in [("image", &a), ("variance", &b)] {
            for (c, s) in ["R", "G", "B"].iter().enumerate() {
                let want: Vec<u32> = img.pixels.iter().map(|p| p[c].to_bits()).collect();
                let got: Vec<u32> = chan(big, &format!("{name}.{s}")).iter().map(|x| x.to_bits()).collect();
                assert_eq!(got, want, "{name}.{s}");
            }
        }
        let attr = |k: &str| match big.attributes.other.get(&text(k)) {
            Some(AttributeValue::Text(t)) => String::from_utf8(t.bytes().to_vec()).unwrap(),
            other => panic!("{k}: {other:?}"),
        };
        assert_eq!(attr("relume.graph"), "graphs/g.ron");
        let prov: serde_json::Value = serde_json::from_str(&attr("relume.layers")).unwrap();
        assert_eq!(prov[1]["layer"], "variance");
        assert_eq!(prov[1]["node"], "pt");
        assert_eq!(prov[0]["params"], "(n: 1, path: \"ü.exr\")");
        assert!(big.attributes.software_name.as_ref().unwrap().to_string().starts_with("relume "));

        write_layers(&path, "g.ron", &layers[..1], true).unwrap();
        let img = read(&path);
        let l = &img.layer_data[0];
        assert!(matches!(l.channel_data.list[0].sample_data, FlatSamples::F16(_)), "half floats when asked");
        for (got, want) in chan(l, "image.R").iter().zip(a.pixels.iter().map(|p| p[0])) {
            assert!((got - want).abs() <= 1e-3 * want.abs().max(1e-3), "{got} vs {want}");
        }
        assert!(write_layers(&path, "g.ron", &[], false).is_err(), "no image output is an error, not an empty file");
    }
}
