//! Pixel relighting (pipeline 1), through its graphs: the BRDF basis graph reports the PCA
//! reconstruction error, projects a material, and a material edit re-runs the projection and
//! nothing upstream.

use relume_core::{Engine, RunOptions};
use relume_nodes::types::{BasisCoefficients, Metrics};
use relume_tests::load_graph;

#[test]
fn the_brdf_basis_graph_reports_its_pca_error_and_a_material_edit_reruns_only_the_projection() {
    let reg = relume_nodes::registry();
    let e = Engine::new(relume_nodes::registry());
    let mut g = load_graph("brdf_basis.ron", &[]);
    let r = e.run(&g, &RunOptions::default()).unwrap();
    let m = r.output("pca_error").unwrap().get::<Metrics>().unwrap();
    // Six bases over s ∈ [1, 200] (measured: mean 1.18 %, max 8.85 % with solid-angle
    // weighting; [S] 0.80 % / 6.75 %): a broken basis is tens of percent.
    assert_eq!(m.get("bases"), Some(6.0));
    let (mean, max) = (m.get("l2_error_mean_pct").unwrap(), m.get("l2_error_max_pct").unwrap());
    assert!(mean > 0.0 && mean < 2.0 && max < 12.0 && max >= mean, "{mean} {max}");
    let c = r.output("coefficients").unwrap().get::<BasisCoefficients>().unwrap();
    assert_eq!(c.0.len(), 6);
    assert!((c.0[0] - 0.2).abs() < 1e-6, "the diffuse coefficient is Kd: {:?}", c.0);

    // A material edit: only the projection runs again.
    g.set_param_text(&reg, "project.s", "180").unwrap();
    let r2 = e.run(&g, &RunOptions::default()).unwrap();
    assert_eq!(r2.report.ran_ids(), vec!["project"]);
    let c2 = r2.output("coefficients").unwrap().get::<BasisCoefficients>().unwrap();
    assert_ne!(c2.0[1..], c.0[1..], "a sharper lobe has other specular coefficients");

    // Kd = 1, Ks = 0 projects to (1, 0, …).
    g.set_param_text(&reg, "project.kd", "1").unwrap();
    g.set_param_text(&reg, "project.ks", "0").unwrap();
    let r3 = e.run(&g, &RunOptions::default()).unwrap();
    let c3 = r3.output("coefficients").unwrap().get::<BasisCoefficients>().unwrap();
    assert_eq!(c3.0, [1.0, 0.0, 0.0, 0.0, 0.0, 0.0]);
}
