//! Image nodes: file I/O, tone mapping, filters, error figures and the z-test.

pub mod combine;
pub mod exr_layers;
pub mod gaussian_blur;
pub mod image_error;
pub mod io;
pub mod load_image;
pub mod median_filter;
pub mod save_image;
pub mod ssim;
pub mod test_pattern;
pub mod tonemap;
pub mod z_test;
