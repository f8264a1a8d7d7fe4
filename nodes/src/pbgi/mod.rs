//! Point-based global illumination (PIPELINES.md pipeline 4; [P] chapters 2–3).

pub mod point_tree;

use relume_core::Registry;

pub fn register(reg: &mut Registry) {
    reg.add(point_tree::BuildPointTree);
}
