use crate::types::Volume;
use relume_base::types::Image;
use relume_core::{node, params, NodeError, ParamEnum, RunCtx};

params! {
    /// A plane through a volume as an image, to look at a voxelised index, a painted weight or the
    /// stored radiance: the voxels of one slice across `axis` at `position` (0 … 1 across the box),
    /// channel `channel` in grey or, for a 3-channel volume with `channel` = −1, the three channels
    /// as RGB. Values are raw (an index of 1.5 shows as 1.5); tone-map or scale to view. The image
    /// is the slice's voxels, one pixel each, row 0 at the top (the largest coordinate of the
    /// slice's vertical axis: y for x and z slices, z for y slices).
    pub struct VolumeSlice {
        /// the axis the slice is across
        pub axis: Axis = Z;
        /// where across the box, 0 at its minimum, 1 at its maximum
        pub position: f32 = 0.5, range = 0.0..=1.0;
        /// the channel shown (−1: channels 0, 1, 2 as RGB)
        pub channel: i32 = 0, range = -1..=63;
    }
}

/// An axis of a volume.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ParamEnum)]
pub enum Axis {
    /// slices of constant x (image: z across, y up)
    X,
    /// slices of constant y (image: x across, z up)
    Y,
    /// slices of constant z (image: x across, y up)
    Z,
}

/// The slice of `v` (see the node's doc).
pub fn slice(v: &Volume, axis: Axis, position: f32, channel: i32) -> Result<Image, NodeError> {
    if channel >= v.channels as i32 || (channel < 0 && v.channels < 3) {
        return Err(NodeError::param("channel", format!("the volume has {} channel(s); channel {channel} is not one of them", v.channels)));
    }
    let d = v.dims.map(|x| x as usize);
    let (a, across, up) = match axis {
        Axis::X => (0, 2, 1),
        Axis::Y => (1, 0, 2),
        Axis::Z => (2, 0, 1),
    };
    let k = ((position * d[a] as f32) as usize).min(d[a] - 1);
    let (w, h) = (d[across], d[up]);
    let mut img = Image::try_new(w, h)?;
    for (p, out) in img.pixels.iter_mut().enumerate() {
        let mut at = [0usize; 3];
        (at[a], at[across], at[up]) = (k, p % w, h - 1 - p / w);
        let i = v.index(at[0], at[1], at[2]);
        *out = if channel < 0 { [v.data[i], v.data[i + 1], v.data[i + 2]] } else { [v.data[i + channel as usize]; 3] };
    }
    Ok(img)
}

#[node(category = "volume", outputs = [image])]
impl VolumeSlice {
    fn run(&self, volume: &Volume, _cx: &RunCtx) -> Result<Image, NodeError> {
        slice(volume, self.axis, self.position, self.channel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn slices_show_the_voxels_with_the_vertical_axis_up() {
        let mut v = Volume::try_new([4, 3, 2], 3, Vec3::ZERO, Vec3::ONE, 0.0, u64::MAX).unwrap();
        for z in 0..2 {
            for y in 0..3 {
                for x in 0..4 {
                    let i = v.index(x, y, z);
                    v.data[i..i + 3].copy_from_slice(&[x as f32, y as f32, z as f32]);
                }
            }
        }
        let s = slice(&v, Axis::Z, 0.9, -1).unwrap();
        assert_eq!((s.width, s.height), (4, 3));
        assert_eq!(s.pixels[0], [0.0, 2.0, 1.0], "top-left: x 0, y at the top, the last z");
        assert_eq!(s.pixels[11], [3.0, 0.0, 1.0]);
        let s = slice(&v, Axis::X, 0.0, 1).unwrap();
        assert_eq!((s.width, s.height), (2, 3));
        assert_eq!(s.pixels[0], [2.0; 3]);
        let s = slice(&v, Axis::Y, 0.5, 2).unwrap();
        assert_eq!((s.width, s.height), (4, 2));
        assert_eq!(s.pixels[0], [1.0; 3], "z up");
        assert!(slice(&v, Axis::Y, 0.5, 3).unwrap_err().to_string().contains("3 channel(s)"));
    }
}
