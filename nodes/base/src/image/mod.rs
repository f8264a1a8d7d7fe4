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

use relume_core::Registry;

pub fn register(reg: &mut Registry) {
    reg.add::<load_image::LoadImage>();
    reg.add::<save_image::SaveImage>();
    reg.add::<tonemap::Tonemap>();
    reg.add::<image_error::ImageError>();
    reg.add::<gaussian_blur::GaussianBlur>();
    reg.add::<median_filter::MedianFilter>();
    reg.add::<test_pattern::TestPattern>();
    reg.add::<combine::Combine>();
    reg.add::<z_test::ZTest>();
}
