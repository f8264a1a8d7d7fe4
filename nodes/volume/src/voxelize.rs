use super::blur::{blur, kernel, put_channels};
use super::scanline::{add_coverage_where, Projected};
use crate::types::Volume;
use glam::{UVec3, Vec3};
use relume_base::geometry::closed_mesh::{enclosed_volume, open_edges};
use relume_base::types::{Material, Scene};
use relume_core::{node, params, NodeError, RunCtx};

params! {
    /// A closed mesh object as a refractive medium ([S] 6.3.1): the inside fraction f of every
    /// voxel of a grid fitted around the object (cubic voxels, `resolution` along its longest
    /// side, `padding` of that side added around so the blur has room), mapped to the refractive
    /// index n = 1 + (index − 1) f, the extinction κ = (σ_a + σ_s) f and the scattering σ = σ_s f
    /// (channels 0, 1, 2), then Gaussian-blurred (`blur_radius` 3: 7³, 4: 9³). Fractions come from
    /// scanlines along x (exact along x): first one line through each voxel row's centre, then,
    /// for boundary voxels (3³ neighbourhood not uniform, or holding a mesh vertex, so a mesh
    /// smaller than a voxel is never missed), `supersample`² lines per voxel row; a mesh all lines
    /// miss puts its exact volume (divergence theorem) into the voxel at its centre. The report
    /// gives the voxelised volume against the mesh's (`volume_error_pct`). Inside is
    /// decided by parity, which needs a closed mesh: an object with edges not shared by exactly two
    /// faces is an error naming it. Index 0 takes the object's dielectric index; negative σ take
    /// the object's medium (grey: the mean over RGB). Rows in parallel, the same bytes on any
    /// thread count; the grid's bytes are checked against the budget before allocating.
    pub struct Voxelize {
        /// the scene object to voxelize (a closed mesh)
        pub object: String = "glass";
        /// voxels along the object's longest side
        pub resolution: u32 = 128, range = 1..=1024, unit = "voxels", test = 32;
        /// margin around the object, as a fraction of its longest side
        pub padding: f32 = 0.1, range = 0.0..=2.0;
        /// refractive index inside (0: the object's dielectric index)
        pub index: f32 = 0.0, range = 0.0..=10.0;
        /// absorption σ_a inside, per unit length (negative: the object's medium)
        pub absorption: f32 = -1.0, range = -1.0..=1e6, unit = "1/unit";
        /// scattering σ_s inside, per unit length (negative: the object's medium)
        pub scattering: f32 = -1.0, range = -1.0..=1e6, unit = "1/unit";
        /// radius of the Gaussian blur (3: 7³, 4: 9³; 0: none)
        pub blur_radius: u32 = 3, range = 0..=8, unit = "voxels";
        /// standard deviation of the Gaussian blur
        pub blur_sigma: f32 = 1.0, range = 0.0..=8.0, unit = "voxels";
        /// lines per side of a boundary voxel row (4: 16 lines)
        pub supersample: u32 = 4, range = 1..=16;
    }
}

/// The grid fitted around `lo … hi`: its box and dimensions.
pub fn fit_grid(lo: Vec3, hi: Vec3, resolution: u32, padding: f32) -> (Vec3, Vec3, [u32; 3]) {
    let side = (hi - lo).max_element().max(f32::MIN_POSITIVE);
    let h = side * (1.0 + 2.0 * padding) / resolution as f32;
    let centre = (lo + hi) / 2.0;
    let dims = ((hi - lo + 2.0 * padding * side) / h).ceil().max(Vec3::ONE).as_uvec3().min(UVec3::splat(resolution.max(1) * 3));
    let half = dims.as_vec3() * h / 2.0;
    (centre - half, centre + half, dims.to_array())
}

/// The inside fraction of every voxel of a `dims` grid over `min + h · …` (see the node's doc).
fn fractions(tris: &[[Vec3; 3]], min: Vec3, h: f32, dims: [usize; 3], ss: usize, cx: &RunCtx) -> Result<Vec<f32>, NodeError> {
    let proj: Vec<Projected> = tris.iter().filter_map(Projected::new).collect();
    let (ny, nz) = (dims[1], dims[2]);
    // The triangles whose (y, z) bounds reach each voxel row.
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); ny * nz];
    let cell = |v: f64, o: f32, n: usize| (((v - o as f64) / h as f64).floor().max(0.0) as usize).min(n - 1);
    for (i, t) in proj.iter().enumerate() {
        let ([y0, y1], [z0, z1]) = t.yz_bounds();
        for z in cell(z0, min.z, nz)..=cell(z1, min.z, nz) {
            for y in cell(y0, min.y, ny)..=cell(y1, min.y, ny) {
                bins[z * ny + y].push(i as u32);
            }
        }
    }
    // The coverage of row (y, z) by the lines at `offsets`, of the voxels `only` where given.
    let row = |y: usize, z: usize, offsets: &[(f64, f64)], only: Option<&[usize]>| -> Vec<f64> {
        let mut cover = vec![0.0f64; dims[0]];
        let mut xs = Vec::new();
        for &(oy, oz) in offsets {
            let (py, pz) = (min.y as f64 + (y as f64 + oy) * h as f64, min.z as f64 + (z as f64 + oz) * h as f64);
            xs.clear();
            xs.extend(bins[z * ny + y].iter().filter_map(|&i| proj[i as usize].crossing(py, pz)));
            add_coverage_where(&mut xs, min.x as f64, h as f64, 1.0 / offsets.len() as f64, only, &mut cover);
        }
        cover
    };
    // Pass 1: one line through each row's centre.
    let centre = [(0.5, 0.5)];
    cx.phase(0.0, 0.5);
    let rows = cx.par_map(ny * nz, |r| row(r % ny, r / ny, &centre, None))?;
    let mut f: Vec<f32> = rows.into_iter().flatten().map(|v| v.clamp(0.0, 1.0) as f32).collect();
    // Boundary voxels: a 3³ neighbourhood that is not uniform, or a mesh vertex inside.
    let idx = |x: usize, y: usize, z: usize| (z * ny + y) * dims[0] + x;
    let mut boundary = vec![false; f.len()];
    for t in tris {
        for v in t {
            let g = ((*v - min) / h).floor();
            if g.cmpge(Vec3::ZERO).all() && (g.x as usize) < dims[0] && (g.y as usize) < ny && (g.z as usize) < nz {
                boundary[idx(g.x as usize, g.y as usize, g.z as usize)] = true;
            }
        }
    }
    let mixed = mixed_voxels(&f, dims);
    boundary.iter_mut().zip(&mixed).for_each(|(b, m)| *b |= m);
    // Pass 2: `ss`² lines through each row holding a boundary voxel, summed at those voxels
    // only (the rest keep pass 1's value).
    let offsets: Vec<(f64, f64)> =
        (0..ss * ss).map(|k| (((k % ss) as f64 + 0.5) / ss as f64, ((k / ss) as f64 + 0.5) / ss as f64)).collect();
    cx.phase(0.5, 1.0);
    let fine = cx.par_map(ny * nz, |r| {
        let (y, z) = (r % ny, r / ny);
        let only: Vec<usize> = (0..dims[0]).filter(|&x| boundary[idx(x, y, z)]).collect();
        (!only.is_empty()).then(|| row(y, z, &offsets, Some(&only)))
    })?;
    for (r, cover) in fine.into_iter().enumerate() {
        if let Some(cover) = cover {
            let (y, z) = (r % ny, r / ny);
            for (x, c) in cover.iter().enumerate() {
                if boundary[idx(x, y, z)] {
                    f[idx(x, y, z)] = c.clamp(0.0, 1.0) as f32;
                }
            }
        }
    }
    Ok(f)
}

/// Per voxel of the `dims` grid `f` (x fastest), whether it is mixed: a fraction strictly
/// between 0 and 1, or a 3³ neighbourhood (clipped to the grid) holding another value than its
/// own. Each voxel as a class (0 and 1 themselves, 2 between), so a neighbourhood differs when
/// its least and largest class do: those found by a pass of three along x, then y, then z,
/// slices in parallel, on bytes.
fn mixed_voxels(f: &[f32], dims: [usize; 3]) -> Vec<bool> {
    use rayon::prelude::*;
    let [nx, ny, nz] = dims;
    let slice = nx * ny;
    let class: Vec<u8> = f
        .par_iter()
        .map(|&v| {
            if v == 0.0 {
                0
            } else if v == 1.0 {
                1
            } else {
                2
            }
        })
        .collect();
    // One row or slice from its own and its neighbours' along an axis of `n` positions
    // (`at(q)` the row or slice at q), the least and the largest together.
    fn three<'a>(out: (&mut [u8], &mut [u8]), p: usize, n: usize, at: impl Fn(usize) -> (&'a [u8], &'a [u8])) {
        let ((lo, hi), (b_lo, b_hi), (a_lo, a_hi)) = (at(p), at(p.saturating_sub(1)), at((p + 1).min(n - 1)));
        for (((o, &v), &b), &a) in out.0.iter_mut().zip(lo).zip(b_lo).zip(a_lo) {
            *o = v.min(b).min(a);
        }
        for (((o, &v), &b), &a) in out.1.iter_mut().zip(hi).zip(b_hi).zip(a_hi) {
            *o = v.max(b).max(a);
        }
    }
    let (mut lo, mut hi) = (vec![0u8; f.len()], vec![0u8; f.len()]);
    lo.par_chunks_mut(nx).zip(hi.par_chunks_mut(nx)).zip(class.par_chunks(nx)).for_each(|((lo, hi), c)| {
        for i in 0..nx {
            let (b, a) = (c[i.saturating_sub(1)], c[(i + 1).min(nx - 1)]);
            (lo[i], hi[i]) = (c[i].min(b).min(a), c[i].max(b).max(a));
        }
    });
    let (mut lo2, mut hi2) = (vec![0u8; f.len()], vec![0u8; f.len()]);
    lo2.par_chunks_mut(slice).zip(hi2.par_chunks_mut(slice)).enumerate().for_each(|(z, (l, h))| {
        let (sl, sh) = (&lo[z * slice..(z + 1) * slice], &hi[z * slice..(z + 1) * slice]);
        for (r, (l, h)) in l.chunks_exact_mut(nx).zip(h.chunks_exact_mut(nx)).enumerate() {
            three((l, h), r, ny, |q| (&sl[q * nx..(q + 1) * nx], &sh[q * nx..(q + 1) * nx]));
        }
    });
    lo.par_chunks_mut(slice).zip(hi.par_chunks_mut(slice)).enumerate().for_each(|(z, (l, h))| {
        three((l, h), z, nz, |q| (&lo2[q * slice..(q + 1) * slice], &hi2[q * slice..(q + 1) * slice]));
    });
    class.par_iter().zip(&lo).zip(&hi).map(|((&c, &l), &h)| c == 2 || l != h).collect()
}

#[node(category = "volume", metrics = ["voxels", "inside_volume", "volume_error_pct", "index"], outputs = [medium])]
impl Voxelize {
    fn memory(&self, inputs: &[Option<relume_core::PortSize>]) -> relume_core::MemoryEstimate {
        // At most resolution · (1 + 2 padding)-ish voxels a side, 3 channels, and the blur's copy.
        let _ = inputs;
        let side = self.resolution as u64 + 1;
        let bytes = side * side * side * 12;
        relume_core::MemoryEstimate { outputs: vec![Some(relume_core::PortSize::bytes(bytes))], working: 2 * bytes }
    }

    fn run(&self, scene: &Scene, cx: &RunCtx) -> Result<Volume, NodeError> {
        let s = scene;
        let names: Vec<&str> = s.objects.iter().map(|o| o.name.as_str()).collect();
        let o = s.objects.iter().find(|o| o.name == self.object).ok_or_else(|| {
            NodeError::param("object", format!("no object \"{}\" in the scene (objects: {})", self.object, names.join(", ")))
        })?;
        let tris: Vec<[Vec3; 3]> = (o.triangles.start as usize..o.triangles.end as usize).map(|t| s.corners(t)).collect();
        if tris.is_empty() {
            return Err(NodeError::input("scene", format!("object \"{}\" has no triangles", o.name)));
        }
        let (lo, hi) = tris.iter().flatten().fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), p| (a.min(*p), b.max(*p)));
        let open = open_edges(&tris, 1e-6 * (hi - lo).max_element().max(f32::MIN_POSITIVE));
        if open > 0 {
            return Err(NodeError::input(
                "scene",
                format!("object \"{}\" is not a closed mesh ({open} edges are not shared by exactly two faces): inside and outside are undefined", o.name),
            ));
        }
        let (index, medium) = match o.material {
            Material::Dielectric { ior, medium } => (ior, medium),
            _ => (1.0, None),
        };
        let index = if self.index > 0.0 { self.index } else { index };
        let grey = |v: Vec3| (v.x + v.y + v.z) / 3.0;
        let sa = if self.absorption >= 0.0 { self.absorption } else { medium.map_or(0.0, |m| grey(m.sigma_a)) };
        let ss = if self.scattering >= 0.0 { self.scattering } else { medium.map_or(0.0, |m| grey(m.sigma_s)) };
        let (min, max, dims) = fit_grid(lo, hi, self.resolution, self.padding);
        // The medium's three channels, refused over the budget before anything is computed.
        let full = Volume::try_new(dims, 3, min, max, 0.0, cx.memory_budget())?;
        // Without absorption or scattering κ and σ are +0 everywhere, before the blur and
        // after it: the index is computed and blurred as a volume of its own and put in place
        // (the same bytes as blurring all three, in a third of the work).
        let index_only = sa.to_bits() == 0 && ss.to_bits() == 0;
        let (mut vol, out) =
            if index_only { (Volume::try_new(dims, 1, min, max, 0.0, cx.memory_budget())?, Some(full)) } else { (full, None) };
        let h = vol.voxel().x;
        let mut f = fractions(&tris, min, h, dims.map(|d| d as usize), self.supersample as usize, cx)?;
        // A mesh every line missed (smaller than the lines' spacing) still has its volume: all
        // of it in the voxel holding its centre.
        let exact = enclosed_volume(&tris);
        if f.iter().all(|v| *v == 0.0) && exact > 0.0 {
            let g = (((lo + hi) / 2.0 - min) / h).floor().as_uvec3().min(UVec3::from(dims) - 1);
            let k = vol.index(g.x as usize, g.y as usize, g.z as usize) / vol.channels as usize;
            f[k] = (exact / (h as f64).powi(3)).min(1.0) as f32;
            cx.note(format!("object \"{}\" is smaller than the lines through its voxel: its volume goes to one voxel", o.name));
        }
        if index_only {
            vol.data.iter_mut().zip(&f).for_each(|(v, f)| *v = 1.0 + (index - 1.0) * f);
        } else {
            for (v, f) in vol.data.chunks_exact_mut(3).zip(&f) {
                v.copy_from_slice(&[1.0 + (index - 1.0) * f, (sa + ss) * f, ss * f]);
            }
        }
        let inside: f64 = f.iter().map(|v| *v as f64).sum::<f64>() * (h as f64).powi(3);
        let vol = blur(&vol, &kernel(self.blur_radius as usize, self.blur_sigma), cx)?;
        let vol = match out {
            Some(mut out) => {
                put_channels(&vol, &[0], &mut out.data, 3);
                out
            }
            None => vol,
        };
        cx.metric("voxels", vol.voxels() as f64);
        cx.metric("inside_volume", inside);
        cx.metric("volume_error_pct", if exact > 0.0 { 100.0 * (inside - exact) / exact } else { 0.0 });
        cx.metric("index", index as f64);
        Ok(vol)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_base::scene::builder::SceneBuilder;
    use relume_base::testing::{f, first, i, run_full, run_on, t};
    use relume_core::Value;
    use std::f64::consts::PI;

    fn glass(radius: f32, ior: f32) -> Scene {
        SceneBuilder::new(Vec3::new(0.0, 1.6, 2.6), Vec3::ZERO, 40.0, 8, 8)
            .sphere("glass", Vec3::new(0.0, 0.6, 0.0), radius, Material::Dielectric { ior, medium: None }, Vec3::ZERO, false)
            .quad(
                "floor",
                Vec3::new(-2.0, 0.0, 2.0),
                Vec3::new(4.0, 0.0, 0.0),
                Vec3::new(0.0, 0.0, -4.0),
                Material::Lambert { albedo: Vec3::splat(0.8) },
                Vec3::ZERO,
            )
            .build()
    }

    #[test]
    fn a_sphere_gives_its_volume_and_index_one_inside_and_one_outside() {
        let p = [("resolution", i(32)), ("blur_radius", i(0))];
        let e = run_full::<Voxelize>(&p, std::path::Path::new("."), vec![Value::new(glass(0.5, 1.5))]).unwrap();
        let v = e.outputs[0].get::<Volume>().unwrap();
        let inside = e.metrics.iter().find(|m| m.0 == "inside_volume").unwrap().1;
        // The tessellated sphere (48 × 96) is a little smaller than 4/3 π r³.
        let want = 4.0 / 3.0 * PI * 0.125;
        assert!((inside - want).abs() < 0.01 * want, "{inside} vs {want}");
        assert_eq!(v.channels, 3);
        assert_eq!(v.dims, [32, 32, 32]);
        let err = e.metrics.iter().find(|m| m.0 == "volume_error_pct").unwrap().1;
        assert!(err.abs() < 0.5, "voxelised against the mesh's own volume: {err} %");
        assert!((v.sample(Vec3::new(0.0, 0.6, 0.0), 0) - 1.5).abs() < 1e-6);
        assert_eq!(v.sample(Vec3::new(0.55, 0.1, 0.55), 0), 1.0);
        assert!(v.data.iter().all(|x| x.is_finite()));
        assert!(v.data.chunks(3).all(|c| c[1] == 0.0 && c[2] == 0.0), "no medium: κ = σ = 0");
    }

    #[test]
    fn the_blur_keeps_index_one_far_outside_and_the_centre_and_smooths_the_interface() {
        let v: Volume = first(&run_on::<Voxelize>(&[("resolution", i(24))], vec![Value::new(glass(0.5, 2.4))]).unwrap());
        assert!((v.sample(Vec3::new(0.0, 0.6, 0.0), 0) - 2.4).abs() < 1e-5);
        assert!((v.sample(v.min + 0.01, 0) - 1.0).abs() < 1e-6);
        let edge = v.sample(Vec3::new(0.5, 0.6, 0.0), 0);
        assert!(edge > 1.2 && edge < 2.2, "{edge}");
    }

    #[test]
    fn a_mesh_smaller_than_a_voxel_still_shows_and_media_fill_kappa_and_sigma() {
        let p = [("resolution", i(1)), ("padding", f(1.0)), ("blur_radius", i(0)), ("absorption", f(2.0)), ("scattering", f(3.0))];
        let v: Volume = first(&run_on::<Voxelize>(&p, vec![Value::new(glass(0.01, 1.33))]).unwrap());
        assert_eq!(v.dims, [1, 1, 1], "one voxel, three times the sphere's diameter");
        let c = v.index(0, 0, 0);
        let frac = (v.data[c] - 1.0) / 0.33;
        assert!(frac > 0.005 && frac < 0.05, "{frac}");
        assert!((v.data[c + 1] - 5.0 * frac).abs() < 1e-4 && (v.data[c + 2] - 3.0 * frac).abs() < 1e-4);
    }

    #[test]
    fn an_open_mesh_or_an_unknown_object_is_a_clear_error() {
        let e = run_on::<Voxelize>(&[("object", t("floor"))], vec![Value::new(glass(0.5, 1.5))]).unwrap_err().to_string();
        assert!(e.contains("\"floor\" is not a closed mesh"), "{e}");
        let e = run_on::<Voxelize>(&[("object", t("teapot"))], vec![Value::new(glass(0.5, 1.5))]).unwrap_err().to_string();
        assert!(e.contains("no object \"teapot\"") && e.contains("glass, floor"), "{e}");
    }

    #[test]
    fn the_same_bytes_on_any_thread_count() {
        let run = || first::<Volume>(&run_on::<Voxelize>(&[("resolution", i(20))], vec![Value::new(glass(0.5, 1.5))]).unwrap());
        let on = |n| rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap().install(run);
        assert_eq!(on(1), on(3));
    }
}
