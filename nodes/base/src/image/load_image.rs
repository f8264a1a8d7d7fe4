use crate::image::io::read_image;
use crate::types::Image;
use relume_core::{node, params, NodeError, RunCtx};
use std::path::PathBuf;

params! {
    /// Reads an image file: OpenEXR (linear RGB) or PNG (sRGB, decoded to linear).
    /// The cache key hashes the file's content, so editing the file re-runs what depends on it.
    pub struct LoadImage {
        /// image file (.exr or .png), relative to the graph file
        pub path: PathBuf;
    }
}

#[node(category = "image", outputs = [image])]
impl LoadImage {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The header gives the size without decoding the pixels.
        let _ = inputs;
        let size = ::image::image_dimensions(&self.path).ok().map(|(w, h)| relume_core::PortSize::image(w as usize, h as usize));
        relume_core::MemoryEstimate { outputs: vec![size], working: 0 }
    }

    fn run(&self, _cx: &RunCtx) -> Result<Image, NodeError> {
        let image = read_image(&self.path).map_err(|m| NodeError::param("path", m))?;
        Ok(image)
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
        let out = run_node::<LoadImage>(&[("path", ParamValue::Text("a.exr".into()))], dir.path(), vec![]).unwrap();
        assert_eq!(out[0].get::<Image>().unwrap(), &img);
        let err = run_node::<LoadImage>(&[("path", ParamValue::Text("missing.exr".into()))], dir.path(), vec![]).unwrap_err();
        assert!(matches!(&err, NodeError::Param { name, msg } if name == "path" && msg.contains("missing.exr")), "{err}");
    }
}
