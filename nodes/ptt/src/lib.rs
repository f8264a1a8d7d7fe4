//! Precomputed transfer tensors (docs/PIPELINES.md pipeline 2; [S] chapter 5): fixed geometry lit by
//! an environment, with the view, the environment and the dynamic objects' BRDFs edited
//! together. Per vertex: direct light from the environment's Haar coefficients against the
//! vertex's visibility times the BRDF tensor's incoming factor (T0), one bounce in 4-band SH
//! (T1) and two bounces as a scalar (T2); shading with the Tucker-decomposed BRDF tensor plus
//! the separated specular lobes; then rasterised.

pub mod bounce;
pub mod brdf;
pub mod camera_hits;
pub mod channels;
pub mod cta_compress;
pub mod env_lighting;
pub mod incident_projection;
pub mod ptt_bounce_light;
pub mod ptt_direct;
pub mod ptt_incident;
pub mod ptt_relight;
pub mod rasterize_vertex_colors;
pub mod screen_hits;
pub mod transfer_t0;
pub mod transfer_t1;
pub mod transfer_t2;
pub mod types;
pub mod vertex_path_trace;
pub mod vertex_visibility;
pub mod vertices;

use relume_core::Registry;

/// Registers the transfer-tensor nodes.
pub fn register(reg: &mut Registry) {
    reg.add::<env_lighting::EnvLighting>();
    reg.add::<vertex_visibility::VertexVisibility>();
    reg.add::<cta_compress::CtaCompress>();
    reg.add::<transfer_t0::TransferT0>();
    reg.add::<transfer_t1::TransferT1>();
    reg.add::<transfer_t2::TransferT2>();
    reg.add::<incident_projection::IncidentProjection>();
    reg.add::<ptt_direct::PttDirect>();
    reg.add::<ptt_bounce_light::PttBounceLight>();
    reg.add::<ptt_incident::PttIncident>();
    reg.add::<ptt_relight::PttRelight>();
    reg.add::<camera_hits::CameraHits>();
    reg.add::<rasterize_vertex_colors::RasterizeVertexColors>();
    reg.add::<vertex_path_trace::VertexPathTrace>();
    brdf::register(reg);
}

/// Test-size parameters of the transfer-tensor nodes (pipeline 2): coarse cube maps, few rays,
/// a small BRDF tensor, few clusters, on envlit's 49 K vertices: what the graph,
/// port-type, editor tests and the benches' test mode run.
pub fn test_size(kind: &str) -> &'static [(&'static str, &'static str)] {
    match kind {
        "EnvLighting" => &[("side", "8"), ("supersample", "2")],
        "VertexVisibility" => &[("side", "8"), ("coarse", "2")],
        "BrdfTensor" => &[("disk", "6"), ("samples", "12"), ("m_count", "3"), ("f0_count", "2")],
        "BrdfSpaceSample" => &[("n_theta_i", "8"), ("n_theta_o", "8"), ("n_phi", "16"), ("samples", "21")],
        "CtaCompress" => &[("clusters", "64"), ("eigenvectors", "8"), ("lighting", "8"), ("cpca_iterations", "2")],
        "TransferT0" => &[("terms", "16"), ("lobe_side", "2")],
        "TransferT1" => &[("rays_side", "2")],
        "TransferT2" => &[("side", "1"), ("rays_side", "2")],
        "VertexPathTrace" => &[("spp", "4")],
        "CameraHits" => &[("spp", "2")],
        _ => &[],
    }
}

#[cfg(test)]
pub(crate) mod test_support;
