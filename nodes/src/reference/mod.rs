//! The reference path tracer and what it is built from.

pub mod camera;
pub mod direct_light;
pub mod integrator;
pub mod lights;
pub mod path_trace;

use relume_core::Registry;

pub fn register(reg: &mut Registry) {
    reg.add(path_trace::PathTrace);
    reg.add(direct_light::DirectLight);
}
