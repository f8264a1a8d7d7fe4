//! Seeded, counter-based random numbers: the value for index i depends only on (seed, i), so
//! results are identical on any thread count.

/// SplitMix64 finaliser: a well-mixed 64-bit hash of `x`.
pub fn mix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Uniform in [0, 1) for stream `seed`, index `i`, dimension `dim`.
pub fn uniform(seed: u64, i: u64, dim: u32) -> f32 {
    uniform_in(stream(seed, i), dim)
}

/// The hashed stream of `seed` and index `i`, which `uniform_in` draws from: computed once
/// for all the dimensions of a sample. Each input passes through its own full mixing round, so
/// that ids differing only in their high bits (pixel << 32 | sample) give independent streams.
pub fn stream(seed: u64, i: u64) -> u64 {
    mix64(mix64(seed ^ 0xA076_1D64_78BD_642F) ^ i)
}

/// Uniform in [0, 1) for dimension `dim` of a `stream`: `uniform(seed, i, dim)` is
/// `uniform_in(stream(seed, i), dim)`.
pub fn uniform_in(stream: u64, dim: u32) -> f32 {
    let h = mix64(stream ^ (dim as u64).wrapping_mul(0x2545_F491_4F6C_DD1D));
    (h >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_is_in_range_and_roughly_uniform() {
        let n = 100_000;
        let mut mean = 0.0f64;
        for i in 0..n {
            let u = uniform(7, i, 0);
            assert!((0.0..1.0).contains(&u));
            mean += u as f64;
        }
        mean /= n as f64;
        assert!((mean - 0.5).abs() < 0.005, "mean {mean}");
        assert_ne!(uniform(7, 1, 0), uniform(8, 1, 0));
        assert_ne!(uniform(7, 1, 0), uniform(7, 1, 1));
        assert_eq!(uniform(7, 3, 5), uniform_in(stream(7, 3), 5));
    }
}
