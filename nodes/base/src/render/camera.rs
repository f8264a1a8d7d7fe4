//! Primary rays of the scene camera (pinhole, field of view on the smaller image axis, image
//! right = forward × up as in Mitsuba 3).

use crate::types::Camera;
use glam::Vec3;

#[derive(Clone, Copy, Debug)]
pub struct CameraRays {
    origin: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    sx: f32,
    sy: f32,
    width: f32,
    height: f32,
}

impl CameraRays {
    pub fn new(c: &Camera) -> Self {
        let forward = (c.target - c.origin).normalize();
        let right = forward.cross(c.up).normalize();
        let up = right.cross(forward);
        let t = (c.fov_deg.to_radians() * 0.5).tan();
        let (w, h) = (c.width as f32, c.height as f32);
        let (sx, sy) = if w >= h { (t * w / h, t) } else { (t, t * h / w) };
        CameraRays { origin: c.origin, forward, right, up, sx, sy, width: w, height: h }
    }

    /// Ray through image position (x, y) in pixels (x right, y down; pixel centres at +0.5).
    pub fn ray(&self, x: f32, y: f32) -> (Vec3, Vec3) {
        let nx = (2.0 * x / self.width - 1.0) * self.sx;
        let ny = (1.0 - 2.0 * y / self.height) * self.sy;
        (self.origin, (self.forward + self.right * nx + self.up * ny).normalize())
    }

    /// A world point in camera coordinates: (along right, along up, depth along forward).
    pub fn to_camera(&self, p: Vec3) -> Vec3 {
        let v = p - self.origin;
        Vec3::new(v.dot(self.right), v.dot(self.up), v.dot(self.forward))
    }

    /// The image position (pixels, as `ray` takes them) of a camera-space point in front of
    /// the eye (depth > 0): `ray` at that position passes through the point.
    pub fn to_pixel(&self, c: Vec3) -> (f64, f64) {
        let (nx, ny) = (c.x as f64 / (c.z as f64 * self.sx as f64), c.y as f64 / (c.z as f64 * self.sy as f64));
        ((nx + 1.0) * 0.5 * self.width as f64, (1.0 - ny) * 0.5 * self.height as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_centre_looks_at_the_target_and_the_smaller_axis_spans_the_fov() {
        let c = Camera { origin: Vec3::new(0.0, 0.0, 3.9), target: Vec3::ZERO, up: Vec3::Y, fov_deg: 40.0, width: 200, height: 100 };
        let r = CameraRays::new(&c);
        assert!((r.ray(100.0, 50.0).1 - Vec3::new(0.0, 0.0, -1.0)).length() < 1e-6);
        let top = r.ray(100.0, 0.0).1;
        assert!((top.y.atan2(-top.z).to_degrees() - 20.0).abs() < 1e-3, "half the fov on the shorter (vertical) axis");
        assert!(r.ray(200.0, 50.0).1.x > 0.0, "image right is world +x for a camera looking down -z");
    }

    #[test]
    fn projecting_a_point_gives_the_position_whose_ray_passes_through_it() {
        let c = Camera {
            origin: Vec3::new(0.3, 1.0, 3.9),
            target: Vec3::new(0.1, 0.0, 0.0),
            up: Vec3::Y,
            fov_deg: 55.0,
            width: 120,
            height: 90,
        };
        let r = CameraRays::new(&c);
        for p in [Vec3::new(0.5, 0.2, -0.4), Vec3::new(-1.0, 0.7, 1.0), Vec3::new(0.0, -0.3, 0.2)] {
            let (x, y) = r.to_pixel(r.to_camera(p));
            let (o, d) = r.ray(x as f32, y as f32);
            assert!((p - o).normalize().dot(d) > 1.0 - 1e-6, "{p}");
        }
    }
}
