//! The spherical microbuffer ([P] 5.3.5): a receiver that transmits light (a refracting
//! surface) sees the whole sphere of directions, not the hemisphere above its surface. The
//! buffer is two Nusselt hemispheres of the same side: the front one over +z (the normal's
//! side, `Microbuffer` itself) and the back one over −z, stored mirrored (a local direction
//! (x, y, z) with z < 0 lands at (x, y, −z) in it), so that each keeps the hemispherical
//! buffer's equal projected solid angle per pixel and its rasteriser.
//!
//! A receiver that does not transmit uses the front hemisphere only, and the traversal culls
//! what lies under its horizon exactly as for `Microbuffer`: for such receivers the gather's
//! result is the hemispherical buffer's, byte for byte (tested). A transmitting receiver keeps
//! everything around it: no horizon culling, nodes rasterised into the hemisphere their
//! centre lies in, near leaves ray-cast into both, except the disks of its own surface (a
//! centre within twice the disk's radius): the points around a receiver overlap beneath it,
//! and an opaque receiver's horizon culling is what keeps them out of its view.
//!
//! Outgoing radiance: the smooth dielectric's two Dirac lobes ([`relume_base::brdf::dielectric::lobes`])
//! read the buffer in their directions, F · L(reflected) from the front and
//! (1 − F)/η² · L(refracted) from the back (nearest pixel). With ior = 1 this is exactly the
//! back pixel straight behind: light goes through unchanged (docs/QUALITY.md §2 "refraction").

use super::microbuffer::{DiskLight, Flat, Microbuffer, SplatRule};
use super::traversal::{GatherBuffer, GatherCounts, NodeRadiance, Raster, Traversal};
use crate::types::faces_inside;
use glam::Vec3;
use relume_base::brdf;
use relume_base::math::frame::Frame;
use relume_base::types::Material;

/// A transmitting receiver skips near leaves whose centre lies within this many of their
/// radii: the disks of its own surface.
const OWN_SURFACE: f32 = 2.0;

/// Mirrors a local direction or point through the receiver's tangent plane.
fn mirror(d: Vec3) -> Vec3 {
    Vec3::new(d.x, d.y, -d.z)
}

#[derive(Clone)]
pub struct SphericalMicrobuffer {
    /// Directions with z ≥ 0 (the normal's side).
    pub front: Microbuffer,
    /// Directions with z < 0, mirrored to z > 0.
    pub back: Microbuffer,
    /// Whether the receiver under way sees the whole sphere (it transmits).
    whole: bool,
    /// While one side's subtree is traversed (`gather`): `Some(true)` writes the front
    /// hemisphere only, `Some(false)` the back one only.
    only_front: Option<bool>,
}

impl SphericalMicrobuffer {
    /// Two N × N hemispheres (N ≥ 1).
    pub fn new(n: usize) -> Self {
        SphericalMicrobuffer { front: Microbuffer::new(n), back: Microbuffer::new(n), whole: false, only_front: None }
    }

    /// Both hemispheres with nodes smaller than a pixel landing by `rule`.
    pub fn with_rule(self, rule: SplatRule) -> Self {
        SphericalMicrobuffer { front: self.front.with_rule(rule), back: self.back.with_rule(rule), ..self }
    }

    /// Whether receivers of material `m` see the whole sphere: those that transmit light.
    pub fn transmits(m: &Material) -> bool {
        matches!(m, Material::Dielectric { .. })
    }

    /// Whether the buffer is set for the whole sphere (`begin` with a transmitting material).
    pub fn whole(&self) -> bool {
        self.whole
    }

    /// Makes both hemispheres readable after writes (`Microbuffer::resolve`).
    pub fn resolve(&mut self) {
        self.front.resolve();
        self.back.resolve();
    }

    /// The radiance the buffer holds toward local direction `d` (the pixel it lands in, in
    /// the hemisphere it points into); 0 behind a front-only buffer.
    pub fn radiance_toward(&self, d: Vec3) -> Vec3 {
        if d.z >= 0.0 {
            self.front.radiance_toward(d)
        } else if self.whole {
            self.back.radiance_toward(mirror(d))
        } else {
            Vec3::ZERO
        }
    }

    /// Outgoing radiance toward local `wo` of a receiver of material `m` after the buffer is
    /// filled: the dielectric's lobes read in their directions; any other material convolves
    /// the front hemisphere (`Microbuffer::convolve`).
    pub fn outgoing(&self, m: &Material, wo: Vec3) -> Vec3 {
        match *m {
            Material::Dielectric { ior, .. } if self.whole => {
                brdf::dielectric::lobes(ior, wo).iter().map(|&(wi, weight)| self.radiance_toward(wi) * weight).sum()
            }
            _ => self.front.convolve(m, wo),
        }
    }
}

impl Raster for SphericalMicrobuffer {
    fn pixel_solid_angle(&self, d: Vec3) -> f32 {
        self.front.pixel_solid_angle(d)
    }

    fn culls_horizon(&self) -> bool {
        !self.whole
    }

    fn splat(&mut self, node: u32, d: Vec3, dist: f32, omega: f32, l: Vec3, flat: Option<Flat>, stack: &mut Vec<u32>) {
        if d.z >= 0.0 {
            if self.only_front != Some(false) {
                Raster::splat(&mut self.front, node, d, dist, omega, l, flat, stack)
            }
        } else if self.whole && self.only_front != Some(true) {
            Raster::splat(&mut self.back, node, mirror(d), dist, omega, l, flat.map(|f| f.mapped(mirror)), stack)
        }
    }

    fn disk(&mut self, node: u32, c: Vec3, nrm: Vec3, r: f32, l: &DiskLight, eps: f32) {
        if self.whole && c.length() < OWN_SURFACE * r {
            // A disk this close is the receiver's own surface: the points around it overlap
            // beneath it (and its twin lies on it), and without the horizon culling that an
            // opaque receiver has, their disks would cover the view into the glass.
            return;
        }
        if self.only_front != Some(false) {
            self.front.disk(node, c, nrm, r, l, eps);
        }
        if self.whole && self.only_front != Some(true) {
            // Mirroring the disk with the directions keeps which side of it each ray meets.
            let along = |w: Vec3| l.along(mirror(w));
            let mirrored = match l {
                DiskLight::Uniform(_) => *l,
                DiskLight::Along(_) => DiskLight::Along(&along),
            };
            self.back.disk(node, mirror(c), mirror(nrm), r, &mirrored, eps);
        }
    }
}

impl GatherBuffer for SphericalMicrobuffer {
    fn shades(&self, _: &Material) -> bool {
        true
    }

    fn begin(&mut self, m: &Material, _: Vec3) {
        self.whole = Self::transmits(m);
        self.front.clear();
        if self.whole {
            self.back.clear();
        }
    }

    fn end(&mut self, m: &Material, wo: Vec3) -> Vec3 {
        self.resolve();
        self.outgoing(m, wo)
    }

    /// A transmitting receiver on a tree whose inner twins are kept apart (`PointTree::sides`)
    /// fills its front hemisphere from its own side's subtree and its back one from the other
    /// side's: the light sent into the glass is seen from inside it only, and what is outside
    /// from outside only. Otherwise the hemispherical buffer's traversal (the whole tree for
    /// a transmitting receiver when nothing is kept apart).
    fn gather<R: NodeRadiance>(
        &mut self,
        t: &Traversal<R>,
        m: &Material,
        p: Vec3,
        frame: &Frame,
        stack: &mut Vec<u32>,
        counts: &mut GatherCounts,
    ) {
        match t.tree.sides {
            Some([outer, inner]) if self.whole => {
                let (own, other) = if faces_inside(m) { (inner, outer) } else { (outer, inner) };
                for (root, front) in [(own, true), (other, false)] {
                    self.only_front = Some(front);
                    t.run(&[root], p, frame, self, stack, counts, |_, _| false);
                }
                self.only_front = None;
            }
            _ => t.run(&[t.tree.outer_root()], p, frame, self, stack, counts, |_, _| false),
        }
        self.resolve();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::traversal::{GatherCounts, Traversal};
    use crate::types::PointTree;
    use relume_base::math::frame::Frame;
    use relume_base::types::SurfacePoints;

    /// 400 disks of radiance `l` on the plane z = `z` facing `facing` (±z), 2 × 2 wide.
    fn plane(z: f32, facing: Vec3, l: Vec3) -> (SurfacePoints, Vec<Vec3>) {
        let position: Vec<Vec3> = (0..400).map(|k| Vec3::new((k % 20) as f32 * 0.1 - 0.95, (k / 20) as f32 * 0.1 - 0.95, z)).collect();
        let pts = SurfacePoints {
            position,
            normal: vec![facing; 400],
            radius: vec![0.06; 400],
            object: vec![0; 400],
            material: vec![Material::Lambert { albedo: Vec3::ONE }; 400],
        };
        (pts, vec![l; 400])
    }

    /// A glass ball of radius 1 at the origin as points and inner twins (`TwinDielectrics`):
    /// the outer points send nothing, the twins radiance 1 into the glass. `ior` 1 keeps the
    /// twins with the outer points in one tree (`faces_inside` is false), 1.5 apart.
    fn lit_inside(ior: f32) -> PointTree {
        let k = 600;
        let outer: Vec<Vec3> = (0..k)
            .map(|i| {
                // A Fibonacci sphere: even, deterministic.
                let z = 1.0 - 2.0 * (i as f32 + 0.5) / k as f32;
                let phi = i as f32 * 2.399_963;
                let s = (1.0 - z * z).sqrt();
                Vec3::new(s * phi.cos(), s * phi.sin(), z)
            })
            .collect();
        let glass = Material::Dielectric { ior, medium: None };
        let pts = SurfacePoints {
            position: outer.clone(),
            normal: outer.clone(),
            radius: vec![0.09; k],
            object: vec![0; k],
            material: vec![glass; k],
        };
        let pts = crate::twin_dielectrics::twin_dielectrics(&pts);
        let rad: Vec<Vec3> = (0..2 * k).map(|i| if i < k { Vec3::ZERO } else { Vec3::ONE }).collect();
        PointTree::build(&pts, &rad)
    }

    #[test]
    fn the_light_sent_into_glass_is_seen_from_inside_it_only() {
        // An opaque receiver outside the ball, facing it, and a point of its surface. With the
        // twins kept apart the receiver sees the ball black (only light sent outward reaches
        // it) and the surface point reads the twins' light behind it; mixed into one tree,
        // the twins' light leaks out between the outer disks.
        let lambert = Material::Lambert { albedo: Vec3::ONE };
        let glass = Material::Dielectric { ior: 1.5, medium: None };
        let outside = |tree: &PointTree| {
            let t = Traversal::new(tree, 1.0, 1e-5);
            let mut mb = SphericalMicrobuffer::new(16);
            let (frame, mut c) = (Frame::from_normal(Vec3::Z), GatherCounts::default());
            mb.begin(&lambert, Vec3::Z);
            mb.gather(&t, &lambert, Vec3::new(0.0, 0.0, -2.0), &frame, &mut Vec::new(), &mut c);
            mb.end(&lambert, Vec3::Z)
        };
        let (apart, mixed) = (lit_inside(1.5), lit_inside(1.0));
        assert!(apart.sides.is_some() && mixed.sides.is_none());
        assert_eq!(outside(&apart), Vec3::ZERO);
        assert!(outside(&mixed).x > 0.01, "the leak this mends: {}", outside(&mixed));
        // The bottom point of the ball (normal −z): its back hemisphere looks into the glass.
        let t = Traversal::new(&apart, 1.0, 1e-5);
        let mut mb = SphericalMicrobuffer::new(16);
        let (frame, mut c) = (Frame::from_normal(-Vec3::Z), GatherCounts::default());
        mb.begin(&glass, Vec3::Z);
        mb.gather(&t, &glass, Vec3::new(0.0, 0.0, -1.0), &frame, &mut Vec::new(), &mut c);
        let (front, back) = (mb.radiance_toward(Vec3::Z), mb.radiance_toward(-Vec3::Z));
        assert_eq!(front, Vec3::ZERO);
        assert!((back.x - 1.0).abs() < 0.1, "straight through the glass: {back}");
    }

    /// A red plane above (z = 0.5, facing down) and a blue one below (z = −0.5, facing up):
    /// their points and radiance.
    fn two_planes() -> (SurfacePoints, Vec<Vec3>) {
        let (mut pts, mut rad) = plane(0.5, -Vec3::Z, Vec3::new(1.0, 0.0, 0.0));
        let (lower, lower_rad) = plane(-0.5, Vec3::Z, Vec3::new(0.0, 0.0, 2.0));
        pts.position.extend(lower.position);
        pts.normal.extend(lower.normal);
        pts.radius.extend(lower.radius);
        pts.object.extend(lower.object);
        pts.material.extend(lower.material);
        rad.extend(lower_rad);
        (pts, rad)
    }

    /// The gather of one receiver between `two_planes` at the origin, normal +z, material
    /// `m`, looking along local `wo`, into a spherical buffer of side `n`.
    fn between_planes(m: &Material, wo: Vec3, n: usize) -> (Vec3, SphericalMicrobuffer, GatherCounts) {
        let (pts, rad) = two_planes();
        let tree = PointTree::build(&pts, &rad);
        let t = Traversal::new(&tree, 1.0, 1e-5);
        let mut mb = SphericalMicrobuffer::new(n);
        let mut counts = GatherCounts::default();
        mb.begin(m, wo);
        t.run(&[tree.root], Vec3::ZERO, &Frame::from_normal(Vec3::Z), &mut mb, &mut Vec::new(), &mut counts, |_, _| false);
        (mb.end(m, wo), mb, counts)
    }

    fn glass(ior: f32) -> Material {
        Material::Dielectric { ior, medium: None }
    }

    #[test]
    fn an_opaque_receiver_gets_the_hemispherical_buffers_bytes() {
        let m = Material::BlinnPhong { kd: Vec3::splat(0.4), ks: Vec3::splat(0.3), exponent: 20.0 };
        let wo = Vec3::new(0.3, -0.2, 0.9).normalize();
        let (l, mb, _) = between_planes(&m, wo, 16);
        assert!(!mb.whole());
        assert!(mb.back.radiance().iter().all(|l| *l == Vec3::ZERO), "nothing behind an opaque receiver");
        // The same traversal into the plain buffer.
        let (pts, rad) = two_planes();
        let tree = PointTree::build(&pts, &rad);
        let t = Traversal::new(&tree, 1.0, 1e-5);
        let mut plain = Microbuffer::new(16);
        GatherBuffer::begin(&mut plain, &m, wo);
        t.run(&[tree.root], Vec3::ZERO, &Frame::from_normal(Vec3::Z), &mut plain, &mut Vec::new(), &mut GatherCounts::default(), |_, _| {
            false
        });
        assert_eq!(l.to_array(), plain.end(&m, wo).to_array());
        assert_eq!(mb.front.radiance(), plain.radiance());
        // Red only: the blue plane lies under the horizon.
        assert!(l.x > 0.0 && l.y == 0.0 && l.z == 0.0, "{l}");
    }

    #[test]
    fn index_one_sees_straight_through_and_a_dielectric_sees_both_sides() {
        // ior 1: no reflection, the ray goes on unbent: exactly the back pixel behind, the
        // blue plane's radiance 2 (within the coverage of the pixel it lands in).
        for wo in [Vec3::Z, Vec3::new(0.2, 0.1, 0.97).normalize()] {
            let (l, mb, _) = between_planes(&glass(1.0), wo, 16);
            assert!(mb.whole());
            assert_eq!(l.to_array(), mb.radiance_toward(-wo).to_array());
            assert!(l.x == 0.0 && (l.z - 2.0).abs() < 0.1, "ior 1 along {wo}: {l}");
        }
        // Glass: F of the red plane above plus (1 − F)/η² of the blue plane below; at normal
        // incidence F = 0.04.
        let (l, _, _) = between_planes(&glass(1.5), Vec3::Z, 16);
        assert!((l.x - 0.04).abs() < 0.004 && (l.z - 0.96 / 2.25 * 2.0).abs() < 0.05, "{l}");
    }

    #[test]
    fn total_internal_reflection_and_extreme_indices_stay_finite_and_bounded() {
        // Inside the glass (wo.z < 0) past the critical angle: all reflection, from the back
        // hemisphere (the blue plane), nothing from the front.
        // 50° from the normal, past the critical angle (41.8°).
        let wo = Vec3::new(50f32.to_radians().sin(), 0.0, -50f32.to_radians().cos());
        let (l, _, _) = between_planes(&glass(1.5), wo, 16);
        assert!(l.x == 0.0 && l.z > 1.5 && l.z <= 2.0 * 1.001, "total internal reflection: {l}");
        // Every index and direction, 1 × 1 to 64 × 64 buffers: finite, and never more than the
        // brightest radiance around (2) times the largest lobe weight (1 for reflection,
        // ior² for refraction into the thinner side).
        for ior in [1.0, 1.33, 1.5, 2.4] {
            for n in [1, 8, 64] {
                for wo in [Vec3::Z, Vec3::new(0.999, 0.0, 0.04).normalize(), -Vec3::Z, Vec3::new(0.3, 0.4, -0.8).normalize()] {
                    let (l, _, _) = between_planes(&glass(ior), wo, n);
                    assert!(l.is_finite() && l.min_element() >= 0.0, "ior {ior}, n {n}, wo {wo}: {l}");
                    assert!(l.max_element() <= 2.0 * ior * ior * 1.001, "ior {ior}, n {n}, wo {wo}: {l}");
                }
            }
        }
    }

    #[test]
    fn a_transmitting_receiver_looks_past_the_disks_of_its_own_surface() {
        // The receiver lies in a layer of black disks overlapping beneath it (its own surface:
        // the points around it and their twins), facing into the glass. Index 1 must still
        // see straight through to the blue plane below, radiance 2.
        let (mut pts, mut rad) = two_planes();
        for k in 0..400 {
            let p = Vec3::new((k % 20) as f32 * 0.05 - 0.475, (k / 20) as f32 * 0.05 - 0.475, -1e-4);
            pts.position.push(p);
            pts.normal.push(-Vec3::Z);
            pts.radius.push(0.04);
            pts.object.push(1);
            pts.material.push(glass(1.0));
            rad.push(Vec3::ZERO);
        }
        let tree = PointTree::build(&pts, &rad);
        let t = Traversal::new(&tree, 1.0, 1e-5);
        let mut mb = SphericalMicrobuffer::new(16);
        mb.begin(&glass(1.0), Vec3::Z);
        let mut counts = GatherCounts::default();
        t.run(&[tree.root], Vec3::ZERO, &Frame::from_normal(Vec3::Z), &mut mb, &mut Vec::new(), &mut counts, |_, _| false);
        let l = mb.end(&glass(1.0), Vec3::Z);
        assert!(counts.near_leaves > 0, "{counts:?}");
        assert!((l.z - 2.0).abs() < 0.1, "straight through its own surface: {l}");
    }

    #[test]
    fn a_transmitting_receiver_culls_nothing_under_its_horizon() {
        let (_, _, opaque) = between_planes(&Material::Lambert { albedo: Vec3::ONE }, Vec3::Z, 8);
        let (_, mb, whole) = between_planes(&glass(1.5), Vec3::Z, 8);
        assert!(whole.rasterised + whole.near_leaves > opaque.rasterised + opaque.near_leaves, "{whole:?} {opaque:?}");
        assert!(mb.back.radiance().iter().any(|l| l.z > 0.0) && mb.back.radiance().iter().all(|l| l.x == 0.0));
        assert!(mb.front.radiance().iter().all(|l| l.z == 0.0));
    }
}
