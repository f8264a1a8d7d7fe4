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

    /// The eye's position.
    pub fn origin(&self) -> Vec3 {
        self.origin
    }

    /// Area of the image on the plane one unit in front of the eye.
    fn film_area(&self) -> f32 {
        4.0 * self.sx * self.sy
    }

    /// Solid-angle density of the direction `d` (unit) of a ray through a point uniform over
    /// the whole image: 1 / (A cos³θ), A the image's area one unit in front of the eye and θ
    /// the angle off the view axis; 0 behind the eye. (Per pixel the density is width × height
    /// times this, over the pixel's own directions.)
    pub fn direction_pdf(&self, d: Vec3) -> f32 {
        let cos = d.dot(self.forward);
        if cos <= 0.0 {
            0.0
        } else {
            1.0 / (self.film_area() * cos * cos * cos)
        }
    }

    /// Where the world point `p` shows in the image: its pixel position (as `ray` takes it),
    /// the unit direction from the eye, the distance, and the importance carried to `p`
    /// along that direction per unit area facing the eye, W cos θ / r² = 1 / (A cos³θ r²)
    /// (W = 1 / (A cos⁴θ), normalised over the whole image). `None` behind the eye or outside
    /// the image.
    pub fn film_point(&self, p: Vec3) -> Option<FilmPoint> {
        let c = self.to_camera(p);
        let dist = c.length();
        if c.z <= 0.0 || !(dist > 0.0) {
            return None;
        }
        let (x, y) = self.to_pixel(c);
        if !(x >= 0.0 && y >= 0.0 && x < self.width as f64 && y < self.height as f64) {
            return None;
        }
        let cos = c.z / dist;
        let importance = 1.0 / (self.film_area() * cos * cos * cos * dist * dist);
        Some(FilmPoint { x, y, dir: (p - self.origin) / dist, dist, importance })
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

/// Camera sample `s` of pixel (x, y) of a `width`-wide image as the reference takes it (box
/// filter: a point uniform over the pixel, from (seed, pixel, sample) only): the ray's origin,
/// direction and the sample's id, which keys the sample's further random numbers. Renderers
/// whose antialiased edges must match the reference's take their samples here.
pub fn camera_sample(cam: &CameraRays, seed: u64, width: usize, x: usize, y: usize, s: u32) -> (Vec3, Vec3, u64) {
    let id = ((y * width + x) as u64) << 32 | s as u64;
    let (jx, jy) = (crate::math::rng::uniform(seed ^ 0x5EED, id, 0), crate::math::rng::uniform(seed ^ 0x5EED, id, 1));
    let (o, d) = cam.ray(x as f32 + jx, y as f32 + jy);
    (o, d, id)
}

/// A world point seen by the camera (`CameraRays::film_point`).
#[derive(Clone, Copy, Debug)]
pub struct FilmPoint {
    /// Pixel position, x right and y down, as `CameraRays::ray` takes it.
    pub x: f64,
    pub y: f64,
    /// Unit direction from the eye to the point.
    pub dir: Vec3,
    pub dist: f32,
    /// W cos θ / r²: the camera's importance reaching the point, per unit area facing the eye.
    pub importance: f32,
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

    #[test]
    fn the_direction_density_integrates_to_one_over_the_image_and_matches_the_importance() {
        let c = Camera { origin: Vec3::new(0.2, 0.5, 3.0), target: Vec3::ZERO, up: Vec3::Y, fov_deg: 50.0, width: 64, height: 48 };
        let r = CameraRays::new(&c);
        let n = 400_000u32;
        let mut total = 0.0f64;
        for k in 0..n {
            let u = glam::Vec2::new(crate::math::rng::uniform(5, k as u64, 0), crate::math::rng::uniform(5, k as u64, 1));
            let d = crate::math::sampling::uniform_sphere(u);
            if r.film_point(r.origin() + d).is_some() {
                total += r.direction_pdf(d) as f64;
            }
        }
        let integral = total / n as f64 * 4.0 * std::f64::consts::PI;
        assert!((integral - 1.0).abs() < 0.02, "{integral}");
        let p = Vec3::new(0.3, -0.2, 0.4);
        let fp = r.film_point(p).unwrap();
        let dist = (p - r.origin()).length();
        assert!((fp.importance - r.direction_pdf(fp.dir) / (dist * dist)).abs() < 1e-5 * fp.importance);
        let (o, d) = r.ray(fp.x as f32, fp.y as f32);
        assert!((p - o).normalize().dot(d) > 1.0 - 1e-6);
        assert!(r.film_point(r.origin() - (p - r.origin())).is_none(), "behind the eye");
    }
}
