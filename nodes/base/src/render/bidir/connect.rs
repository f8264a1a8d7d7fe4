//! Joining the subpaths: the contribution of the strategy with `s` light and `t` camera
//! vertices, before its MIS weight. s = 0: the camera subpath reached an emitter; t = 1: the
//! light subpath's last vertex seen by the camera (it lands on some pixel); otherwise a shadow
//! ray between the two subpaths' last vertices, through the medium both lie in.

use super::vertex::{toward, Kind, Mode, Vertex};
use super::Bidir;
use crate::render::integrator::Counts;
use glam::Vec3;

/// An unweighted strategy's value and, for t = 1, the pixel position it lands on.
pub(super) struct Contribution {
    pub value: Vec3,
    pub pixel: Option<(f64, f64)>,
}

impl Bidir<'_> {
    pub(super) fn connect(&self, light: &[Vertex], cam: &[Vertex], s: usize, t: usize, counts: &mut Counts) -> Option<Contribution> {
        if s == 0 {
            let pt = &cam[t - 1];
            let value = pt.beta * pt.emitted(self.scene);
            return (value != Vec3::ZERO).then_some(Contribution { value, pixel: None });
        }
        let qs = &light[s - 1];
        if !qs.connectible() {
            return None;
        }
        if t == 1 {
            if qs.is_infinite() {
                return None;
            }
            let fp = self.cam.film_point(qs.p())?;
            let w = -fp.dir;
            let tr = transmittance(qs, &cam[0], fp.dist)?;
            let value = qs.beta * self.sends(qs, w) * fp.importance * tr;
            if value == Vec3::ZERO || !self.visible(qs, &cam[0], counts) {
                return None;
            }
            return Some(Contribution { value, pixel: Some((fp.x, fp.y)) });
        }
        let pt = &cam[t - 1];
        if !pt.connectible() {
            return None;
        }
        let (w, dist2) = qs.dir_to(pt);
        if !(dist2 > 0.0) {
            return None;
        }
        // From an infinite light no distance falls off: its density is per solid angle.
        let falloff = if qs.is_infinite() { 1.0 } else { 1.0 / dist2 };
        let tr = transmittance(qs, pt, dist2.sqrt())?;
        let value = qs.beta * self.sends(qs, w) * pt.f(-w, Mode::Radiance) * pt.beta * tr * (pt.cos_g(w) * falloff);
        if value == Vec3::ZERO || !value.is_finite() || !self.visible(qs, pt, counts) {
            return None;
        }
        Some(Contribution { value, pixel: None })
    }

    /// What the light subpath's vertex `qs` sends toward `w` per its weight, with the cosine
    /// at `qs`: emission at the light's own vertex, the (adjoint) BSDF or the phase function
    /// elsewhere.
    fn sends(&self, qs: &Vertex, w: Vec3) -> Vec3 {
        let g = match qs.kind {
            Kind::Surface | Kind::Medium => qs.f(w, Mode::Importance),
            _ => qs.emit(self.scene, w),
        };
        g * qs.cos_g(w)
    }

    /// Whether nothing blocks the segment between two vertices (a shadow ray from `a`, off
    /// its surface, stopping short of `b`; from `b` out of the scene where `a` is an infinite
    /// light).
    fn visible(&self, a: &Vertex, b: &Vertex, counts: &mut Counts) -> bool {
        if a.is_infinite() {
            counts.rays += 1;
            return !self.accel.occluded(b.surf.spawn(a.wo, self.eps), a.wo, 0.0, f32::INFINITY);
        }
        let (w, dist2) = toward(a.p(), b.p());
        let dist = dist2.sqrt();
        let origin = if a.on_surface() { a.surf.spawn(w, self.eps) } else { a.p() };
        let tmax = dist * (1.0 - 1e-4) - if b.on_surface() { self.eps } else { 0.0 };
        counts.rays += 1;
        !self.accel.occluded(origin, w, 0.0, tmax)
    }
}

/// Transmittance e^(−σt d) over the distance `dist` between two vertices, through the medium
/// they lie in (1 outside media). `None` where they lie in different media: a boundary is
/// between them, which the shadow ray would meet.
fn transmittance(a: &Vertex, b: &Vertex, dist: f32) -> Option<Vec3> {
    if a.medium != b.medium {
        return None;
    }
    Some(match a.medium {
        None => Vec3::ONE,
        Some(m) if dist.is_finite() => (-(m.sigma_a + m.sigma_s) * dist).exp(),
        Some(_) => Vec3::ZERO,
    })
}
