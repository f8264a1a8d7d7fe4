use crate::types::Image;
use rayon::prelude::*;
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// Weighted sum of two images of the same size: out = weight_a · a + weight_b · b
    /// (direct + indirect lighting, or the difference of two renders with weight_b = −1).
    pub struct Combine {
        /// factor on input a
        pub weight_a: f32 = 1.0, range = -1e6..=1e6;
        /// factor on input b
        pub weight_b: f32 = 1.0, range = -1e6..=1e6;
    }
}

#[node(category = "image", outputs = [image])]
impl Combine {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        relume_core::MemoryEstimate { outputs: vec![inputs[0]], working: 0 }
    }

    fn run(&self, a: &Image, b: &Image, _cx: &RunCtx) -> Result<Image, NodeError> {
        a.check_same_size(b, "a", "b")?;
        let pixels =
            a.pixels.par_iter().zip(&b.pixels).map(|(x, y)| std::array::from_fn(|c| self.weight_a * x[c] + self.weight_b * y[c])).collect();
        Ok(Image { width: a.width, height: a.height, pixels })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{f, first, run_on};
    use relume_core::Value;

    #[test]
    fn weights_apply_and_sizes_must_agree() {
        let a = Image::from_fn(2, 2, |x, _| [x as f32; 3]);
        let b = Image::from_fn(2, 2, |_, _| [1.0; 3]);
        let out: Image =
            first(&run_on::<Combine>(&[("weight_a", f(2.0)), ("weight_b", f(-1.0))], vec![Value::new(a.clone()), Value::new(b)]).unwrap());
        assert_eq!(out.get(1, 0), [1.0; 3]);
        assert_eq!(out.get(0, 1), [-1.0; 3]);
        let small = Image::from_fn(1, 1, |_, _| [0.0; 3]);
        let err = run_on::<Combine>(&[], vec![Value::new(a), Value::new(small)]).unwrap_err();
        assert!(err.to_string().contains("1 × 1 but `a` is 2 × 2"), "{err}");
    }
}
