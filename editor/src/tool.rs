//! The viewer's tools and the state of a drag or stroke under way (what the manipulators in
//! `manipulate` read and keep), with the conversions between parameter values and numbers
//! they share.

use crate::pick::Probe;
use glam::Vec3;
use relume_core::ParamValue;

/// Degrees an orbit turns for a drag across the whole image, sideways and up-down.
pub(crate) const ORBIT_DEG_PER_WIDTH: f32 = 180.0;
pub(crate) const ORBIT_DEG_PER_HEIGHT: f32 = 90.0;
/// Degrees the sky turns about the vertical for a drag across the whole image, and tilts
/// (shift or secondary button) for a drag down the whole image.
pub(crate) const TURN_DEG_PER_WIDTH: f32 = 360.0;
pub(crate) const TILT_DEG_PER_HEIGHT: f32 = 180.0;
/// The distance factor per point of wheel turn: exp(−k · scroll).
pub(crate) const ZOOM_PER_POINT: f32 = 0.002;
/// Dabs one stroke adds at most (a longer stroke keeps moving its last dab).
pub(crate) const MAX_DABS: usize = 64;

/// Where a dab goes and the brush node's parameters that put it there.
pub(crate) type Dab = (Vec3, Vec<(&'static str, ParamValue)>);

/// A viewer tool.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tool {
    Orbit,
    Move,
    Turn,
    Pick,
    Paint,
    PaintVolume,
}

impl Tool {
    pub const ALL: [Tool; 6] = [Tool::Orbit, Tool::Move, Tool::Turn, Tool::Pick, Tool::Paint, Tool::PaintVolume];

    /// The node kind the tool edits (`Pick` edits none: it selects).
    pub fn kind(self) -> Option<&'static str> {
        match self {
            Tool::Orbit => Some("OrbitCamera"),
            Tool::Move => Some("MoveObject"),
            Tool::Turn => Some("TurnEnvironment"),
            Tool::Pick => None,
            Tool::Paint => Some("PaintMaterial"),
            Tool::PaintVolume => Some("VolumePaint"),
        }
    }

    pub fn label(self) -> &'static str {
        match self {
            Tool::Orbit => "orbit",
            Tool::Move => "move",
            Tool::Turn => "turn sky",
            Tool::Pick => "pick",
            Tool::Paint => "paint",
            Tool::PaintVolume => "paint volume",
        }
    }

    pub fn hint(self) -> &'static str {
        match self {
            Tool::Orbit => "drag to orbit the camera, shift-drag or right-drag to pan, wheel to zoom",
            Tool::Move => "drag to move the object in the view's plane",
            Tool::Turn => "drag sideways to turn the environment; shift-drag up or down to tilt it",
            Tool::Pick => "click an object to select the node that edits its material",
            Tool::Paint => "stroke over an object to paint its material map (the brush is the selected or last paint node)",
            Tool::PaintVolume => "stroke over the medium to paint it (the brush is the selected or last volume paint node)",
        }
    }

    /// The input and output port a brush node is chained through.
    pub(crate) fn chain_ports(self) -> Option<(&'static str, &'static str)> {
        match self {
            Tool::Paint => Some(("materials", "materials")),
            Tool::PaintVolume => Some(("medium", "medium")),
            _ => None,
        }
    }
}

/// A drag or stroke under way.
pub(crate) struct Gesture {
    pub(crate) tool: Tool,
    /// The undo step's tag: every edit of the gesture merges into one step.
    pub(crate) tag: String,
    /// The node the drag edits (for a stroke: the last dab).
    pub(crate) node: String,
    /// Its parameters when the drag began.
    pub(crate) start: Vec<(String, ParamValue)>,
    /// Pointer travel since the button went down, in image pixels.
    pub(crate) total: egui::Vec2,
    pub(crate) probe: Option<Probe>,
    /// Where the last dab went (UV for paint, scene units for volume), and how many.
    pub(crate) last_dab: Option<Vec3>,
    pub(crate) dabs: usize,
}

pub(crate) fn float(v: Option<&ParamValue>) -> f32 {
    match v {
        Some(ParamValue::Float(x)) => *x as f32,
        Some(ParamValue::Int(x)) => *x as f32,
        _ => 0.0,
    }
}

pub(crate) fn vec3(v: Option<&ParamValue>) -> Vec3 {
    match v {
        Some(ParamValue::Tuple(t)) if t.len() == 3 => Vec3::new(float(t.first()), float(t.get(1)), float(t.get(2))),
        _ => Vec3::ZERO,
    }
}

pub(crate) fn tuple(v: Vec3) -> ParamValue {
    ParamValue::Tuple(v.to_array().iter().map(|&x| ParamValue::Float(x as f64)).collect())
}

/// An angle in degrees wrapped into [−180°, 180°).
pub(crate) fn wrap_deg(a: f32) -> f32 {
    (a + 180.0).rem_euclid(360.0) - 180.0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_wrap_into_one_turn() {
        assert_eq!(wrap_deg(190.0), -170.0);
        assert_eq!(wrap_deg(-190.0), 170.0);
        assert_eq!(wrap_deg(45.0), 45.0);
        assert_eq!(wrap_deg(-180.0), -180.0);
    }

    #[test]
    fn parameter_values_read_back() {
        assert_eq!(float(Some(&ParamValue::Int(3))), 3.0);
        assert_eq!(vec3(Some(&tuple(Vec3::new(1.0, -2.0, 0.5)))), Vec3::new(1.0, -2.0, 0.5));
        assert_eq!(vec3(None), Vec3::ZERO);
    }
}
