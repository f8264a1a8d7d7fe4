//! The memory model: what a node will hold while it runs, estimated before it runs, and the
//! budget a whole run must fit.
//!
//! A node states its estimate from its parameters and the sizes of its inputs
//! (`Node::memory`): the bytes of each output and the working memory it allocates besides
//! them. The executor adds up, in plan order, what is held at once — every result still
//! needed by a later node or asked for as an output, plus the running node's inputs,
//! outputs and working memory — and refuses, before running anything, a run whose estimate
//! exceeds the budget (statically, from parameters; again before each node with the actual
//! input sizes). `relume check` and `relume plan` report the same refusal.

/// The size of a value on a port, as far as it is known before it exists.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PortSize {
    pub bytes: u64,
    /// Pixel dimensions (an image's, or the camera resolution a scene asks for).
    pub dims: Option<[usize; 2]>,
}

impl PortSize {
    pub fn bytes(bytes: u64) -> Self {
        PortSize { bytes, dims: None }
    }
    /// An RGB f32 image of `w` × `h`.
    pub fn image(w: usize, h: usize) -> Self {
        PortSize { bytes: (w as u64) * (h as u64) * 12 + 16, dims: Some([w, h]) }
    }
    pub fn pixels(&self) -> Option<u64> {
        self.dims.map(|[w, h]| w as u64 * h as u64)
    }
}

/// A node's estimate: its outputs (declaration order; `None` where unknown) and the working
/// memory it allocates besides its inputs and outputs.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct MemoryEstimate {
    pub outputs: Vec<Option<PortSize>>,
    pub working: u64,
}

impl MemoryEstimate {
    /// Nothing known: the default for nodes that state no estimate.
    pub fn unknown(outputs: usize) -> Self {
        MemoryEstimate { outputs: vec![None; outputs], working: 0 }
    }
    pub fn output_bytes(&self) -> u64 {
        self.outputs.iter().flatten().map(|s| s.bytes).sum()
    }
}

/// Bytes in GiB/MiB for messages.
pub fn fmt_bytes(b: u64) -> String {
    let g = b as f64 / (1u64 << 30) as f64;
    if g >= 1.0 {
        format!("{g:.2} GiB")
    } else if b >= 1 << 20 {
        format!("{:.1} MiB", b as f64 / (1u64 << 20) as f64)
    } else if b >= 1 << 10 {
        format!("{:.1} KiB", b as f64 / 1024.0)
    } else {
        format!("{b} B")
    }
}

/// Parses `4G`, `512M`, `2GiB`, `1.5g` or a number of bytes (`--memory-budget`).
pub fn parse_bytes(s: &str) -> Option<u64> {
    let t = s.trim().to_ascii_lowercase();
    let t = t.trim_end_matches("ib").trim_end_matches('b');
    let (num, mul) = match t.chars().last()? {
        'k' => (&t[..t.len() - 1], 1u64 << 10),
        'm' => (&t[..t.len() - 1], 1 << 20),
        'g' => (&t[..t.len() - 1], 1 << 30),
        't' => (&t[..t.len() - 1], 1 << 40),
        _ => (t, 1),
    };
    let x: f64 = num.trim().parse().ok()?;
    (x.is_finite() && x >= 0.0).then_some((x * mul as f64) as u64)
}

/// Asks the kernel to back `v`'s allocation with 2 MiB pages where it can (no effect on what
/// any code computes; nothing off Linux, or below 4 MiB): for arrays of hundreds of MiB read
/// a few bytes at a time far apart (a vertex's visibility), where every read would
/// otherwise miss the address-translation cache. Only pages not yet touched change, so call
/// it before filling a new allocation.
pub fn huge_pages<T>(v: &Vec<T>) {
    let bytes = v.capacity() * std::mem::size_of::<T>();
    if bytes < 4 << 20 {
        return;
    }
    #[cfg(target_os = "linux")]
    {
        const PAGE: usize = 4096;
        let start = (v.as_ptr() as usize).next_multiple_of(PAGE);
        let end = (v.as_ptr() as usize + bytes) & !(PAGE - 1);
        // SAFETY: the range lies inside `v`'s allocation and is page-aligned; the advice
        // changes how the kernel backs the pages, never their contents (a refusal is ignored).
        unsafe {
            libc::madvise(start as *mut libc::c_void, end - start, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_and_print() {
        assert_eq!(parse_bytes("4G"), Some(4 << 30));
        assert_eq!(parse_bytes("512MiB"), Some(512 << 20));
        assert_eq!(parse_bytes("1.5g"), Some(3 << 29));
        assert_eq!(parse_bytes("1000"), Some(1000));
        assert_eq!(parse_bytes("lots"), None);
        assert_eq!(fmt_bytes(3 << 30), "3.00 GiB");
        assert_eq!(PortSize::image(2, 3).bytes, 2 * 3 * 12 + 16);
    }

    /// The advice changes how pages are backed, never what they hold: an array filled after
    /// it (and one it reaches after filling) reads back the same.
    #[test]
    fn large_pages_keep_an_arrays_contents() {
        let mut v: Vec<u32> = Vec::with_capacity(3 << 20);
        huge_pages(&v);
        v.extend((0..3u32 << 20).map(|k| k.wrapping_mul(2_654_435_761)));
        huge_pages(&v);
        assert!(v.iter().enumerate().all(|(k, &x)| x == (k as u32).wrapping_mul(2_654_435_761)));
        huge_pages(&Vec::<u8>::new());
    }
}
