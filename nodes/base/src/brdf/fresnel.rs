//! Fresnel reflectance: exact for a smooth dielectric interface, Schlick's approximation for the
//! Cook-Torrance specular term.

/// Exact (unpolarised) Fresnel reflectance of a smooth dielectric interface.
///
/// `cos_i` ≥ 0 is the cosine of the angle of incidence, `eta` = n_t / n_i the index of the side
/// the light refracts into over the index of the side it arrives from. With
/// sin²θt = (1 − cos²θi) / η² (Snell), total internal reflection when sin²θt ≥ 1, else
///
///   r_s = (cos θi − η cos θt) / (cos θi + η cos θt),
///   r_p = (η cos θi − cos θt) / (η cos θi + cos θt),
///   F   = (r_s² + r_p²) / 2.
///
/// Returns (F, cos θt); cos θt = 0 under total internal reflection (F = 1). η = 1 gives
/// exactly (0, cos θi). Computed in f64.
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> (f32, f32) {
    let ci = (cos_i as f64).clamp(0.0, 1.0);
    if eta == 1.0 {
        return (0.0, ci as f32);
    }
    let eta = eta as f64;
    let sin2_t = (1.0 - ci * ci).max(0.0) / (eta * eta);
    if sin2_t >= 1.0 {
        return (1.0, 0.0);
    }
    let ct = (1.0 - sin2_t).sqrt();
    let rs = (ci - eta * ct) / (ci + eta * ct);
    let rp = (eta * ci - ct) / (eta * ci + ct);
    let f = 0.5 * (rs * rs + rp * rp);
    (f.clamp(0.0, 1.0) as f32, ct as f32)
}

/// Schlick's approximation F = f0 + (1 − f0)(1 − cos β)⁵, with cos β = ωi·h (= ωo·h) the
/// cosine between the light direction and the half vector, as in Cook & Torrance 1981.
pub fn schlick(f0: f64, cos_beta: f64) -> f64 {
    let c = (1.0 - cos_beta.clamp(0.0, 1.0)).powi(5);
    f0 + (1.0 - f0) * c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exact_fresnel_at_normal_incidence_is_the_squared_index_contrast() {
        for eta in [1.0f32, 1.1, 1.333, 1.5, 2.4, 1.0 / 1.5, 0.4] {
            let (f, ct) = fresnel_dielectric(1.0, eta);
            let expect = ((eta - 1.0) / (eta + 1.0)).powi(2);
            assert!((f - expect).abs() < 1e-6, "eta {eta}: {f} vs {expect}");
            assert!((ct - 1.0).abs() < 1e-6);
        }
    }

    #[test]
    fn exact_fresnel_is_the_same_from_both_sides_of_the_interface() {
        // Stokes: a ray and its refracted partner see the same reflectance.
        for eta in [1.2f32, 1.5, 2.0] {
            for k in 0..50 {
                let ci = 0.02 + 0.98 * k as f32 / 49.0;
                let (f_out, ct) = fresnel_dielectric(ci, eta);
                let (f_in, ci_back) = fresnel_dielectric(ct, 1.0 / eta);
                assert!((f_out - f_in).abs() < 1e-5, "eta {eta} cos {ci}: {f_out} vs {f_in}");
                assert!((ci_back - ci).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn exact_fresnel_totally_reflects_past_the_critical_angle_and_not_before() {
        let eta = 1.0 / 1.5; // from glass into air
        let crit_cos = (1.0f32 - eta * eta).sqrt();
        assert_eq!(fresnel_dielectric(crit_cos - 1e-3, eta), (1.0, 0.0));
        assert_eq!(fresnel_dielectric(0.0, eta), (1.0, 0.0));
        let (f, ct) = fresnel_dielectric(crit_cos + 1e-3, eta);
        assert!(f < 1.0 && ct > 0.0, "{f} {ct}");
        // At grazing incidence from outside everything is reflected too.
        assert!((fresnel_dielectric(0.0, 1.5).0 - 1.0).abs() < 1e-6);
    }

    #[test]
    fn exact_fresnel_matches_textbook_glass_values_and_loses_p_light_at_brewster() {
        // Glass (η = 1.5) at 45°: R_s = 0.0920, R_p = 0.00847, F = 0.0502.
        let (f, _) = fresnel_dielectric(45f32.to_radians().cos(), 1.5);
        assert!((f - 0.050_24).abs() < 1e-4, "{f}");
        // At Brewster's angle tan θ = η only s-polarised light reflects:
        // F = R_s / 2 = ((1 − η²) / (1 + η²))² / 2.
        for eta in [1.333f32, 1.5, 2.4] {
            let (f, _) = fresnel_dielectric(eta.atan().cos(), eta);
            let expect = ((1.0 - eta * eta) / (1.0 + eta * eta)).powi(2) / 2.0;
            assert!((f - expect).abs() < 1e-5, "eta {eta}: {f} vs {expect}");
        }
    }

    #[test]
    fn schlick_runs_from_f0_at_normal_incidence_to_one_at_grazing() {
        for f0 in [0.0, 0.04, 0.5, 1.0] {
            assert!((schlick(f0, 1.0) - f0).abs() < 1e-12);
            assert!((schlick(f0, 0.0) - 1.0).abs() < 1e-12);
            assert!(schlick(f0, 0.5) >= f0 && schlick(f0, 0.5) <= 1.0);
        }
    }
}
