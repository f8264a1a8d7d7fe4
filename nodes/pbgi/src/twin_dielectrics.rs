use relume_base::types::{Material, SurfacePoints};
use relume_core::{node, MemoryEstimate, NodeError, Params, PortSize, RunCtx};

/// Refraction through the points ([P] 5.3.5): a PBGI point is a one-sided disk that sends
/// light toward its normal's side only, but a point on glass sends light both ways, out of
/// the glass and into it. Every point on a smooth dielectric gets a twin at the same place
/// facing the other way (normal −n, relative index 1/ior: its front is the glass's inside),
/// appended after the points in their order; the others pass unchanged, at the same indices.
/// Each twin sends what its side of the interface sends: the outer one the light reflected
/// outside and transmitted out of the glass, the inner one the light reflected inside and
/// transmitted into it (`SurfelWavelets` for the direct light, `ViewTree`'s spherical gathers
/// for the bounces). `PointTree` keeps the twins in a subtree of their own (its `sides`),
/// so that their light is seen from inside the glass only. Put it between `SampleSurface`
/// and every node that reads the points.
#[derive(Params)]
pub struct TwinDielectrics;

/// `pts` with a twin appended for each point on a smooth dielectric.
pub fn twin_dielectrics(pts: &SurfacePoints) -> SurfacePoints {
    let mut out = pts.clone();
    for i in 0..pts.len() {
        if let Material::Dielectric { ior, medium } = pts.material[i] {
            out.position.push(pts.position[i]);
            out.normal.push(-pts.normal[i]);
            out.radius.push(pts.radius[i]);
            out.object.push(pts.object[i]);
            out.material.push(Material::Dielectric { ior: 1.0 / ior, medium });
        }
    }
    out
}

#[node(category = "pbgi", metrics = ["points", "twins"], outputs = [points])]
impl TwinDielectrics {
    fn memory(&self, inputs: &[Option<PortSize>]) -> MemoryEstimate {
        // At most twice the points.
        MemoryEstimate { outputs: vec![inputs[0].map(|s| PortSize::bytes(2 * s.bytes))], working: 0 }
    }

    fn run(&self, points: &SurfacePoints, cx: &RunCtx) -> Result<SurfacePoints, NodeError> {
        cx.check()?;
        let out = twin_dielectrics(points);
        cx.metric("points", points.len() as f64);
        cx.metric("twins", (out.len() - points.len()) as f64);
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use relume_base::testing::{first, run_on};
    use relume_core::Value;

    #[test]
    fn points_on_glass_get_a_twin_facing_inside_and_the_rest_keep_their_places() {
        let glass = Material::Dielectric { ior: 1.5, medium: None };
        let grey = Material::Lambert { albedo: Vec3::splat(0.5) };
        let pts = SurfacePoints {
            position: vec![Vec3::X, Vec3::Y, Vec3::Z],
            normal: vec![Vec3::X, Vec3::Y, Vec3::Z],
            radius: vec![0.1, 0.2, 0.3],
            object: vec![0, 1, 0],
            material: vec![glass, grey, glass],
        };
        let out: SurfacePoints = first(&run_on::<TwinDielectrics>(&[], vec![Value::new(pts.clone())]).unwrap());
        assert_eq!(out.len(), 5);
        assert_eq!(out.position[..3], pts.position[..]);
        assert_eq!(out.material[..3], pts.material[..]);
        assert_eq!((out.position[3], out.normal[3], out.radius[3], out.object[3]), (Vec3::X, -Vec3::X, 0.1, 0));
        assert_eq!((out.position[4], out.normal[4], out.radius[4]), (Vec3::Z, -Vec3::Z, 0.3));
        assert_eq!(out.material[4], Material::Dielectric { ior: 1.0 / 1.5, medium: None });
        // Nothing to twin: the same points.
        let opaque = SurfacePoints { material: vec![grey; 3], ..pts };
        let same = twin_dielectrics(&opaque);
        assert_eq!(
            (same.position, same.normal, same.radius, same.material),
            (opaque.position, opaque.normal, opaque.radius, opaque.material)
        );
    }
}
