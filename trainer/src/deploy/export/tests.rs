//! The export: folding keeps the function, the f32 allowance is sound and not vacuous, the
//! clamp band and the f32 domain, validation messages, the rustfmt layout of arrays.

use super::rust::array;
use super::*;

#[test]
fn folding_preserves_the_function() {
    let m = placeholder_pendulum();
    let f = m.folded();
    for x in [[0.3, -0.2], [-6.0, 1.0], [2.0, 0.5]] {
        // folded network in f64
        let mut h = x.to_vec();
        for (k, l) in f.layers.iter().enumerate() {
            h =
                l.w.iter()
                    .zip(&l.b)
                    .map(|(r, b)| {
                        let z = r.iter().zip(&h).fold(*b, |a, (w, x)| a + w * x);
                        if k + 1 < f.layers.len() {
                            z.tanh()
                        } else {
                            z
                        }
                    })
                    .collect();
        }
        assert!((h[0] - m.eval_f64(&x)[0]).abs() < 1e-12);
    }
}

#[test]
fn allowance_is_sound_on_a_million_states_and_not_vacuous() {
    let m = placeholder_pendulum();
    for t in Tanh::ALL {
        let (bound, _) = f32_allowance(&m, t);
        let seen = sampled_max_diff(&m, t, SAMPLES, 7);
        println!("{}: bound {bound:e}, observed {seen:e}", t.name());
        assert!(
            bound >= seen,
            "{}: bound {bound} < observed {seen}",
            t.name()
        );
        assert!(seen > 0.0);
        // tight enough to be useful: within three orders of magnitude of what is seen
        assert!(bound < 1e3 * seen.max(1e-7), "{bound} vs {seen}");
    }
}

#[test]
fn allowance_grows_with_a_worse_tanh_and_weights() {
    let m = placeholder_pendulum();
    let (a, _) = f32_allowance(&m, Tanh::Libm);
    let (b, _) = f32_allowance(&m, Tanh::Fast);
    assert!(b > a);
    let mut big = m.clone();
    big.output.scale = vec![150.0];
    assert!(f32_allowance(&big, Tanh::Libm).0 > a);
}

#[test]
fn band_contains_u_d_and_stays_in_actuator_limits() {
    let mut m = placeholder_pendulum();
    m.actuator_lo = vec![-20.0];
    m.actuator_hi = vec![16.0];
    let (lo, hi) = m.clamp_band(1.3);
    assert!(f64::from(lo[0]) <= -16.3 && f64::from(lo[0]) > -16.31);
    assert_eq!(hi[0], 16.0);
    m.u_lo = vec![-0.1];
    let (lo, _) = m.clamp_band(1e-9);
    assert!(f64::from(lo[0]) <= -0.1 - 1e-9);
    // The f32 domain contains X, and the f32 state nearest each corner of X.
    let (dlo, dhi) = m.domain_f32();
    for i in 0..2 {
        let (lo, hi) = (m.domain_lo[i], m.domain_hi[i]);
        assert!(f64::from(dlo[i]) <= lo && f64::from(dhi[i]) >= hi);
        assert!(dlo[i] <= lo as f32 && dhi[i] >= hi as f32, "corner {i}");
    }
}

#[test]
fn validate_names_the_field() {
    let mut m = placeholder_pendulum();
    m.layers[1].w[3].pop();
    let e = m.validate().unwrap_err().to_string();
    assert!(e.contains("layers[1].w[3]"), "{e}");
    let mut m = placeholder_pendulum();
    m.u_hi = vec![20.0];
    assert!(m.validate().unwrap_err().to_string().contains("u_0"));
}

#[test]
fn array_layout_rules() {
    let s: Vec<String> = (0..3).map(|i| format!("{i}.5")).collect();
    assert_eq!(array(&s, 0, 10, 1), "[0.5, 1.5, 2.5]");
}

/// Export refuses a certificate of another model, and one that names no problem.
#[test]
fn a_certificate_of_another_model_or_no_problem_is_refused() {
    use crate::certify::certificate::{certify, tests::two_problems, CertifyOptions};
    let dir = std::env::temp_dir().join(format!("ampc_export_cert_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let [(_, _, pmodel), (dcfg, ddata, dmodel)] = two_problems(&dir);
    let c = certify(&dmodel, &ddata, &dcfg, &CertifyOptions::default()).unwrap();
    assert!(ExportModel::from_trained("di", &dmodel, &c).is_ok());
    let e = ExportModel::from_trained("p", &pmodel, &c)
        .unwrap_err()
        .to_string();
    assert!(e.contains("not this model"), "{e}");
    let mut old = c.clone();
    old.problem_hash.clear();
    let e = ExportModel::from_trained("di", &dmodel, &old)
        .unwrap_err()
        .to_string();
    assert!(e.contains("names no problem"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_tier_above_what_the_numbers_support_is_refused() {
    let mut m = placeholder_pendulum();
    m.guarantee = Guarantee::Sound;
    let e = m.validate().unwrap_err().to_string();
    assert!(e.contains("guarantee") && e.contains("estimated"), "{e}");
    m.placeholder = false;
    m.l_mpc_is_estimate = false;
    assert!(m.validate().is_ok());
    // A declaration only ever lowers the tier.
    let m = m.with_declared_guarantee(Some(Guarantee::Statistical));
    assert_eq!(m.guarantee, Guarantee::Statistical);
    let m = m.with_declared_guarantee(Some(Guarantee::Sound));
    assert_eq!(m.guarantee, Guarantee::Statistical);
    assert_eq!(
        m.with_declared_guarantee(None).guarantee,
        Guarantee::Statistical
    );
}

#[test]
fn a_statistical_eps_is_statistical_and_narrows_the_band() {
    let mut m = placeholder_pendulum();
    let claim = StatisticalClaim {
        p_exceed_upper: 1e-3,
        confidence: 0.99,
        samples: 5000,
        unlabelled_p_upper: None,
    };
    // A placeholder has no statistical ε.
    let e = m
        .clone()
        .with_statistical_eps(0.5, claim.clone())
        .unwrap_err()
        .to_string();
    assert!(e.contains("placeholder"), "{e}");
    m.placeholder = false;
    m.eps = 40.0;
    m.actuator_lo = vec![-60.0];
    m.actuator_hi = vec![60.0];
    let wide = m.clamp_band(m.eps);
    let s = m.clone().with_statistical_eps(0.5, claim.clone()).unwrap();
    assert_eq!((s.eps, s.guarantee), (0.5, Guarantee::Statistical));
    assert!(s.validate().is_ok(), "statistical with a sampled L_MPC");
    let narrow = s.clamp_band(s.eps);
    assert!(narrow.0[0] > wide.0[0] && narrow.1[0] < wide.1[0]);
    assert!(narrow.0[0] as f64 <= -15.5 && narrow.1[0] as f64 >= 15.5);
    // Never sound, even with a proven L_MPC and a sound declaration.
    let mut t = s.clone();
    t.l_mpc_is_estimate = false;
    t.guarantee = Guarantee::Sound;
    let e = t.validate().unwrap_err().to_string();
    assert!(e.contains("statistical"), "{e}");
    // A declared weaker tier still lowers it.
    let low = s
        .clone()
        .with_declared_guarantee(Some(Guarantee::Estimated));
    assert_eq!(low.guarantee, Guarantee::Estimated);
    // Bad claims and levels name the field.
    for (eps, p, c, n, key) in [
        (f64::NAN, 1e-3, 0.99, 10, "statistical ε"),
        (0.5, 0.0, 0.99, 10, "p_exceed_upper"),
        (0.5, 1e-3, 1.0, 10, "confidence"),
        (0.5, 1e-3, 0.99, 0, "samples"),
    ] {
        let bad = StatisticalClaim {
            p_exceed_upper: p,
            confidence: c,
            samples: n,
            unlabelled_p_upper: None,
        };
        let e = m
            .clone()
            .with_statistical_eps(eps, bad)
            .unwrap_err()
            .to_string();
        assert!(e.contains(key), "{key}: {e}");
    }
    // The generated file says what ε rests on.
    let r = certify_f32(&s).unwrap();
    let text = render_rust(&s, &r);
    assert!(
        text.contains("statistical level") && text.contains("1.000e-3"),
        "rust file"
    );
    assert!(text.contains("Guarantee::Statistical"));
}

#[test]
fn numbers_beyond_the_f32_range_are_refused_naming_the_value() {
    // A weight, ε and a scaling whose folding overflows f32: each refused
    // before anything is written, the message naming the field and the value.
    let dir = std::env::temp_dir().join(format!("ampc_range_{}", std::process::id()));
    let (rs, bin) = (dir.join("w.rs"), dir.join("w.bin"));
    type Edit = Box<dyn Fn(&mut ExportModel)>;
    let cases: Vec<(&str, Edit)> = vec![
        (
            "layers[1].w[0][2] = 1e39",
            Box::new(|m| m.layers[1].w[0][2] = 1e39),
        ),
        ("eps = 5e40", Box::new(|m| m.eps = 5e40)),
        ("l_mpc = 1e300", Box::new(|m| m.l_mpc = 1e300)),
        (
            "folded layers[0].w[0]",
            Box::new(|m| {
                m.input.scale[0] = 1e-38;
                m.layers[0].w[0][0] = 1e4;
            }),
        ),
    ];
    for (what, edit) in cases {
        let mut m = placeholder_pendulum();
        edit(&mut m);
        let e = export_files(&m, &rs, &bin).unwrap_err().to_string();
        assert!(
            e.contains(what) && e.contains("beyond the f32 range"),
            "{what}: {e}"
        );
        assert!(!rs.exists() && !bin.exists(), "{what}: a file was written");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// In a scaled norm (u_scale = S_u) the f32 allowance is ‖S_u⁻¹(κ_NN,f32 − κ_NN,f64)‖₂ (for
/// one output the unscaled bound divided by s_u, rounded up) and the band is per input
/// U_d ⊕ [−s_u·ε, s_u·ε]: its physical bound, the same band as the unscaled ε·s_u.
#[test]
fn scaled_norm_allowance_and_band_are_per_input_physical() {
    let mut m = placeholder_pendulum();
    m.actuator_lo = vec![-20.0];
    m.actuator_hi = vec![20.0];
    let mut s = m.clone();
    s.u_scale = vec![15.0];
    let (a, _) = f32_allowance(&m, Tanh::Libm);
    let (b, _) = f32_allowance(&s, Tanh::Libm);
    assert!(
        b * 15.0 >= a && b * 15.0 <= a * (1.0 + 1e-12),
        "{a} vs 15·{b}"
    );
    let (lo, hi) = s.clamp_band(0.01);
    let (ulo, uhi) = m.clamp_band(0.15);
    assert!(f64::from(lo[0]) <= -15.15 && f64::from(hi[0]) >= 15.15);
    assert_eq!((lo, hi), (ulo, uhi));
    let d = sampled_max_diff(&s, Tanh::Libm, 10_000, 3);
    assert!(d <= b && d > 0.0, "observed {d} vs allowance {b}");
}
