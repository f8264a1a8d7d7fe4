//! Multiple importance sampling over every way of making a path from the two subpaths:
//! Veach's power heuristic (β = 2) with the densities each strategy would have sampled the
//! path's vertices with. A strategy that would need a Dirac vertex or a delta light to be
//! connected is left out of the sum, as it cannot make the path.

use super::vertex::Vertex;
use super::Bidir;

impl Bidir<'_> {
    /// Weight of the path made by joining `light[..s]` and `cam[..t]` (with `cam[0]` the
    /// pinhole; for t = 1 the light vertex is projected onto it).
    pub(super) fn mis_weight(&self, light: &[Vertex], cam: &[Vertex], s: usize, t: usize) -> f32 {
        let (scene, c) = (self.scene, &self.cam);
        let pt = &cam[t - 1];
        let qs = (s > 0).then(|| &light[s - 1]);
        let dir = |a: &Vertex, b: &Vertex| a.dir_to(b).0;
        // The reverse densities of the connection's two ends and their neighbours.
        let pt_rev = match qs {
            Some(qs) => qs.pdf(scene, c, from_prev(light, s), pt),
            None => pt.origin_pdf(scene, &self.lights),
        };
        let pt_minus_rev = match (t >= 2, qs) {
            (false, _) => 0.0,
            (true, Some(qs)) => pt.pdf(scene, c, dir(pt, qs), &cam[t - 2]),
            (true, None) => pt.light_pdf(scene, &cam[t - 2]),
        };
        let qs_rev = match qs {
            Some(qs) => pt.pdf(scene, c, from_prev(cam, t), qs),
            None => 0.0,
        };
        let qs_minus_rev = if s >= 2 { light[s - 1].pdf(scene, c, dir(&light[s - 1], pt), &light[s - 2]) } else { 0.0 };
        let remap = |x: f32| if x != 0.0 { x } else { 1.0 };
        let mut sum = 0.0f32;
        let mut ri = 1.0f32;
        for i in (1..t).rev() {
            let rev = if i == t - 1 {
                pt_rev
            } else if i + 2 == t {
                pt_minus_rev
            } else {
                cam[i].pdf_rev
            };
            ri *= remap(rev) / remap(cam[i].pdf_fwd);
            let delta = i != t - 1 && cam[i].delta;
            // The camera cannot see an infinite light by light tracing.
            if !delta && !cam[i - 1].delta && !(i == 1 && cam[1].is_infinite()) {
                sum += ri * ri;
            }
        }
        ri = 1.0;
        for i in (0..s).rev() {
            let rev = if i == s - 1 {
                qs_rev
            } else if i + 2 == s {
                qs_minus_rev
            } else {
                light[i].pdf_rev
            };
            ri *= remap(rev) / remap(light[i].pdf_fwd);
            let delta = i != s - 1 && light[i].delta;
            let delta_before = if i > 0 { light[i - 1].delta } else { light[0].is_delta_light() };
            if !delta && !delta_before {
                sum += ri * ri;
            }
        }
        let w = 1.0 / (1.0 + sum);
        if w.is_finite() {
            w
        } else {
            0.0
        }
    }
}

/// Unit direction from the last of `path[..n]` toward the one before it (zero for one vertex).
fn from_prev(path: &[Vertex], n: usize) -> glam::Vec3 {
    if n >= 2 {
        path[n - 1].dir_to(&path[n - 2]).0
    } else {
        glam::Vec3::ZERO
    }
}
