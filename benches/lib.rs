//! Graphs generated for the benchmarks, and the benchmarks' access to `graphs/`.
//!
//! The generated graph is layers of real image nodes, every one of them needed:
//!
//! ```
//! use relume_benches::{generated_graph, WIDTH};
//!
//! let g = generated_graph(200);
//! assert_eq!(g.nodes.len(), 200);
//! assert_eq!(g.outputs.len(), WIDTH, "the last layer is the outputs");
//! g.validate(&relume_cli::registry()).unwrap();
//! ```

use relume_core::Graph;

/// Nodes per layer of the generated graph.
pub const WIDTH: usize = 10;

/// A layered graph of `n` (a multiple of `WIDTH`) real image nodes on 16 × 16 images:
/// layer 0 holds TestPattern sources; node j of layer l is, by (l + j) mod 4, a GaussianBlur,
/// MedianFilter, Combine or Tonemap reading node j of layer l − 1 (and, for Combine, node
/// j + 1 mod WIDTH too). Every node is needed; the last layer is the outputs.
pub fn generated_graph(n: usize) -> Graph {
    assert!(n.is_multiple_of(WIDTH) && n >= 2 * WIDTH);
    let id = |l: usize, j: usize| format!("n{l}_{j}");
    let mut nodes = String::new();
    let mut edges = String::new();
    for l in 0..n / WIDTH {
        for j in 0..WIDTH {
            let (kind, params) = if l == 0 {
                ("TestPattern", format!("width: 16, height: 16, pattern: Checker, cell: 4, noise: 0.1, seed: {j}"))
            } else {
                match (l + j) % 4 {
                    0 => ("GaussianBlur", format!("sigma: {}", 0.5 + (j % 3) as f64 * 0.25)),
                    1 => ("MedianFilter", "radius: 1".to_string()),
                    2 => ("Combine", "weight_a: 0.5, weight_b: 0.5".to_string()),
                    _ => ("Tonemap", "exposure: 0.25".to_string()),
                }
            };
            nodes += &format!("\"{}\": (kind: \"{kind}\", params: ({params})),\n", id(l, j));
            if l > 0 {
                let first = if kind == "Combine" { "a" } else { "image" };
                edges += &format!("(\"{}.image\", \"{}.{first}\"),\n", id(l - 1, j), id(l, j));
                if kind == "Combine" {
                    edges += &format!("(\"{}.image\", \"{}.b\"),\n", id(l - 1, (j + 1) % WIDTH), id(l, j));
                }
            }
        }
    }
    let last = n / WIDTH - 1;
    let outputs: String = (0..WIDTH).map(|j| format!("\"o{j}\": \"{}.image\",", id(last, j))).collect();
    let text = format!("Graph(version: 1, nodes: {{ {nodes} }}, edges: [ {edges} ], outputs: {{ {outputs} }})");
    Graph::parse(&text, None).expect("generated graph parses")
}

/// The text of `generated_graph(n)`, for benchmarks of loading itself.
pub fn generated_graph_text(n: usize) -> String {
    generated_graph(n).to_ron()
}

/// The node whose parameter the "after one edit" benchmark changes: a GaussianBlur about two
/// thirds of the way down.
pub fn edit_node(n: usize) -> String {
    let l = 2 * n / WIDTH / 3;
    let j = (4 - l % 4) % 4;
    format!("n{l}_{j}")
}

/// The repository's `graphs/` folder.
pub fn graphs_dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../graphs")
}

/// A graph file, the parameter its representative edit changes (`node.param`), and the value
/// text of the k-th edit.
pub type GraphEdit = (&'static str, &'static str, fn(u64) -> String);

/// Every pipeline graph in `graphs/` with its representative edit: the parameter a user
/// drags and the value of the k-th edit (new every time, so never cached).
pub fn graph_edits() -> Vec<GraphEdit> {
    vec![
        ("filters.ron", "blur.sigma", |k| format!("{}", 0.8 + k as f64 * 1e-6)),
        ("brdf_basis.ron", "project.s", |k| format!("{}", 5.0 + k as f64 * 1e-6)),
        ("relight_cornell_bunny.ron", "project.kd", |k| format!("({}, 0.2, 0.2)", 0.2 + k as f64 * 1e-6)),
        ("relight_cornell_spot.ron", "project.kd", |k| format!("({}, 0.7, 0.7)", 0.7 - k as f64 * 1e-6)),
        ("relight_ring.ron", "project.kd", |k| format!("({}, 0.2, 0.2)", 0.2 + k as f64 * 1e-6)),
        ("relight_basis_ring.ron", "project_plane.s", |k| format!("{}", 5.0 + k as f64 * 1e-6)),
        ("relight_basis_cornell_bunny.ron", "project_bunny.s", |k| format!("{}", 180.0 - k as f64 * 1e-6)),
        ("relight_vs_reference.ron", "transfer.spp", |k| format!("{}", 16 + k)),
        ("relight_sv_vs_reference.ron", "transfer.spp", |k| format!("{}", 16 + k)),
        ("voxelize_glass.ron", "voxelize.index", |k| format!("{}", 1.5 + k as f64 * 1e-6)),
        ("refract_glass.ron", "light.translation", |k| format!("({}, 0, 0)", k as f64 * 1e-6)),
        ("refract_glass_medium.ron", "light.translation", |k| format!("({}, 0, 0)", k as f64 * 1e-6)),
        ("refract_grin.ron", "source.index", |k| format!("{}", 1.5 + k as f64 * 1e-6)),
        ("refract_paint.ron", "paint.weight", |k| format!("{}", 0.4 + k as f64 * 1e-6)),
        ("refract_deform.ron", "deform.amount", |k| format!("{}", 40.0 + k as f64 * 1e-6)),
        ("refract_spot.ron", "light.translation", |k| format!("({}, 0, 0)", k as f64 * 1e-6)),
        ("relight_sv_spot.ron", "project.kd", |k| format!("({}, 0.7, 0.7)", 0.7 + k as f64 * 1e-6)),
        ("image_error.ron", "error_denoised.epsilon", |k| format!("{}", 0.01 + k as f64 * 1e-9)),
        ("reference_cornell.ron", "reference.seed", |k| format!("{}", 1000 + k)),
        ("bidir_glass.ron", "bidir.seed", |k| format!("{}", 1000 + k)),
        ("pbgi_cornell.ron", "move.translation", |k| format!("({}, 0, 0)", k as f64 * 1e-6)),
        ("fpbgi_cornell.ron", "move.translation", |k| format!("({}, 0, 0)", k as f64 * 1e-6)),
        ("pbgi_vs_reference.ron", "fpbgi.epsilon", |k| format!("{}", 1.0 + k as f64 * 1e-6)),
        ("ptt_precompute.ron", "turn.rotation_deg", |k| format!("{}", 30.0 + k as f64 * 1e-6)),
        ("ptt_envlit.ron", "camera.azimuth", |k| format!("{}", 10.0 + k as f64 * 1e-6)),
        ("ptt_envlit_ct.ron", "project.m", |k| format!("{}", 0.3 + k as f64 * 1e-6)),
        ("ptt_envlit_ct_bounce.ron", "project.m", |k| format!("{}", 0.3 + k as f64 * 1e-6)),
        ("ptt_envlit_pair.ron", "teapot.s", |k| format!("{}", 80.0 + k as f64 * 1e-6)),
        ("ptt_vs_reference.ron", "camera.azimuth", |k| format!("{}", 10.0 + k as f64 * 1e-6)),
        ("wpbgi_ring.ron", "coded.threshold", |k| format!("{}", 0.002 + k as f64 * 1e-9)),
        ("wpbgi_cornell_bunny.ron", "coded.threshold", |k| format!("{}", 0.002 + k as f64 * 1e-9)),
        ("vpbgi_cornell.ron", "views.view_threshold", |k| format!("{}", 0.08 + k as f64 * 1e-6)),
        ("vpbgi_glass.ron", "views.view_threshold", |k| format!("{}", 0.08 + k as f64 * 1e-6)),
    ]
}

/// Whether divan runs each bench once, only to check that it runs: `cargo test` (the README's
/// test command) and `cargo bench -- --test`; `cargo bench` passes `--bench` alone. Benches
/// then take their graphs and scenes at test size, so that the check costs seconds.
pub fn test_mode() -> bool {
    let args: Vec<String> = std::env::args().collect();
    args.iter().any(|a| a == "--test") || !args.iter().any(|a| a == "--bench")
}

/// `full` in a bench run, `small` in test mode (a resolution, a sample count).
pub fn sized<T>(full: T, small: T) -> T {
    if test_mode() {
        small
    } else {
        full
    }
}

/// Loads a graph of `graphs/` at bench size: the converged references (4096 samples per
/// pixel) come down to 64, so that a cold run takes seconds, not minutes; everything else is
/// as the file says. In test mode, the whole graph at test size.
pub fn bench_graph(name: &str) -> Graph {
    let reg = relume_cli::registry();
    let mut g = Graph::load(&graphs_dir().join(name), &reg).expect("graph loads");
    if test_mode() {
        g.shrink_to_test_size(&reg).expect("graph shrinks");
        return g;
    }
    for n in g.nodes.clone() {
        if n.kind == "PathTrace" && n.param("spp").is_some_and(|v| v.to_text().parse::<i64>().is_ok_and(|spp| spp > 64)) {
            g.set_param_text(&reg, &format!("{}.spp", n.id), "64").unwrap();
        }
    }
    g
}

/// Adds a graph output `name` for port `node.port` (to read an intermediate result).
pub fn add_output(g: &mut Graph, name: &str, port: &str) {
    let port = relume_core::graph::PortRef::parse(port).expect("node.port");
    g.outputs.push(relume_core::graph::Output { name: name.into(), port, pos: Default::default() });
}

/// Runs one registered node kind by name with its default parameters on `inputs` in
/// declared order: a kernel benchmark through the node's own interface.
pub fn run_kind(kind: &str, inputs: &[relume_core::Value]) -> Vec<relume_core::Value> {
    relume_core::run_kind(&relume_cli::registry(), kind, &[], &graphs_dir(), inputs).unwrap_or_else(|e| panic!("{kind}: {e}")).outputs
}

/// A canonical scene from `graphs/scenes/`, optionally at another resolution (32² in test
/// mode).
pub fn scene(name: &str, size: Option<usize>) -> relume_base::types::Scene {
    let size = if test_mode() { Some(32) } else { size };
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../graphs/scenes").join(format!("{name}.ron"));
    let mut s = relume_base::scene::format::load_scene_file(&path).expect("scene loads").scene;
    if let Some(n) = size {
        s.camera.width = n;
        s.camera.height = n;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use relume_core::{Engine, RunOptions};

    #[test]
    fn every_generated_node_is_needed_and_one_edit_reaches_a_part_of_the_graph() {
        let reg = relume_cli::registry();
        let mut g = generated_graph(200);
        g.validate(&reg).unwrap();
        assert_eq!(g.node(&edit_node(200)).unwrap().kind, "GaussianBlur");
        let e = Engine::new(reg);
        assert_eq!(e.run(&g, &RunOptions::default()).unwrap().report.ran, 200);
        g.set_param_text(e.registry(), &format!("{}.sigma", edit_node(200)), "2.0").unwrap();
        let ran = e.run(&g, &RunOptions::default()).unwrap().report.ran;
        assert!((10..100).contains(&ran), "{ran}");
    }

    #[test]
    fn every_graph_in_graphs_has_a_representative_edit_that_reruns_part_of_it() {
        let mut names: Vec<String> = std::fs::read_dir(graphs_dir())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".ron"))
            .collect();
        names.sort();
        let mut listed: Vec<&str> = graph_edits().iter().map(|e| e.0).collect();
        listed.sort();
        assert_eq!(names, listed, "benches/lib.rs graph_edits() lists every graph");
        let reg = relume_cli::registry();
        for (name, param, value) in graph_edits() {
            let mut g = Graph::load(&graphs_dir().join(name), &reg).unwrap();
            g.set_param_text(&reg, param, &value(1)).unwrap_or_else(|e| panic!("{name}: {e}"));
        }
    }
}
