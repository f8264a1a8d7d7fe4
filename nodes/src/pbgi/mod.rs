//! Point-based global illumination (PIPELINES.md pipeline 4; [P] chapters 2–3).

pub mod cluster_receivers;

use relume_core::Registry;

pub fn register(reg: &mut Registry) {
    reg.add(cluster_receivers::ClusterReceivers);
}
