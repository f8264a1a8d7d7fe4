//! Reading and writing image files (EXR linear; PNG sRGB-encoded). Shared by LoadImage,
//! SaveImage and the command line.

use crate::math::srgb::{srgb_decode, srgb_encode};
use crate::types::Image;
use relume_core::graph::write_atomic;
use std::io::Cursor;
use std::path::Path;

fn ext(path: &Path) -> String {
    path.extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default()
}

/// Reads an EXR or Radiance HDR (linear) or PNG (sRGB, decoded to linear) file.
pub fn read_image(path: &Path) -> Result<Image, String> {
    if !matches!(ext(path).as_str(), "exr" | "hdr" | "png") {
        return decode_image(path, &[]);
    }
    let bytes = relume_core::read_input(path).map_err(|err| format!("cannot read {}: {err}", path.display()))?;
    decode_image(path, &bytes)
}

/// Decodes image bytes; `path` gives the type (by extension) and names the file in messages.
pub fn decode_image(path: &Path, bytes: &[u8]) -> Result<Image, String> {
    let e = ext(path);
    let format = match e.as_str() {
        "exr" => image::ImageFormat::OpenExr,
        "hdr" => image::ImageFormat::Hdr,
        "png" => image::ImageFormat::Png,
        _ => return Err(format!("{}: unsupported image type `.{e}` (relume reads .exr, .hdr and .png)", path.display())),
    };
    let img = image::load_from_memory_with_format(bytes, format)
        .map_err(|err| format!("{}: not a readable {} file: {err}", path.display(), e.to_uppercase()))?;
    let rgb = img.to_rgb32f();
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let decode = e == "png";
    let pixels = rgb
        .pixels()
        .map(|p| {
            let c = p.0;
            if decode {
                [srgb_decode(c[0]), srgb_decode(c[1]), srgb_decode(c[2])]
            } else {
                c
            }
        })
        .collect();
    Ok(Image { width: w, height: h, pixels })
}

/// Writes linear RGB as a 32-bit float EXR (ZIP-compressed, blocks in order: the same image
/// gives the same bytes), atomically.
pub fn write_exr(path: &Path, img: &Image) -> Result<(), String> {
    use exr::prelude::{Encoding, Layer, LayerAttributes, SpecificChannels, Vec2, WritableImage};
    let (w, h) = (img.width, img.height);
    let channels = SpecificChannels::rgb(|p: Vec2<usize>| {
        let [r, g, b] = img.get(p.x(), p.y());
        (r, g, b)
    });
    let layer = Layer::new((w, h), LayerAttributes::default(), Encoding::FAST_LOSSLESS, channels);
    let mut out = Cursor::new(Vec::new());
    // One thread, blocks in order: the same image gives the same bytes (the parallel writer
    // stores blocks in the order they finish compressing).
    exr::image::Image::from_layer(layer)
        .write()
        .non_parallel()
        .to_buffered(&mut out)
        .map_err(|e| format!("encoding {}: {e}", path.display()))?;
    write_atomic(path, out.get_ref()).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Writes an 8-bit sRGB PNG of `img` (values clamped to [0, 1], NaN as 0), atomically.
pub fn write_png(path: &Path, img: &Image) -> Result<(), String> {
    let bytes: Vec<u8> = img.as_floats().iter().map(|&x| (srgb_encode(x) * 255.0 + 0.5) as u8).collect();
    let buf = image::RgbImage::from_raw(img.width as u32, img.height as u32, bytes).ok_or("image buffer size mismatch")?;
    let mut out = Cursor::new(Vec::new());
    buf.write_to(&mut out, image::ImageFormat::Png).map_err(|e| format!("encoding {}: {e}", path.display()))?;
    write_atomic(path, out.get_ref()).map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// Writes by extension (.exr or .png).
pub fn write_image(path: &Path, img: &Image) -> Result<(), String> {
    match ext(path).as_str() {
        "exr" => write_exr(path, img),
        "png" => write_png(path, img),
        e => Err(format!("{}: unsupported image type `.{e}` (relume writes .exr and .png)", path.display())),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_round_trip_is_exact_and_png_is_within_quantisation() {
        let dir = tempfile::tempdir().unwrap();
        let img = Image::from_fn(5, 3, |x, y| [x as f32 * 0.1, y as f32 * 0.3, 7.5]);
        let exr = dir.path().join("a.exr");
        write_image(&exr, &img).unwrap();
        assert_eq!(read_image(&exr).unwrap(), img);
        let png = dir.path().join("a.png");
        let ldr = Image::from_fn(5, 3, |x, _| [x as f32 * 0.2, 0.5, 1.0]);
        write_image(&png, &ldr).unwrap();
        let back = read_image(&png).unwrap();
        for (a, b) in back.as_floats().iter().zip(ldr.as_floats()) {
            assert!((a - b).abs() < 0.01, "{a} vs {b}");
        }
    }

    #[test]
    fn missing_and_malformed_files_name_the_path() {
        let dir = tempfile::tempdir().unwrap();
        let e = read_image(&dir.path().join("none.exr")).unwrap_err();
        assert!(e.contains("none.exr") && e.contains("cannot read"), "{e}");
        let bad = dir.path().join("bad.exr");
        std::fs::write(&bad, b"not an exr").unwrap();
        assert!(read_image(&bad).unwrap_err().contains("not a readable EXR"));
        assert!(read_image(&dir.path().join("x.jpg")).unwrap_err().contains("unsupported"));
    }
}
