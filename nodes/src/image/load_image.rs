//! LoadImage node.

use crate::image::io::read_image;
use crate::types::Image;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};
use std::path::PathBuf;

node_doc! {
    /// Reads an image file: OpenEXR (linear RGB) or PNG (sRGB, decoded to linear).
    /// The cache key hashes the file's content, so editing the file re-runs what depends on it.
    pub struct LoadImage;
}

pub struct LoadImageParams {
    pub path: PathBuf,
}

impl Params for LoadImageParams {
    fn schema() -> Schema {
        Schema::new().input_file("path").help("image file (.exr or .png), relative to the graph file")
    }
    fn from_values(v: &ParamValues) -> Self {
        LoadImageParams { path: v.path("path") }
    }
}

impl Node for LoadImage {
    const KIND: &'static str = "LoadImage";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "image";
    const CACHING: Caching = Caching::Disk;
    type Params = LoadImageParams;

    fn ports() -> Ports {
        Ports::new().output::<Image>("image")
    }

    fn run(&self, p: &LoadImageParams, io: &mut Io, _cx: &RunCtx) -> Result<(), NodeError> {
        let img = read_image(&p.path).map_err(|m| NodeError::param("path", m))?;
        io.set("image", img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::run_node;
    use relume_core::ParamValue;

    #[test]
    fn reads_an_exr_and_reports_a_missing_file_by_parameter() {
        let dir = tempfile::tempdir().unwrap();
        let img = Image::from_fn(4, 4, |x, y| [x as f32, y as f32, 1.0]);
        crate::image::io::write_exr(&dir.path().join("a.exr"), &img).unwrap();
        let out = run_node(LoadImage, &[("path", ParamValue::Text("a.exr".into()))], dir.path(), vec![]).unwrap();
        assert_eq!(out[0].get::<Image>().unwrap(), &img);
        let err = run_node(LoadImage, &[("path", ParamValue::Text("missing.exr".into()))], dir.path(), vec![]).unwrap_err();
        assert!(matches!(&err, NodeError::Param { name, msg } if name == "path" && msg.contains("missing.exr")), "{err}");
    }
}
