//! The transfer images pixel relighting stores ([S] 4.1.1, 4.1.3, table 4-1, 4.1.5): which
//! (path, basis) terms a scene has, which of them can be grey, and what they cost.
//!
//! A pixel's first hit x′ lies on one object, so images are per basis, not per object: the
//! object-id image says which object's coefficients multiply a pixel. At x′ the term uses
//! either a specular basis k (1..=S) of a dynamic object, or the *merged* slot: the diffuse
//! basis of a dynamic object or the own BRDF of a fixed-material object (their pixels never
//! overlap, so they share one image — this is how [S] 4.1.5 reaches 29 RGB images, see
//! docs/PIPELINES.md). Direct light at x′ is `Direct(first)`; one bounce x′ → x″ with direct light
//! at x″ is `Bounce(first, second)`, where x″ is a fixed-material object (all of them in one
//! image) or dynamic object r with its diffuse basis or specular basis k.
//!
//! With D dynamic objects and S specular bases this gives grey = S + D·S² and RGB =
//! 2 + D + S + 2DS (55 and 29 for D = 2, S = 5): a term is grey when nothing on its path has
//! a colour of its own — no diffuse basis (Kd and textures act on the diffuse term only), no
//! fixed-material object — and every light has the same colour; otherwise RGB. A scene without
//! fixed-material objects has no `Bounce(_, Fixed)` terms (1 + S images fewer).
//!
//! Besides these, a scene with emitters or an environment stores the light seen directly,
//! `Emitted`, in one more image (grey under one light colour), weighted 1 for every pixel: it
//! averages every camera sample of a pixel whatever object the others hit, so the edge of a
//! light is antialiased like the reference's, where folding it into the object's own direct
//! image (as the thesis' count does) made the light's edge pixels all light or all ceiling —
//! 99 % of the L2 error against the path tracer on cornell-bunny came from those 100 pixels.
//! It is not among the thesis' counts (`TermSet::count`).

use serde::{Deserialize, Serialize};

/// What the first hit x′ contributes with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum First {
    /// The diffuse basis of a dynamic object, or a fixed object's own BRDF.
    Merged,
    /// Specular basis `k` (1-based, 1..=S) of a dynamic object.
    Specular(u16),
}

/// What the second hit x″ of a one-bounce path is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Second {
    /// Any fixed-material object (its own BRDF).
    Fixed,
    /// Dynamic object `object` (index among the dynamic objects) with its diffuse basis.
    Diffuse { object: u16 },
    /// Dynamic object `object` with specular basis `basis` (1..=S).
    Specular { object: u16, basis: u16 },
}

/// One stored image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Term {
    Direct(First),
    Bounce(First, Second),
    /// Emission seen directly (emitters, the environment): weight 1 on every pixel.
    Emitted,
}

/// Channels of a stored image.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Channels {
    Grey,
    Rgb,
}

impl Channels {
    pub fn count(self) -> usize {
        match self {
            Channels::Grey => 1,
            Channels::Rgb => 3,
        }
    }
}

/// What of a scene decides its terms.
#[derive(Clone, Copy, Debug)]
pub struct SceneTraits {
    /// Objects whose material is edited (D).
    pub dynamic_objects: usize,
    /// Whether any object keeps its own material (walls, a floor).
    pub fixed_objects: bool,
    /// Whether every light has the same colour (then specular-only paths can be grey).
    pub one_light_colour: bool,
    /// Specular bases (S = N_b − 1).
    pub specular_bases: usize,
    /// Whether a camera ray can see light directly (emitting objects or an environment).
    pub emitters: bool,
}

/// The terms of a scene, in a fixed order, with their channels, and sentences saying what was
/// left out and why (for the report).
#[derive(Clone, Debug)]
pub struct TermSet {
    pub terms: Vec<(Term, Channels)>,
    pub left_out: Vec<String>,
}

impl TermSet {
    /// Transfer images of channels `c` (the thesis' count: `Emitted` is not among them).
    pub fn count(&self, c: Channels) -> usize {
        self.terms.iter().filter(|t| t.1 == c && t.0 != Term::Emitted).count()
    }
    /// Whether the light seen directly has its own image.
    pub fn emitted(&self) -> bool {
        self.index(Term::Emitted).is_some()
    }
    /// Floats per pixel over every image.
    pub fn floats_per_pixel(&self) -> usize {
        self.terms.iter().map(|t| t.1.count()).sum()
    }
    /// Bytes of every image at `width × height`, f32 (what the precompute will hold).
    pub fn bytes(&self, width: usize, height: usize) -> u64 {
        self.floats_per_pixel() as u64 * width as u64 * height as u64 * 4
    }
    /// The index of `term` in `terms`.
    pub fn index(&self, term: Term) -> Option<usize> {
        self.terms.iter().position(|t| t.0 == term)
    }
}

/// Enumerates the terms of a scene (see the module doc).
pub fn enumerate(t: &SceneTraits) -> TermSet {
    let s = t.specular_bases as u16;
    let d = t.dynamic_objects as u16;
    let firsts: Vec<First> = std::iter::once(First::Merged).chain((1..=s).map(First::Specular)).collect();
    let mut seconds = Vec::new();
    if t.fixed_objects {
        seconds.push(Second::Fixed);
    }
    for object in 0..d {
        seconds.push(Second::Diffuse { object });
        seconds.extend((1..=s).map(|basis| Second::Specular { object, basis }));
    }
    let colourless_first = |f: First| matches!(f, First::Specular(_));
    let colourless_second = |x: Second| matches!(x, Second::Specular { .. });
    let grey_if = |colourless: bool| if colourless && t.one_light_colour { Channels::Grey } else { Channels::Rgb };
    let mut terms = Vec::new();
    for &f in &firsts {
        terms.push((Term::Direct(f), grey_if(colourless_first(f))));
    }
    for &f in &firsts {
        for &x in &seconds {
            terms.push((Term::Bounce(f, x), grey_if(colourless_first(f) && colourless_second(x))));
        }
    }
    if t.emitters {
        terms.push((Term::Emitted, grey_if(true)));
    }
    let mut left_out = Vec::new();
    if !t.emitters {
        left_out.push("no emitter or environment is seen: no image of directly seen light".to_string());
    }
    if !t.fixed_objects {
        left_out.push(format!("no fixed-material object: the {} one-bounce images onto fixed objects are not computed", firsts.len()));
    }
    if d == 0 {
        left_out.push("no dynamic object: only the fixed objects' own terms are computed".to_string());
    }
    if !t.one_light_colour {
        left_out.push("the lights differ in colour: specular-only terms are stored in RGB, not grey".to_string());
    }
    TermSet { terms, left_out }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn traits(d: usize, fixed: bool, one_colour: bool, s: usize) -> SceneTraits {
        SceneTraits { dynamic_objects: d, fixed_objects: fixed, one_light_colour: one_colour, specular_bases: s, emitters: true }
    }

    #[test]
    fn two_dynamic_objects_and_six_bases_give_the_thesis_55_grey_and_29_rgb_images() {
        let set = enumerate(&traits(2, true, true, 5));
        assert_eq!((set.count(Channels::Grey), set.count(Channels::Rgb)), (55, 29));
        // At 512² that is about 142 MiB, the thesis' "140 MB", and one grey image of the light
        // seen directly.
        assert!(set.emitted());
        assert_eq!(set.bytes(512, 512), (55 + 1 + 3 * 29) * 512 * 512 * 4);
        assert!((set.bytes(512, 512) as f64 / (1u64 << 20) as f64 - 143.0).abs() < 0.5);
        assert!(set.left_out.is_empty(), "{:?}", set.left_out);
        let dark = enumerate(&SceneTraits { emitters: false, ..traits(2, true, true, 5) });
        assert!(!dark.emitted() && dark.terms.len() == 84);
        assert!(dark.left_out[0].contains("no emitter"), "{:?}", dark.left_out);
    }

    #[test]
    fn counts_follow_the_corrected_formulas_for_one_two_and_four_dynamic_objects() {
        for d in [1usize, 2, 4] {
            for s in [1usize, 3, 5] {
                let with = enumerate(&traits(d, true, true, s));
                assert_eq!(with.count(Channels::Grey), s + d * s * s, "D={d} S={s}");
                assert_eq!(with.count(Channels::Rgb), 2 + d + s + 2 * d * s, "D={d} S={s}");
                // Without fixed objects: no bounce onto them (1 + S images fewer, all RGB).
                let without = enumerate(&traits(d, false, true, s));
                assert_eq!(without.count(Channels::Grey), s + d * s * s);
                assert_eq!(without.count(Channels::Rgb), 1 + d + 2 * d * s);
                assert!(without.terms.iter().all(|t| !matches!(t.0, Term::Bounce(_, Second::Fixed))));
                assert!(without.left_out[0].contains(&format!("{} one-bounce images onto fixed objects", 1 + s)));
            }
        }
    }

    #[test]
    fn lights_of_several_colours_make_every_image_rgb() {
        let set = enumerate(&traits(2, true, false, 5));
        assert_eq!((set.count(Channels::Grey), set.count(Channels::Rgb)), (0, 84));
        assert_eq!(set.terms[set.index(Term::Emitted).unwrap()].1, Channels::Rgb);
        assert!(set.left_out.iter().any(|l| l.contains("differ in colour")));
    }

    #[test]
    fn terms_are_unique_and_in_a_fixed_order() {
        let set = enumerate(&traits(4, true, true, 5));
        let mut sorted: Vec<Term> = set.terms.iter().map(|t| t.0).collect();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), set.terms.len());
        assert_eq!(set.terms[0].0, Term::Direct(First::Merged));
        assert_eq!(set.index(Term::Bounce(First::Specular(1), Second::Fixed)), Some(6 + (1 + 4 * 6)));
        let again = enumerate(&traits(4, true, true, 5));
        assert_eq!(set.terms, again.terms);
    }
}
