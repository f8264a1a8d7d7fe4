//! What the spatially varying precompute's paths weigh with ([S] 4.2, 4-35, 4-36): every
//! direct basis at x′ on a dynamic object, the first N_b,indirect bases at x″ on a dynamic
//! object in its UV sub-region r1, own BRDFs on fixed objects; and where each (x′ slot, x″
//! slot) pair accumulates (`SvLayout`). Pairs the extension drops (specular at both ends,
//! 4-36; x′ bases beyond the indirect ones on a bounce) go to one discarded accumulator.

use super::paths::{object_classes, Shade, Slots, MAX_SLOTS};
use super::sv_terms::{enumerate_sv, SvTerms, SvTraits};
use super::terms::First;
use glam::{Vec2, Vec3};
use relume_base::brdf;
use relume_base::render::surface::Surface;
use relume_base::types::{BrdfBasis, Scene};

/// The sub-region (cell of the n × n grid over the UV square, row v, column u; UVs repeat) of
/// `uv`: `row * n + column`.
pub fn cell(uv: Vec2, n: usize) -> usize {
    let f = |t: f32| {
        let t = if t.is_finite() { t.rem_euclid(1.0) } else { 0.0 };
        ((t * n as f32) as usize).min(n - 1)
    };
    f(uv.y) * n + f(uv.x)
}

/// The UV rectangle of sub-region `r` of an n × n grid: ((u0, u1), (v0, v1)).
pub fn cell_rect(r: usize, n: usize) -> ((f32, f32), (f32, f32)) {
    let (row, col) = (r / n, r % n);
    let s = 1.0 / n as f32;
    ((col as f32 * s, (col + 1) as f32 * s), (row as f32 * s, (row + 1) as f32 * s))
}

/// The SV images of `scene` (see `sv_terms`).
pub fn scene_sv_terms(scene: &Scene, sub_regions: usize, direct: usize, indirect: usize) -> Result<SvTerms, String> {
    enumerate_sv(&SvTraits {
        dynamic_objects: scene.dynamic_groups().len(),
        fixed_objects: object_classes(scene).contains(&0),
        sub_regions,
        direct_bases: direct,
        indirect_bases: indirect,
    })
}

/// Where the accumulators of one pixel lie: direct light per direct basis, the light seen
/// directly, the bounce onto fixed objects per x′ basis, then each group's n² sub-regions, then
/// the discarded pairs.
#[derive(Clone, Debug)]
pub struct SvLayout {
    /// Direct-light accumulators (the first ones, one per direct basis).
    pub direct: usize,
    pub emitted: Option<usize>,
    /// First accumulator of the bounce onto fixed objects (one per indirect x′ basis).
    pub fixed: Option<usize>,
    /// First accumulator of group q's sub-regions: `groups + q · n²`.
    pub groups: usize,
    pub trash: usize,
    pub accumulators: usize,
}

impl SvLayout {
    /// The layout and the paths' slot tables for `sv` (`emitters`: the scene has light to see).
    pub fn new(sv: &SvTerms, emitters: bool) -> (SvLayout, Slots) {
        let t = sv.traits;
        let (nbd, nbi, n2) = (t.direct_bases, t.indirect_bases, t.sub_regions * t.sub_regions);
        let mut next = nbd;
        let emitted = emitters.then(|| {
            next += 1;
            next - 1
        });
        let fixed = t.fixed_objects.then(|| {
            next += nbi;
            next - nbi
        });
        let groups = next;
        let trash = groups + sv.groups.len() * n2;
        let layout = SvLayout { direct: nbd, emitted, fixed, groups, trash, accumulators: trash + 1 };
        // Second slots: [fixed] then, per dynamic object g and sub-region r, nbi bases.
        let fixed_offset = t.fixed_objects as usize;
        let n_second = fixed_offset + t.dynamic_objects * n2 * nbi;
        let first = |f: usize| if f == 0 { First::Merged } else { First::Specular(f as u16) };
        let mut bounce = vec![trash as u32; nbd * n_second];
        for f in 0..nbi {
            if let Some(base) = fixed {
                bounce[f * n_second] = (base + f) as u32;
            }
            for (q, g) in sv.groups.iter().enumerate().filter(|(_, g)| g.first == first(f)) {
                for r in 0..n2 {
                    let x = fixed_offset + (g.object as usize * n2 + r) * nbi + g.second as usize;
                    bounce[f * n_second + x] = (groups + q * n2 + r) as u32;
                }
            }
        }
        let slots = Slots {
            direct: (0..nbd as u32).collect(),
            bounce,
            n_second,
            emitted: emitted.map(|e| e as u32),
            accumulators: layout.accumulators,
        };
        (layout, slots)
    }
}

/// The SV shade: basis BRDFs on dynamic objects (x″ by sub-region), own BRDFs on fixed ones.
pub struct SvShade<'a> {
    scene: &'a Scene,
    basis: &'a BrdfBasis,
    /// 0: fixed; g + 1: dynamic object g.
    class: Vec<u32>,
    sub_regions: usize,
    indirect: usize,
    fixed_offset: usize,
}

impl<'a> SvShade<'a> {
    pub fn new(scene: &'a Scene, basis: &'a BrdfBasis, sv: &SvTerms) -> SvShade<'a> {
        let t = sv.traits;
        SvShade {
            scene,
            basis,
            class: object_classes(scene),
            sub_regions: t.sub_regions,
            indirect: t.indirect_bases,
            fixed_offset: t.fixed_objects as usize,
        }
    }

    fn bases(&self, wi: Vec3, wo: Vec3, out: &mut [Vec3], n: usize) -> usize {
        let nb = self.basis.bases();
        let mut v = [0.0f32; MAX_SLOTS];
        self.basis.eval_all(wi, wo, &mut v[..nb]);
        for k in 0..n {
            out[k] = Vec3::splat(v[k]);
        }
        n
    }
}

impl Shade for SvShade<'_> {
    fn first(&self, at: &Surface, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> usize {
        match self.class[at.object as usize] {
            0 => {
                out[0] = brdf::eval(&at.material(self.scene), wo, wi);
                1
            }
            _ => self.bases(wi, wo, out, self.basis.bases()),
        }
    }
    fn second(&self, at: &Surface, wi: Vec3, wo: Vec3, out: &mut [Vec3]) -> (usize, usize) {
        match self.class[at.object as usize] {
            0 => {
                out[0] = brdf::eval(&at.material(self.scene), wo, wi);
                (0, 1)
            }
            c => {
                let n2 = self.sub_regions * self.sub_regions;
                let r = cell(at.uv, self.sub_regions);
                let base = self.fixed_offset + ((c as usize - 1) * n2 + r) * self.indirect;
                (base, self.bases(wi, wo, out, self.indirect))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_cover_the_uv_square_row_by_row_and_repeat() {
        let n = 4;
        assert_eq!(cell(Vec2::new(0.0, 0.0), n), 0);
        assert_eq!(cell(Vec2::new(0.99, 0.0), n), 3);
        assert_eq!(cell(Vec2::new(0.0, 0.26), n), 4);
        assert_eq!(cell(Vec2::new(1.0, 1.0), n), 0, "UVs repeat");
        assert_eq!(cell(Vec2::new(-0.1, 0.1), n), 3);
        assert_eq!(cell(Vec2::new(f32::NAN, 0.6), n), 8);
        for r in 0..n * n {
            let ((u0, u1), (v0, v1)) = cell_rect(r, n);
            assert_eq!(cell(Vec2::new((u0 + u1) / 2.0, (v0 + v1) / 2.0), n), r);
        }
    }

    #[test]
    fn the_layout_sends_each_kept_pair_to_its_group_and_the_dropped_ones_to_the_trash() {
        let sv = enumerate_sv(&SvTraits { dynamic_objects: 2, fixed_objects: true, sub_regions: 2, direct_bases: 4, indirect_bases: 3 })
            .unwrap();
        let (l, slots) = SvLayout::new(&sv, true);
        assert_eq!((l.emitted, l.fixed, l.groups), (Some(4), Some(5), 8));
        assert_eq!(sv.groups.len(), 2 * 5);
        assert_eq!(l.trash, 8 + 10 * 4);
        // Every group accumulator is reached exactly once; the fixed ones once per x′ basis.
        let mut hits = vec![0; l.accumulators];
        slots.bounce.iter().for_each(|&i| hits[i as usize] += 1);
        assert!(hits[l.groups..l.trash].iter().all(|&h| h == 1), "{hits:?}");
        assert!(hits[5..8].iter().all(|&h| h == 1));
        // Dropped: x′ basis 3 (direct only) everywhere, and specular × specular.
        let n_second = slots.n_second;
        assert!(slots.bounce[3 * n_second..].iter().all(|&i| i as usize == l.trash));
        let spec_spec = 2; // after the fixed slot: object 0, sub-region 0, x″ basis 1
        assert_eq!(slots.bounce[n_second + spec_spec] as usize, l.trash);
    }
}
