//! Point-based global illumination (PIPELINES.md pipeline 4; [P] chapters 2–3).

pub mod cluster_receivers;
pub mod gbuffer;
pub mod shade_direct;

use relume_core::Registry;

pub fn register(reg: &mut Registry) {
    reg.add(shade_direct::ShadeDirect);
    reg.add(gbuffer::GBuffer);
    reg.add(cluster_receivers::ClusterReceivers);
}
