use crate::types::{Camera, Scene};
use glam::{Quat, Vec3};
use relume_core::{node, params, NodeError, PortValue, RunCtx};

params! {
    /// The scene's camera orbited about its target, as a `Camera` of its own: a render that takes
    /// the camera as an input re-runs alone when the view changes, not what reads the scene.
    /// `azimuth` turns the origin about the camera's `up` through the target (right-handed:
    /// counter-clockwise seen from above); `elevation` is added to the angle between the view
    /// ray (target → origin) and the horizontal plane, clamped to ±89° (or the scene camera's own
    /// angle where that is already steeper) so that the view never looks along `up`; `distance`
    /// scales the origin's distance to the target; `pan_right` and `pan_up` then move origin and
    /// target together along the orbited view's right and up axes, in units of the distance
    /// between them. `up` is kept; `fov`, `width` and `height` replace the scene's when not 0.
    /// The defaults give the scene's camera.
    pub struct OrbitCamera {
        /// turn about the up axis through the target (degrees)
        pub azimuth: f32 = 0.0, range = -360.0..=360.0, unit = "°";
        /// added to the view's elevation, which stays within ±89° (degrees)
        pub elevation: f32 = 0.0, range = -89.0..=89.0, unit = "°";
        /// factor on the distance from the origin to the target
        pub distance: f32 = 1.0, range = 0.01..=100.0;
        /// shift of the view to its right, in distances to the target
        pub pan_right: f32 = 0.0, range = -100.0..=100.0;
        /// shift of the view along its up axis, in distances to the target
        pub pan_up: f32 = 0.0, range = -100.0..=100.0;
        /// field of view on the smaller image axis; 0 keeps the scene's
        pub fov: f32 = 0.0, range = 0.0..=179.0, unit = "°";
        /// image width; 0 keeps the scene's
        pub width: usize = 0, range = 0..=16384, unit = "px";
        /// image height; 0 keeps the scene's
        pub height: usize = 0, range = 0..=16384, unit = "px";
    }
}

/// Largest elevation above or below the plane across `up` that an orbit reaches (degrees).
pub const MAX_ELEVATION_DEG: f32 = 89.0;

impl OrbitCamera {
    /// `cam` orbited, zoomed and resized by this node's parameters (see the node's doc).
    pub fn apply(&self, cam: &Camera) -> Result<Camera, NodeError> {
        let mut c = cam.clone();
        let up = cam.up.normalize_or_zero();
        let d = cam.origin - cam.target;
        if self.elevation != 0.0 {
            let len = d.length();
            let horizontal = d - d.dot(up) * up;
            if up == Vec3::ZERO || len == 0.0 || horizontal.length_squared() == 0.0 {
                return Err(NodeError::input(
                    "scene",
                    "the scene's camera has no horizontal direction to orbit from (it looks along its up vector)",
                ));
            }
            let h = Quat::from_axis_angle(up, self.azimuth.to_radians()) * horizontal.normalize();
            let e0 = (d.dot(up) / len).clamp(-1.0, 1.0).asin();
            let limit = MAX_ELEVATION_DEG.to_radians();
            let e = (e0 + self.elevation.to_radians()).clamp(e0.min(-limit), e0.max(limit));
            c.origin = cam.target + len * self.distance * (e.cos() * h + e.sin() * up);
        } else if self.azimuth != 0.0 || self.distance != 1.0 {
            let turned = if self.azimuth != 0.0 && up != Vec3::ZERO { Quat::from_axis_angle(up, self.azimuth.to_radians()) * d } else { d };
            c.origin = cam.target + turned * self.distance;
        }
        if self.pan_right != 0.0 || self.pan_up != 0.0 {
            let view = c.target - c.origin;
            let right = view.cross(c.up).normalize_or_zero();
            let shift = (self.pan_right * right + self.pan_up * right.cross(view.normalize_or_zero())) * view.length();
            c.origin += shift;
            c.target += shift;
        }
        if self.fov > 0.0 {
            c.fov_deg = self.fov;
        }
        if self.width > 0 {
            c.width = self.width;
        }
        if self.height > 0 {
            c.height = self.height;
        }
        if !c.is_consistent() {
            return Err(NodeError::failed(format!(
                "the orbited camera cannot render (origin {}, target {}, up {}, fov {}°, {} × {})",
                c.origin, c.target, c.up, c.fov_deg, c.width, c.height
            )));
        }
        Ok(c)
    }
}

#[node(category = "scene", outputs = [camera])]
impl OrbitCamera {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let dims = inputs[0].and_then(|s| s.dims);
        let w = if self.width > 0 { Some(self.width) } else { dims.map(|d| d[0]) };
        let h = if self.height > 0 { Some(self.height) } else { dims.map(|d| d[1]) };
        let bytes = std::mem::size_of::<Camera>() as u64;
        let size = relume_core::PortSize { bytes, dims: w.zip(h).map(|(w, h)| [w, h]) };
        relume_core::MemoryEstimate { outputs: vec![Some(size)], working: 0 }
    }

    fn run(&self, scene: &Scene, _cx: &RunCtx) -> Result<Camera, NodeError> {
        let camera = self.apply(&scene.camera)?;
        debug_assert!(Camera::decode(&camera.encode()).is_some());
        Ok(camera)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{f, first, i, run_on, test_scene};
    use relume_core::{ParamValue, Value};

    fn orbit(params: &[(&str, ParamValue)], scene: &Scene) -> Camera {
        first(&run_on::<OrbitCamera>(params, vec![Value::new(scene.clone())]).unwrap())
    }

    /// Elevation of the view ray (target → origin) above the plane across `up`, in degrees.
    fn elevation(c: &Camera) -> f32 {
        let d = (c.origin - c.target).normalize();
        d.dot(c.up.normalize()).asin().to_degrees()
    }

    #[test]
    fn the_defaults_give_the_scene_camera() {
        let s = test_scene::spheres();
        let c = orbit(&[], &s);
        assert_eq!(c, s.camera);
        assert_eq!(c.encode(), s.camera.encode());
    }

    #[test]
    fn azimuth_turns_about_up_through_the_target_and_a_full_turn_comes_back() {
        let mut s = test_scene::spheres();
        s.camera.origin = Vec3::new(0.3, 1.2, 2.5);
        s.camera.target = Vec3::new(0.1, 0.2, -0.3);
        let c = orbit(&[("azimuth", f(360.0))], &s);
        assert!((c.origin - s.camera.origin).length() < 1e-5, "{} vs {}", c.origin, s.camera.origin);
        let c = orbit(&[("azimuth", f(-360.0)), ("elevation", f(0.0))], &s);
        assert!((c.origin - s.camera.origin).length() < 1e-5);
        // A quarter turn of the default camera on +z, counter-clockwise seen from above: to +x.
        let s = test_scene::spheres();
        let c = orbit(&[("azimuth", f(90.0))], &s);
        assert!((c.origin - Vec3::new(3.0, 0.0, 0.0)).length() < 1e-5, "{}", c.origin);
        assert_eq!((c.target, c.up), (s.camera.target, s.camera.up));
        // With an elevation change too, the azimuth turns the same way and keeps the distance.
        let c = orbit(&[("azimuth", f(90.0)), ("elevation", f(30.0))], &s);
        let want = 3.0 * Vec3::new(30f32.to_radians().cos(), 30f32.to_radians().sin(), 0.0);
        assert!((c.origin - want).length() < 1e-5, "{} vs {want}", c.origin);
    }

    #[test]
    fn distance_scales_the_distance_to_the_target_along_the_same_ray() {
        let mut s = test_scene::spheres();
        s.camera.origin = Vec3::new(0.3, 1.2, 2.5);
        s.camera.target = Vec3::new(0.1, 0.2, -0.3);
        let d0 = s.camera.origin - s.camera.target;
        for k in [0.01, 0.5, 2.0, 100.0] {
            let c = orbit(&[("distance", f(k))], &s);
            let d = c.origin - c.target;
            assert!((d.length() / d0.length() - k as f32).abs() < 1e-5 * k as f32, "{k}");
            assert!(d.normalize().dot(d0.normalize()) > 1.0 - 1e-6);
        }
        let c = orbit(&[("distance", f(2.0)), ("elevation", f(10.0))], &s);
        assert!(((c.origin - c.target).length() / d0.length() - 2.0).abs() < 1e-5);
    }

    #[test]
    fn elevation_is_added_and_clamped_below_the_pole() {
        let s = test_scene::spheres();
        assert!(elevation(&s.camera).abs() < 1e-6);
        let c = orbit(&[("elevation", f(40.0))], &s);
        assert!((elevation(&c) - 40.0).abs() < 1e-3);
        let up = orbit(&[("elevation", f(40.0))], &Scene { camera: c.clone(), ..s.clone() });
        assert!((elevation(&up) - 80.0).abs() < 1e-3);
        // 80° + 89° and 80° + 20° stop at 89°; the camera never looks along up.
        for e in [89.0, 20.0] {
            let top = orbit(&[("elevation", f(e))], &Scene { camera: up.clone(), ..s.clone() });
            assert!((elevation(&top) - 89.0).abs() < 1e-3, "{}", elevation(&top));
            assert!(top.is_consistent());
        }
        let below = orbit(&[("elevation", f(-89.0))], &Scene { camera: c.clone(), ..s.clone() });
        assert!((elevation(&below) - -49.0).abs() < 1e-3);
        let bottom = orbit(&[("elevation", f(-89.0))], &Scene { camera: below, ..s.clone() });
        assert!((elevation(&bottom) - -89.0).abs() < 1e-3);
        // A scene camera already steeper than 89° is not pulled back by a change toward its pole.
        let mut steep = s.camera.clone();
        steep.origin = Vec3::new(0.0, 3.0, 0.03);
        let e0 = elevation(&steep);
        assert!(e0 > 89.0);
        let c = orbit(&[("elevation", f(5.0))], &Scene { camera: steep.clone(), ..s.clone() });
        assert!((elevation(&c) - e0).abs() < 1e-3);
        let c = orbit(&[("elevation", f(-10.0))], &Scene { camera: steep, ..s.clone() });
        assert!((elevation(&c) - (e0 - 10.0)).abs() < 1e-3);
    }

    #[test]
    fn panning_moves_origin_and_target_together_across_the_view() {
        let s = test_scene::spheres();
        let d = (s.camera.origin - s.camera.target).length();
        // The default camera looks along −z from +z with up +y: right is +x.
        let c = orbit(&[("pan_right", f(0.5)), ("pan_up", f(-0.25))], &s);
        let want = Vec3::new(0.5 * d, -0.25 * d, 0.0);
        assert!((c.origin - s.camera.origin - want).length() < 1e-5, "{}", c.origin);
        assert!((c.target - s.camera.target - want).length() < 1e-5, "{}", c.target);
        // After an orbit the shift follows the orbited view: a quarter turn makes right −z.
        let c = orbit(&[("azimuth", f(90.0)), ("pan_right", f(1.0))], &s);
        assert!((c.target - s.camera.target - Vec3::new(0.0, 0.0, -d)).length() < 1e-5, "{}", c.target);
    }

    #[test]
    fn fov_and_resolution_replace_the_scene_values_when_not_zero() {
        let s = test_scene::spheres();
        let c = orbit(&[("fov", f(60.0)), ("width", i(320))], &s);
        assert_eq!((c.fov_deg, c.width, c.height, c.origin), (60.0, 320, s.camera.height, s.camera.origin));
        assert_eq!(c.size().dims, Some([320, s.camera.height]));
        let e = run_on::<OrbitCamera>(&[("distance", f(0.0))], vec![Value::new(s)]).unwrap_err().to_string();
        assert!(e.contains("distance"), "{e}");
    }

    #[test]
    fn a_camera_encodes_decodes_and_refuses_bad_bytes() {
        let cam = test_scene::spheres().camera;
        let b = cam.encode();
        assert_eq!(Camera::decode(&b), Some(cam.clone()));
        assert_eq!(Camera::decode(&b).unwrap().encode(), b);
        assert!(Camera::decode(&b[..b.len() - 1]).is_none(), "truncated");
        assert!(Camera::decode(&[b.as_slice(), &[0]].concat()).is_none(), "trailing bytes");
        assert!(Camera::decode(&[]).is_none());
        let bad: [fn(&mut Camera); 8] = [
            |c| c.target = c.origin,
            |c| c.origin.x = f32::NAN,
            |c| c.up = Vec3::ZERO,
            |c| c.up = c.target - c.origin,
            |c| c.width = 0,
            |c| c.height = 16385,
            |c| c.fov_deg = 0.0,
            |c| c.fov_deg = 180.0,
        ];
        for (k, spoil) in bad.iter().enumerate() {
            let mut c = cam.clone();
            spoil(&mut c);
            assert!(Camera::decode(&c.encode()).is_none(), "case {k}");
        }
        assert_ne!(cam.fingerprint(), Camera { fov_deg: 41.0, ..cam.clone() }.fingerprint());
    }
}
