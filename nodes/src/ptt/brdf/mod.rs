//! The BRDF side of pipeline 2 ([S] 5.2.2, 5.3.1, 5.3.3.1): `BrdfTensor` samples a BRDF
//! family's specular part into F(h, ωo, ωi) over the disk-projected hemisphere,
//! `SpecularSeparation` splits F into Gaussian lobes around the mirror direction plus a
//! low-frequency residual, and `TuckerDecompose` factors a tensor (F or the residual) into
//! the core and the h, ωo, ωi factors a renderer shades with. Port types in `types`.

pub mod brdf_tensor;
pub mod types;

use relume_core::Registry;

/// Registers the BRDF-tensor nodes.
pub fn register(reg: &mut Registry) {
    reg.add::<brdf_tensor::BrdfTensor>();
}

/// Tensors, separations and decompositions made by the nodes themselves, for this folder's
/// unit tests.
#[cfg(test)]
pub(crate) mod test_support {
    use super::types::BrdfTensorTable;
    use crate::testing::{first, run_on};
    use relume_core::ParamValue;

    /// `BrdfTensor` with the given parameters.
    pub fn tensor(p: &[(&str, ParamValue)]) -> BrdfTensorTable {
        first(&run_on::<super::brdf_tensor::BrdfTensor>(p, vec![]).unwrap())
    }
}
