//! The images of the spatially varying extension of pixel relighting ([S] 4.2, 4-36): which
//! (ρ′, R1, ρ1) groups exist, how many sub-region images each holds, and what they cost
//! before compression — the figure a precompute must refuse before allocating.
//!
//! Each dynamic object is split into n × n sub-regions of its UV square; one-bounce images
//! gain the sub-region index r1 of x″. Direct light keeps N_b direct bases (6 by default: the
//! texture acts per pixel through the exact texel at x′); the bounce uses fewer, N_b indirect
//! (4), and specular-to-specular inter-reflection is dropped (4-36: zero unless ρ′ or ρ1 is
//! the diffuse basis), which leaves 2·N_b,indirect − 1 (ρ′, ρ1) pairs per dynamic object R1: 7,
//! each a block of n² RGB images (textures make every such path coloured). Fixed objects at x″
//! have no sub-regions (one image per ρ′). With the thesis' setting — one dynamic object,
//! 32 × 32 sub-regions, 512² pixels — that is 7 × 1024 × 512² × 3 × 4 B = 21 GiB.

use super::terms::First;

/// What decides the SV images of a scene.
#[derive(Clone, Copy, Debug)]
pub struct SvTraits {
    /// Dynamic (textured) objects, each split into sub-regions.
    pub dynamic_objects: usize,
    pub fixed_objects: bool,
    /// Sub-regions per side (n; n² per object).
    pub sub_regions: usize,
    /// Bases for direct light (N_b direct, the diffuse one included).
    pub direct_bases: usize,
    /// Bases for the bounce (N_b indirect, the diffuse one included).
    pub indirect_bases: usize,
}

/// One block of n² sub-region images: x′ with `first`, x″ on dynamic object `object` in one
/// of its sub-regions with basis `second` (0: diffuse).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SvGroup {
    pub first: First,
    pub object: u16,
    pub second: u16,
}

/// The SV images of a scene.
#[derive(Clone, Debug)]
pub struct SvTerms {
    pub traits: SvTraits,
    /// The blocks of sub-region images, in a fixed order (object, then ρ′, then ρ1).
    pub groups: Vec<SvGroup>,
    /// Images without sub-regions: direct light (one per direct basis) and the bounce onto
    /// fixed objects (one per indirect basis), all RGB.
    pub plain_images: usize,
}

impl SvTerms {
    /// RGB images in all (the groups' sub-region images and the plain ones).
    pub fn images(&self) -> u64 {
        let n2 = (self.traits.sub_regions * self.traits.sub_regions) as u64;
        self.groups.len() as u64 * n2 + self.plain_images as u64
    }

    /// Bytes of every image at `width × height` before compression (RGB f32).
    pub fn uncompressed_bytes(&self, width: usize, height: usize) -> u64 {
        self.images() * width as u64 * height as u64 * 12
    }

    /// Bytes of one group's block at `width × height` (what compressing a group holds).
    pub fn group_bytes(&self, width: usize, height: usize) -> u64 {
        (self.traits.sub_regions * self.traits.sub_regions) as u64 * width as u64 * height as u64 * 12
    }
}

/// Enumerates the SV images (see the module doc). The bases must satisfy
/// 1 ≤ indirect ≤ direct.
pub fn enumerate_sv(t: &SvTraits) -> Result<SvTerms, String> {
    if t.indirect_bases == 0 || t.indirect_bases > t.direct_bases {
        return Err(format!("the bounce takes 1 to {} bases (the direct ones), not {}", t.direct_bases, t.indirect_bases));
    }
    if t.sub_regions == 0 {
        return Err("an object needs at least one sub-region".into());
    }
    let first = |k: usize| if k == 0 { First::Merged } else { First::Specular(k as u16) };
    let mut groups = Vec::new();
    for object in 0..t.dynamic_objects as u16 {
        for f in 0..t.indirect_bases {
            for s in 0..t.indirect_bases {
                // [S] 4-36: no specular-to-specular inter-reflection.
                if f == 0 || s == 0 {
                    groups.push(SvGroup { first: first(f), object, second: s as u16 });
                }
            }
        }
    }
    let plain_images = t.direct_bases + if t.fixed_objects { t.indirect_bases } else { 0 };
    Ok(SvTerms { traits: *t, groups, plain_images })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn thesis() -> SvTraits {
        SvTraits { dynamic_objects: 1, fixed_objects: false, sub_regions: 32, direct_bases: 6, indirect_bases: 4 }
    }

    #[test]
    fn the_thesis_setting_has_seven_pairs_of_1024_images_and_holds_21_gib() {
        let sv = enumerate_sv(&thesis()).unwrap();
        assert_eq!(sv.groups.len(), 7, "2 · 4 − 1 pairs with a diffuse basis on either side");
        assert!(sv.groups.iter().all(|g| g.first == First::Merged || g.second == 0));
        let group_images = 7 * 1024;
        assert_eq!(sv.images(), group_images + 6);
        let gib = sv.uncompressed_bytes(512, 512) as f64 / (1u64 << 30) as f64;
        assert!((gib - 21.0).abs() < 0.1, "{gib} GiB");
        assert_eq!(sv.group_bytes(512, 512), 3 << 30, "one group's block: 3 GiB");
    }

    #[test]
    fn counts_follow_objects_bases_and_fixed_objects() {
        for d in [1usize, 2, 4] {
            for nb in [1usize, 2, 4, 6] {
                let t = SvTraits { dynamic_objects: d, fixed_objects: true, sub_regions: 4, direct_bases: 6, indirect_bases: nb };
                let sv = enumerate_sv(&t).unwrap();
                assert_eq!(sv.groups.len(), d * (2 * nb - 1), "D = {d}, N_b = {nb}");
                assert_eq!(sv.plain_images, 6 + nb);
                let mut seen = sv.groups.clone();
                seen.dedup();
                assert_eq!(seen.len(), sv.groups.len());
            }
        }
    }

    #[test]
    fn impossible_settings_are_errors() {
        assert!(enumerate_sv(&SvTraits { indirect_bases: 7, ..thesis() }).unwrap_err().contains("1 to 6"));
        assert!(enumerate_sv(&SvTraits { indirect_bases: 0, ..thesis() }).is_err());
        assert!(enumerate_sv(&SvTraits { sub_regions: 0, ..thesis() }).is_err());
    }
}
