//! TestPattern node.

use crate::math::rng::uniform;
use crate::types::Image;
use rayon::prelude::*;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};

node_doc! {
    /// A synthetic image for tests, benchmarks and filter demos: a gradient, a checkerboard
    /// or a constant colour, plus optional seeded uniform noise of ± noise/2 (the same bytes
    /// on any thread count).
    pub struct TestPattern;
}

pub const PATTERNS: &[&str] = &["Gradient", "Checker", "Constant"];

pub struct TestPatternParams {
    pub width: usize,
    pub height: usize,
    pub pattern: String,
    pub cell: usize,
    pub color: [f32; 3],
    pub noise: f32,
    pub seed: u64,
}

impl Params for TestPatternParams {
    fn schema() -> Schema {
        Schema::new()
            .int("width", 64, 1, 16384)
            .unit("px")
            .help("image width")
            .int("height", 64, 1, 16384)
            .unit("px")
            .help("image height")
            .enumeration("pattern", PATTERNS, "Gradient")
            .help("what to draw")
            .int("cell", 8, 1, 4096)
            .unit("px")
            .help("checker cell size")
            .rgb("color", [1.0, 1.0, 1.0], 0.0, 1e6)
            .help("colour (scales the pattern)")
            .float("noise", 0.0, 0.0, 1e6)
            .help("amplitude of uniform noise added to every channel")
            .int("seed", 0, 0, i64::MAX)
            .help("noise seed")
    }
    fn from_values(v: &ParamValues) -> Self {
        TestPatternParams {
            width: v.int("width") as usize,
            height: v.int("height") as usize,
            pattern: v.variant("pattern").to_string(),
            cell: v.int("cell") as usize,
            color: v.triple("color").map(|x| x as f32),
            noise: v.float("noise") as f32,
            seed: v.int("seed") as u64,
        }
    }
}

impl Node for TestPattern {
    const KIND: &'static str = "TestPattern";
    const VERSION: u32 = 2;
    const CATEGORY: &'static str = "image";
    const CACHING: Caching = Caching::Memory;
    type Params = TestPatternParams;

    fn ports() -> Ports {
        Ports::new().output::<Image>("image")
    }

    fn run(&self, p: &TestPatternParams, io: &mut Io, _cx: &RunCtx) -> Result<(), NodeError> {
        let mut img = Image::try_new(p.width, p.height)?;
        let (w, h) = (p.width, p.height);
        img.pixels.par_iter_mut().enumerate().for_each(|(i, px)| {
            let (x, y) = (i % w, i / w);
            let base = match p.pattern.as_str() {
                "Gradient" => [(x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32, 0.5],
                "Checker" => [((x / p.cell + y / p.cell) % 2) as f32; 3],
                _ => [1.0; 3],
            };
            *px = std::array::from_fn(|c| {
                let n = if p.noise > 0.0 { (uniform(p.seed, i as u64, c as u32) - 0.5) * p.noise } else { 0.0 };
                base[c] * p.color[c] + n
            });
        });
        io.set("image", img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{f, first, i, id, run_on};

    #[test]
    fn patterns_have_the_expected_values() {
        let g: Image = first(&run_on(TestPattern, &[("width", i(4)), ("height", i(2))], vec![]).unwrap());
        assert_eq!(g.get(0, 0), [0.125, 0.25, 0.5]);
        let c: Image = first(&run_on(TestPattern, &[("pattern", id("Checker")), ("cell", i(2))], vec![]).unwrap());
        assert_eq!((c.get(0, 0)[0], c.get(2, 0)[0], c.get(2, 2)[0]), (0.0, 1.0, 0.0));
    }

    #[test]
    fn noise_is_seeded_and_bounded() {
        let run = |seed| -> Image {
            first(&run_on(TestPattern, &[("pattern", id("Constant")), ("noise", f(0.2)), ("seed", i(seed))], vec![]).unwrap())
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
        assert!(run(3).as_floats().iter().all(|x| (0.9..=1.1).contains(x)));
    }

    #[test]
    fn the_largest_size_is_refused_before_allocating() {
        let err = run_on(TestPattern, &[("width", i(16384)), ("height", i(16384))], vec![]).unwrap_err();
        assert!(err.to_string().contains("3.0 GiB"), "{err}");
    }
}
