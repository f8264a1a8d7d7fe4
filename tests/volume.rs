//! Pipeline 3 (in progress), through its graph: voxelising the glass sphere, a paint stroke
//! and the octree; a stroke re-runs what reads the medium, never the voxelisation.

use relume_core::{Engine, RunOptions};
use relume_nodes::types::{Image, Volume};
use relume_tests::load_graph;

#[test]
fn a_paint_stroke_reruns_the_octree_onward_and_not_the_voxelisation() {
    let reg = relume_nodes::registry();
    let e = Engine::new(relume_nodes::registry());
    let mut g = load_graph("voxelize_glass.ron", &[("voxelize.resolution", "32")]);
    let r = e.run(&g, &RunOptions::default()).unwrap();
    let v = r.report.node("voxelize").unwrap();
    assert!(v.metrics["volume_error_pct"].abs() < 1.0, "{:?}", v.metrics);
    let medium = r.output("medium").unwrap().get::<Volume>().unwrap().clone();
    assert_eq!(medium.dims, [32, 32, 32]);
    let painted = r.report.node("paint").unwrap().metrics["voxels_painted"];
    assert!(painted > 10.0, "{painted}");

    g.set_param_text(&reg, "paint.weight", "0.5").unwrap();
    let r2 = e.run(&g, &RunOptions::default()).unwrap();
    let mut ran = r2.report.ran_ids();
    ran.sort();
    assert_eq!(ran, ["leaves", "octree", "paint", "slice"], "the stroke reaches the medium's readers only");
    let (a, b) = (r.output("slice").unwrap().get::<Image>().unwrap(), r2.output("slice").unwrap().get::<Image>().unwrap());
    let brighter = a.pixels.iter().zip(&b.pixels).filter(|(x, y)| y[0] > x[0] + 0.05).count();
    assert!(brighter > 5, "{brighter} voxels of the slice gained index");
}
