use crate::image::io::write_image;
use crate::types::Image;
use relume_core::{node, params, NodeError, RunCtx};
use std::path::PathBuf;

params! {
    /// Writes its input to a file (.exr: linear float; .png: 8-bit sRGB, clamped) and passes
    /// the image on. It has a side effect, so it is never cached and runs whenever needed.
    pub struct SaveImage {
        /// file to write (.exr or .png), relative to the graph file; it must lie below the graph's
        /// folder or the run's output folder unless the run allows writes anywhere
        pub path: PathBuf, output, extensions = ["exr", "png"];
    }
}

#[node(category = "image", caching = Never, outputs = [image])]
impl SaveImage {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // The image passed on, and the file's bytes while they are encoded (at most as many as
        // the image's floats: 8-bit PNG, half or float EXR).
        relume_core::MemoryEstimate { outputs: vec![inputs[0]], working: inputs[0].map_or(0, |s| s.bytes) }
    }

    fn run(&self, image: &Image, cx: &RunCtx) -> Result<Image, NodeError> {
        cx.check_write_path("path", &self.path)?;
        if let Some(dir) = self.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| NodeError::param("path", format!("cannot create {}: {e}", dir.display())))?;
        }
        write_image(&self.path, image).map_err(|m| NodeError::param("path", m))?;
        Ok(image.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::run_node;
    use relume_core::{ParamValue, Value};

    #[test]
    fn writes_exr_and_png_and_refuses_other_extensions() {
        let dir = tempfile::tempdir().unwrap();
        let img = Image::from_fn(2, 2, |x, _| [x as f32, 0.5, 2.0]);
        for name in ["sub/a.exr", "b.png"] {
            run_node::<SaveImage>(&[("path", ParamValue::Text(name.into()))], dir.path(), vec![Value::new(img.clone())]).unwrap();
            assert!(dir.path().join(name).is_file(), "{name}");
        }
        assert_eq!(crate::image::io::read_image(&dir.path().join("sub/a.exr")).unwrap(), img);
        let err = run_node::<SaveImage>(&[("path", ParamValue::Text("c.tiff".into()))], dir.path(), vec![Value::new(img)]).unwrap_err();
        assert!(err.to_string().contains("\"c.tiff\" has the extension .tiff; this parameter takes a .exr or .png file"), "{err}");
    }

    #[test]
    fn the_memory_estimate_is_the_image_passed_on_and_its_encoding() {
        use relume_core::{Node, PortValue};
        let img = Image::from_fn(5, 3, |x, y| [x as f32, y as f32, 1.0]);
        let size = img.size();
        let p = SaveImage { path: "a.png".into() };
        let e = p.memory(&[Some(size)]);
        assert_eq!(e.outputs, vec![Some(size)]);
        assert_eq!(e.working, size.bytes);
        assert!(size.bytes >= img.byte_size() as u64);
    }
}
