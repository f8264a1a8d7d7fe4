use crate::math::rng::uniform;
use crate::types::Image;
use rayon::prelude::*;
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

params! {
    /// A synthetic image for tests, benchmarks and filter demos: a gradient, a checkerboard
    /// or a constant colour, plus optional seeded uniform noise of ± noise/2 (the same bytes
    /// on any thread count).
    pub struct TestPattern {
        /// image width
        pub width: usize = 64, range = 1..=16384, unit = "px";
        /// image height
        pub height: usize = 64, range = 1..=16384, unit = "px";
        /// what to draw
        pub pattern: Pattern = Gradient;
        /// checker cell size
        pub cell: usize = 8, range = 1..=4096, unit = "px";
        /// colour (scales the pattern)
        pub color: [f32; 3] = (1.0, 1.0, 1.0), rgb, range = 0.0..=1e6;
        /// amplitude of uniform noise added to every channel
        pub noise: f32 = 0.0, range = 0.0..=1e6;
        /// noise seed
        pub seed: u64 = 0, range = 0..=i64::MAX;
    }
}

/// What TestPattern draws.
#[derive(Clone, Copy, Debug, PartialEq, ParamEnum)]
pub enum Pattern {
    Gradient,
    Checker,
    Constant,
}

#[node(category = "image", version = 2, outputs = [image])]
impl TestPattern {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        let _ = inputs;
        relume_core::MemoryEstimate { outputs: vec![Some(relume_core::PortSize::image(self.width, self.height))], working: 0 }
    }

    fn run(&self, _cx: &RunCtx) -> Result<Image, NodeError> {
        let mut img = Image::try_new(self.width, self.height)?;
        let (w, h, cell) = (self.width, self.height, self.cell);
        img.pixels.par_iter_mut().enumerate().for_each(|(i, px)| {
            let (x, y) = (i % w, i / w);
            let base = match self.pattern {
                Pattern::Gradient => [(x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32, 0.5],
                Pattern::Checker => [((x / cell + y / cell) % 2) as f32; 3],
                Pattern::Constant => [1.0; 3],
            };
            *px = std::array::from_fn(|c| {
                let n = if self.noise > 0.0 { (uniform(self.seed, i as u64, c as u32) - 0.5) * self.noise } else { 0.0 };
                base[c] * self.color[c] + n
            });
        });
        Ok(img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{f, first, i, id, run_on};

    #[test]
    fn patterns_have_the_expected_values() {
        let g: Image = first(&run_on::<TestPattern>(&[("width", i(4)), ("height", i(2))], vec![]).unwrap());
        assert_eq!(g.get(0, 0), [0.125, 0.25, 0.5]);
        let c: Image = first(&run_on::<TestPattern>(&[("pattern", id("Checker")), ("cell", i(2))], vec![]).unwrap());
        assert_eq!((c.get(0, 0)[0], c.get(2, 0)[0], c.get(2, 2)[0]), (0.0, 1.0, 0.0));
    }

    #[test]
    fn noise_is_seeded_and_bounded() {
        let run = |seed| -> Image {
            first(&run_on::<TestPattern>(&[("pattern", id("Constant")), ("noise", f(0.2)), ("seed", i(seed))], vec![]).unwrap())
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
        assert!(run(3).as_floats().iter().all(|x| (0.9..=1.1).contains(x)));
    }

    #[test]
    fn the_largest_size_is_refused_before_allocating() {
        let err = run_on::<TestPattern>(&[("width", i(16384)), ("height", i(16384))], vec![]).unwrap_err();
        assert!(err.to_string().contains("3.0 GiB"), "{err}");
    }
}
