//! Combine node.

use crate::types::Image;
use rayon::prelude::*;
use relume_core::{node_doc, Caching, Io, Node, NodeError, ParamValues, Params, Ports, RunCtx, Schema};

node_doc! {
    /// Weighted sum of two images of the same size: out = weight_a · a + weight_b · b
    /// (direct + indirect lighting, or the difference of two renders with weight_b = −1).
    pub struct Combine;
}

pub struct CombineParams {
    pub weight_a: f32,
    pub weight_b: f32,
}

impl Params for CombineParams {
    fn schema() -> Schema {
        Schema::new()
            .float("weight_a", 1.0, -1e6, 1e6)
            .help("factor on input a")
            .float("weight_b", 1.0, -1e6, 1e6)
            .help("factor on input b")
    }
    fn from_values(v: &ParamValues) -> Self {
        CombineParams { weight_a: v.float("weight_a") as f32, weight_b: v.float("weight_b") as f32 }
    }
}

impl Node for Combine {
    const KIND: &'static str = "Combine";
    const VERSION: u32 = 1;
    const CATEGORY: &'static str = "image";
    const CACHING: Caching = Caching::Memory;
    type Params = CombineParams;

    fn ports() -> Ports {
        Ports::new().input::<Image>("a").input::<Image>("b").output::<Image>("image")
    }

    fn run(&self, p: &CombineParams, io: &mut Io, _cx: &RunCtx) -> Result<(), NodeError> {
        let (a, b) = (io.input::<Image>("a")?, io.input::<Image>("b")?);
        a.check_same_size(b, "a", "b")?;
        let pixels =
            a.pixels.par_iter().zip(&b.pixels).map(|(x, y)| std::array::from_fn(|c| p.weight_a * x[c] + p.weight_b * y[c])).collect();
        io.set("image", Image { width: a.width, height: a.height, pixels })
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
            first(&run_on(Combine, &[("weight_a", f(2.0)), ("weight_b", f(-1.0))], vec![Value::new(a.clone()), Value::new(b)]).unwrap());
        assert_eq!(out.get(1, 0), [1.0; 3]);
        assert_eq!(out.get(0, 1), [-1.0; 3]);
        let small = Image::from_fn(1, 1, |_, _| [0.0; 3]);
        let err = run_on(Combine, &[], vec![Value::new(a), Value::new(small)]).unwrap_err();
        assert!(err.to_string().contains("1 × 1 but `a` is 2 × 2"), "{err}");
    }
}
