//! SaveImage node.

use crate::image::io::write_image;
use crate::types::Image;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};
use std::path::PathBuf;

node_doc! {
    /// Writes its input to a file (.exr: linear float; .png: 8-bit sRGB, clamped) and passes
    /// the image on. It has a side effect, so it is never cached and runs whenever needed.
    pub struct SaveImage;
}

pub struct SaveImageParams {
    pub path: PathBuf,
}

impl Params for SaveImageParams {
    fn schema() -> Schema {
        Schema::new().output_file("path").help("file to write (.exr or .png), relative to the graph file")
    }
    fn from_values(v: &ParamValues) -> Self {
        SaveImageParams { path: v.path("path") }
    }
}

impl Node for SaveImage {
    const KIND: &'static str = "SaveImage";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "image";
    const CACHING: Caching = Caching::Never;
    type Params = SaveImageParams;

    fn ports() -> Ports {
        Ports::new().input::<Image>("image").output::<Image>("image")
    }

    fn run(&self, p: &SaveImageParams, io: &mut Io, _cx: &RunCtx) -> Result<(), NodeError> {
        let img = io.input::<Image>("image")?.clone();
        if let Some(dir) = p.path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| NodeError::param("path", format!("cannot create {}: {e}", dir.display())))?;
        }
        write_image(&p.path, &img).map_err(|m| NodeError::param("path", m))?;
        io.set("image", img)
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
            run_node(SaveImage, &[("path", ParamValue::Text(name.into()))], dir.path(), vec![Value::new(img.clone())]).unwrap();
            assert!(dir.path().join(name).is_file(), "{name}");
        }
        assert_eq!(crate::image::io::read_image(&dir.path().join("sub/a.exr")).unwrap(), img);
        let err = run_node(SaveImage, &[("path", ParamValue::Text("c.tiff".into()))], dir.path(), vec![Value::new(img)]).unwrap_err();
        assert!(err.to_string().contains("unsupported"), "{err}");
    }
}
