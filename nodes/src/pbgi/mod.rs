//! Point-based global illumination (PIPELINES.md pipeline 4; [P] chapters 2–3).

use relume_core::Registry;

pub fn register(_reg: &mut Registry) {}
