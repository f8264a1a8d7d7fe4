use crate::types::Image;
use rayon::prelude::*;
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

params! {
    /// Maps linear HDR radiance to display-referred values in [0, 1]: exposure in stops, then
    /// a curve (Clamp, Reinhard x/(1+x), or the ACES filmic fit of Narkowicz 2015). The output
    /// stays linear; PNG writing applies the sRGB encoding. NaN becomes 0 and +∞ becomes 1,
    /// so a broken pixel shows instead of poisoning the picture.
    pub struct Tonemap {
        /// scale by 2^exposure before the curve
        pub exposure: f32 = 0.0, range = -20.0..=20.0, unit = "stops";
        /// tone curve
        pub operator: Operator = Aces;
    }
}

#[derive(Clone, Copy, Debug, PartialEq, ParamEnum)]
pub enum Operator {
    Clamp,
    Reinhard,
    Aces,
}

/// One channel through exposure scale and curve; always finite, in [0, 1].
pub fn tonemap_channel(x: f32, scale: f32, op: Operator) -> f32 {
    if x.is_nan() {
        return 0.0;
    }
    let x = (x * scale).max(0.0);
    let y = match op {
        Operator::Clamp => x,
        Operator::Reinhard => {
            if x.is_infinite() {
                1.0
            } else {
                x / (1.0 + x)
            }
        }
        Operator::Aces => {
            if x.is_infinite() {
                1.0
            } else {
                let (a, b, c, d, e) = (2.51, 0.03, 2.43, 0.59, 0.14);
                (x * (a * x + b)) / (x * (c * x + d) + e)
            }
        }
    };
    if y.is_nan() {
        1.0
    } else {
        y.clamp(0.0, 1.0)
    }
}

#[node(category = "image", outputs = [image])]
impl Tonemap {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        relume_core::MemoryEstimate { outputs: vec![inputs[0]], working: 0 }
    }

    fn run(&self, image: &Image, _cx: &RunCtx) -> Result<Image, NodeError> {
        let scale = 2f32.powf(self.exposure);
        let pixels = image.pixels.par_iter().map(|c| c.map(|x| tonemap_channel(x, scale, self.operator))).collect();
        Ok(Image { width: image.width, height: image.height, pixels })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{f, first, id, run_on};
    use relume_core::Value;

    #[test]
    fn curves_are_monotone_and_bounded() {
        for op in [Operator::Clamp, Operator::Reinhard, Operator::Aces] {
            let mut last = -1.0;
            for i in 0..1000 {
                let y = tonemap_channel(i as f32 * 0.05, 1.0, op);
                assert!((0.0..=1.0).contains(&y) && y >= last, "{op:?} at {i}: {y}");
                last = y;
            }
        }
        assert_eq!(tonemap_channel(0.25, 4.0, Operator::Clamp), 1.0);
    }

    #[test]
    fn extreme_values_give_finite_output() {
        let img = Image::from_fn(4, 1, |x, _| [[f32::NAN, f32::INFINITY, -5.0, 1e30][x]; 3]);
        for op in Operator::VARIANTS {
            let out: Image =
                first(&run_on::<Tonemap>(&[("operator", id(op)), ("exposure", f(20.0))], vec![Value::new(img.clone())]).unwrap());
            assert!(out.as_floats().iter().all(|x| x.is_finite() && (0.0..=1.0).contains(x)), "{op}: {:?}", out.pixels);
            assert_eq!(out.pixels[0], [0.0; 3]);
            assert_eq!(out.pixels[1], [1.0; 3]);
        }
    }
}
