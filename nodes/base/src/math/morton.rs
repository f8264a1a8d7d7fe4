//! Morton (Z-order) codes: coordinates' bits interleaved, so points near each other in 2-D or
//! 3-D are mostly near each other in the code's order (the order photons and receivers are
//! processed in, for cache reuse).

/// The Morton code of a 2-D cell (16 bits an axis, x in the even bits).
pub fn morton2(x: usize, y: usize) -> u32 {
    let spread = |v: usize| {
        let mut v = (v as u32) & 0xffff;
        v = (v | (v << 8)) & 0x00ff_00ff;
        v = (v | (v << 4)) & 0x0f0f_0f0f;
        v = (v | (v << 2)) & 0x3333_3333;
        (v | (v << 1)) & 0x5555_5555
    };
    spread(x) | (spread(y) << 1)
}

/// The Morton code of a 3-D cell (10 bits an axis, x lowest).
pub fn morton3(c: [usize; 3]) -> u32 {
    let spread = |v: usize| {
        let mut x = (v as u32) & 0x3ff;
        x = (x | (x << 16)) & 0x0300_00ff;
        x = (x | (x << 8)) & 0x0300_f00f;
        x = (x | (x << 4)) & 0x030c_30c3;
        (x | (x << 2)) & 0x0924_9249
    };
    spread(c[0]) | (spread(c[1]) << 1) | (spread(c[2]) << 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit-by-bit interleaving, the definition.
    fn slow(c: &[usize], bits: u32) -> u32 {
        let mut out = 0u32;
        for b in 0..bits {
            for (axis, v) in c.iter().enumerate() {
                out |= (((v >> b) & 1) as u32) << (b as usize * c.len() + axis);
            }
        }
        out
    }

    #[test]
    fn the_codes_interleave_the_bits() {
        for (x, y) in [(0, 0), (1, 0), (0, 1), (3, 5), (255, 1), (65535, 65535), (12345, 54321)] {
            assert_eq!(morton2(x, y), slow(&[x, y], 16), "({x}, {y})");
        }
        for c in [[0, 0, 0], [1, 0, 0], [0, 0, 1], [7, 3, 5], [1023, 0, 512], [1023, 1023, 1023]] {
            assert_eq!(morton3(c), slow(&c, 10), "{c:?}");
        }
        // A 4 × 4 image in Z order: 2 × 2 blocks first.
        let order: Vec<u32> = (0..16).map(|i| morton2(i % 4, i / 4)).collect();
        assert_eq!(order, [0, 1, 4, 5, 2, 3, 6, 7, 8, 9, 12, 13, 10, 11, 14, 15]);
    }
}
