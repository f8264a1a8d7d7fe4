use crate::types::Volume;
use glam::{EulerRot, Quat, Vec3};
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

params! {
    /// One brush stroke in a medium ([S] 6.5.2.1, volume painting): a brush pattern placed at
    /// `centre`, scaled by `radius` × `stretch` along its own axes and turned by `rotation` (Euler
    /// angles in degrees, about x, then y, then z), adds `weight` × the pattern (0 … 1) to one
    /// channel — the refractive index, the extinction κ or the scattering σ. Chain one node per
    /// stroke: strokes are parameters, saved with the graph and undone with it, and a stroke
    /// re-runs only what reads the medium (the octree onward, never `Voxelize`). Afterwards n ≥ 1,
    /// κ ≥ 0 and 0 ≤ σ ≤ κ hold (painting σ above κ raises κ with it: scattering is extinction).
    pub struct VolumePaint {
        /// the property painted
        pub channel: PaintChannel = Index;
        /// the brush's pattern
        pub brush: Brush = Ball;
        /// centre of the stroke (scene units)
        pub centre: Vec3 = (0.0, 0.6, 0.0);
        /// size of the brush (scene units)
        pub radius: f32 = 0.2, range = 1e-6..=1e6;
        /// the brush's relative size along its own x, y, z
        pub stretch: Vec3 = (1.0, 1.0, 1.0);
        /// the brush's turn: Euler angles about x, y, z (degrees)
        pub rotation: Vec3 = (0.0, 0.0, 0.0);
        /// what the pattern's full strength adds (negative removes)
        pub weight: f32 = 0.2, range = -1e6..=1e6;
    }
}

/// The channel a stroke paints.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum PaintChannel {
    /// the refractive index n (channel 0)
    Index,
    /// the extinction κ (channel 1)
    Extinction,
    /// the scattering σ (channel 2)
    Scattering,
}

/// A brush's pattern in its own unit space.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum Brush {
    /// a ball with a smooth falloff (1 − r²)²
    Ball,
    /// a box, full strength inside |x|, |y|, |z| ≤ 1
    Box,
}

impl VolumePaint {
    fn pattern(&self, local: Vec3) -> f32 {
        match self.brush {
            Brush::Ball => (1.0 - local.length_squared()).max(0.0).powi(2),
            Brush::Box => (local.abs().max_element() <= 1.0) as u8 as f32,
        }
    }
}

/// `v` with the stroke `s` painted (see the node's doc); returns the voxels it touched.
pub fn paint(v: &mut Volume, s: &VolumePaint) -> Result<usize, NodeError> {
    if v.channels < 3 {
        return Err(NodeError::input("medium", format!("a medium has 3 channels (n, κ, σ); this volume has {}", v.channels)));
    }
    let scale = s.radius * s.stretch;
    if !(scale.cmpgt(Vec3::ZERO).all() && scale.is_finite()) {
        return Err(NodeError::param("stretch", format!("the brush needs a positive size along each axis, not {scale}")));
    }
    let r = s.rotation * (std::f32::consts::PI / 180.0);
    let turn = Quat::from_euler(EulerRot::XYZ, r.x, r.y, r.z);
    let inverse = turn.inverse();
    // The voxels under the brush's bounding sphere.
    let reach = scale.max_element() * 3f32.sqrt();
    let (lo, hi) = (v.to_grid(s.centre - reach).floor(), v.to_grid(s.centre + reach).ceil());
    let d = v.dims.map(|x| x as i64);
    let span = |a: f32, b: f32, n: i64| (a.max(0.0) as i64).min(n)..(b.max(0.0) as i64).min(n);
    let c = match s.channel {
        PaintChannel::Index => 0,
        PaintChannel::Extinction => 1,
        PaintChannel::Scattering => 2,
    };
    let mut touched = 0;
    for z in span(lo.z, hi.z, d[2]) {
        for y in span(lo.y, hi.y, d[1]) {
            for x in span(lo.x, hi.x, d[0]) {
                let (x, y, z) = (x as usize, y as usize, z as usize);
                let local = inverse * (v.centre(x, y, z) - s.centre) / scale;
                let w = s.pattern(local);
                if w == 0.0 {
                    continue;
                }
                let i = v.index(x, y, z);
                let px = &mut v.data[i..i + 3];
                px[c] += s.weight * w;
                px[0] = px[0].max(1.0);
                px[2] = px[2].max(0.0);
                px[1] = px[1].max(0.0).max(px[2]);
                touched += 1;
            }
        }
    }
    Ok(touched)
}

#[node(category = "volume", metrics = ["voxels_painted"], outputs = [medium])]
impl VolumePaint {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        relume_core::MemoryEstimate { outputs: vec![inputs[0]], working: 0 }
    }

    fn run(&self, medium: &Volume, cx: &RunCtx) -> Result<Volume, NodeError> {
        let mut medium = medium.clone();
        let touched = paint(&mut medium, self)?;
        cx.metric("voxels_painted", touched as f64);
        if touched == 0 {
            cx.note("the stroke reaches no voxel centre: move it into the volume or enlarge it");
        }
        Ok(medium)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn medium() -> Volume {
        let mut v = Volume::try_new([20, 20, 20], 3, Vec3::splat(-1.0), Vec3::splat(1.0), 0.0, u64::MAX).unwrap();
        v.data.chunks_mut(3).for_each(|c| c[0] = 1.2);
        v
    }

    fn stroke() -> VolumePaint {
        VolumePaint {
            channel: PaintChannel::Index,
            brush: Brush::Ball,
            centre: Vec3::ZERO,
            radius: 0.5,
            stretch: Vec3::ONE,
            rotation: Vec3::ZERO,
            weight: 0.3,
        }
    }

    #[test]
    fn a_ball_adds_its_weight_at_the_centre_fading_to_nothing_at_its_radius() {
        let mut v = medium();
        let n = paint(&mut v, &stroke()).unwrap();
        assert!(n > 100);
        let centre = v.sample(Vec3::ZERO, 0);
        assert!(centre > 1.45 && centre <= 1.5, "{centre}");
        assert_eq!(v.get(19, 10, 10, 0), 1.2, "outside the radius");
        // Voxel (13, 10, 10)'s centre is (0.35, 0.05, 0.05): r² / R² = 0.51.
        let mid = v.get(13, 10, 10, 0) - 1.2;
        assert!((mid - 0.3 * (1.0f32 - 0.51).powi(2)).abs() < 1e-5, "{mid}");
        let mut zero = medium();
        paint(&mut zero, &VolumePaint { weight: 0.0, ..stroke() }).unwrap();
        assert_eq!(zero, medium());
    }

    #[test]
    fn a_stretched_box_turns_with_its_rotation() {
        // A bar 0.9 long along its own x, thin across: turned 90° about z it lies along y.
        let bar = VolumePaint { brush: Brush::Box, radius: 0.1, stretch: Vec3::new(9.0, 1.0, 1.0), ..stroke() };
        let mut a = medium();
        paint(&mut a, &bar).unwrap();
        let mut b = medium();
        paint(&mut b, &VolumePaint { rotation: Vec3::new(0.0, 0.0, 90.0), ..bar }).unwrap();
        let painted = |v: &Volume, x: usize, y: usize| v.get(x, y, 10, 0) > 1.2;
        assert!(painted(&a, 3, 10) && !painted(&a, 10, 3));
        assert!(painted(&b, 10, 3) && !painted(&b, 3, 10));
    }

    #[test]
    fn limits_hold_after_painting_index_one_kappa_zero_and_sigma_within_kappa() {
        let mut v = medium();
        paint(&mut v, &VolumePaint { weight: -5.0, ..stroke() }).unwrap();
        assert!(v.data.chunks(3).all(|c| c[0] >= 1.0));
        assert_eq!(v.get(10, 10, 10, 0), 1.0);
        paint(&mut v, &VolumePaint { channel: PaintChannel::Scattering, weight: 2.0, ..stroke() }).unwrap();
        assert!(v.data.chunks(3).all(|c| c[2] >= 0.0 && c[2] <= c[1]), "σ ≤ κ");
        assert!(v.get(10, 10, 10, 1) > 1.5, "κ raised with σ");
        let mut scalar = Volume::try_new([2, 2, 2], 1, Vec3::ZERO, Vec3::ONE, 1.0, u64::MAX).unwrap();
        assert!(paint(&mut scalar, &stroke()).unwrap_err().to_string().contains("3 channels"));
        assert!(paint(&mut medium(), &VolumePaint { stretch: Vec3::new(1.0, 0.0, 1.0), ..stroke() }).is_err());
    }
}
