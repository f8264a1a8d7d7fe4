//! Images between the engine and numpy: float32 arrays of height × width × 3 (linear RGB),
//! read from and written to EXR, HDR and PNG by the engine's own readers and writers.

use numpy::{PyArray1, PyArray3, PyArrayMethods, PyReadonlyArrayDyn, PyUntypedArrayMethods};
use pyo3::exceptions::{PyOSError, PyValueError};
use pyo3::prelude::*;
use relume_base::types::Image;
use std::path::PathBuf;

/// An image as a new float32 array, height × width × 3: one copy of its pixels, which the
/// array then owns.
pub fn to_numpy<'py>(py: Python<'py>, img: &Image) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let flat: Vec<f32> = img.pixels.iter().flatten().copied().collect();
    PyArray1::from_vec(py, flat).reshape([img.height, img.width, 3])
}

/// An array of height × width × 3 (RGB), × 4 (RGBA: alpha dropped) or height × width (grey)
/// of any real type, as an image.
pub fn from_numpy(array: &Bound<'_, PyAny>) -> PyResult<Image> {
    let np = array.py().import("numpy")?;
    let f32_array = np.call_method1("ascontiguousarray", (array, "float32"))?;
    let a: PyReadonlyArrayDyn<f32> = f32_array.extract()?;
    let shape = a.shape().to_vec();
    let (h, w, c) = match shape.as_slice() {
        [h, w] => (*h, *w, 1),
        [h, w, c @ (3 | 4)] => (*h, *w, *c),
        _ => {
            return Err(PyValueError::new_err(format!(
                "an image is height × width × 3 (or × 4, or height × width), not an array of shape {shape:?}"
            )))
        }
    };
    let data = a.as_slice().map_err(|e| PyValueError::new_err(e.to_string()))?;
    let mut img = Image::try_new(w, h).map_err(|e| PyValueError::new_err(e.to_string()))?;
    for (px, src) in img.pixels.iter_mut().zip(data.chunks_exact(c)) {
        *px = if c == 1 { [src[0]; 3] } else { [src[0], src[1], src[2]] };
    }
    Ok(img)
}

/// Reads an EXR, HDR or PNG image (PNG decoded from sRGB to linear) as a float32 array,
/// height × width × 3.
#[pyfunction]
pub fn read_image(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyArray3<f32>>> {
    let img = py.detach(|| relume_base::image::io::read_image(&path)).map_err(PyOSError::new_err)?;
    to_numpy(py, &img)
}

/// Writes a float32-convertible array (height × width × 3, × 4 or height × width) as EXR
/// (linear, exact) or PNG (sRGB, 8 bits), by the path's extension.
#[pyfunction]
pub fn write_image(path: PathBuf, array: &Bound<'_, PyAny>) -> PyResult<()> {
    let img = from_numpy(array)?;
    array.py().detach(|| relume_base::image::io::write_image(&path, &img)).map_err(PyOSError::new_err)
}
