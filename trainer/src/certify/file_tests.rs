//! Tests of [`super::CertificateFile`]: round trip, sealing, and every re-check naming its key.

use super::*;
use crate::certify::certificate::LnnMethod;

fn base() -> Certificate {
    let (eps_d, l_mpc, l_nn, r) = (0.25, 3.0, 40.0, 0.01);
    let eps = eps_d + (l_mpc + l_nn) * r;
    Certificate {
        eps,
        eps_d,
        l_nn,
        l_nn_method: LnnMethod::LipSdpNeuron,
        l_nn_naive: 60.0,
        l_nn_lipsdp: l_nn,
        l_nn_vertex: None,
        l_nn_lower: 10.0,
        l_mpc,
        l_mpc_is_estimate: true,
        l_mpc_method: "estimate".into(),
        covering_radius: r,
        covering_method: "exact".into(),
        f32_allowance: 0.0,
        domain_lo: vec![-1.0, -2.0],
        domain_hi: vec![1.0, 2.0],
        u_lo: vec![-5.0],
        u_hi: vec![5.0],
        clamp_lo: vec![-5.0 - eps],
        clamp_hi: vec![5.0 + eps],
        n_points: 100,
        hash: "ab".into(),
        problem_hash: "cd".into(),
        dataset_hash: "ef".into(),
        labels: None,
        scales: None,
        epsilon_per_input: vec![],
    }
}

/// `text` with `from` replaced by `to` once and the checksum recomputed (a careful forger).
pub(crate) fn reseal(text: &str, from: &str, to: &str) -> String {
    assert!(text.contains(from), "{from} not in {text}");
    let v: serde_json::Value = serde_json::from_str(&text.replacen(from, to, 1)).unwrap();
    crate::certify::seal::sealed_json(&v).unwrap()
}

fn refused(text: &str) -> String {
    match CertificateFile::parse(text, "c.json", false)
        .and_then(|(f, _)| f.recheck("c.json", &Against::default()).map(|_| f))
    {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn the_file_round_trips_with_the_contract_keys() {
    let f = CertificateFile::theorem1(base());
    let text = f.sealed().unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    for k in [
        "eps",
        "eps_d",
        "l_nn",
        "l_nn_method",
        "l_nn_naive",
        "l_nn_lower",
        "l_mpc",
        "l_mpc_is_estimate",
        "covering_radius",
        "f32_allowance",
        "domain_lo",
        "domain_hi",
        "u_lo",
        "u_hi",
        "clamp_lo",
        "clamp_hi",
        "hash",
        "guarantee",
        "tiers",
        "assumptions",
        "checksum",
    ] {
        assert!(v.get(k).is_some(), "{k} missing in {text}");
    }
    let (back, seal) = CertificateFile::parse(&text, "c.json", false).unwrap();
    assert_eq!(seal, Seal::Verified);
    assert_eq!(back, f);
    back.recheck("c.json", &Against::default()).unwrap();
    // The file is the same as the JSON assembled by hand before (the certificate's keys
    // extended by the tiers'): same keys, same bytes.
    let mut old = serde_json::to_value(base()).unwrap();
    let g = serde_json::to_value(tier::theorem1(&base())).unwrap();
    old.as_object_mut()
        .unwrap()
        .extend(g.as_object().unwrap().clone());
    let old = crate::certify::seal::sealed_json(&old).unwrap();
    assert_eq!(text, old);
}

#[test]
fn edits_with_a_recomputed_checksum_are_refused_naming_the_field() {
    let text = CertificateFile::theorem1(base()).sealed().unwrap();
    let eps = base().eps.to_string();
    let e = refused(&reseal(&text, &format!("\"eps\": {eps}"), "\"eps\": 0.01"));
    assert!(
        e.contains("`eps` = 0.01") && e.contains("ε_D + (L_MPC + L_NN)·r"),
        "{e}"
    );
    let e = refused(&reseal(
        &text,
        "\"clamp_hi\": [\n    ",
        "\"clamp_hi\": [\n    1e9, ",
    ));
    assert!(e.contains("clamp_hi") || e.contains("entries"), "{e}");
    let hi = format!("{}", 5.0 + base().eps);
    let e = refused(&reseal(&text, &hi, "1000000000.0"));
    assert!(e.contains("`clamp_hi[0]`"), "{e}");
    let e = refused(&reseal(
        &text,
        "\"guarantee\": \"estimated\"",
        "\"guarantee\": \"sound\"",
    ));
    assert!(e.contains("`guarantee` = \"sound\""), "{e}");
    // Every tier upgraded together: the terms (a sampled L_MPC) still say estimated.
    let forged = text
        .replace("\"estimated\"", "\"sound\"")
        .replace("\"assumptions\": [", "\"assumptions_\": [");
    let mut v: serde_json::Value = serde_json::from_str(&forged).unwrap();
    v["assumptions"] = serde_json::json!([]);
    v.as_object_mut().unwrap().remove("assumptions_");
    let e = refused(&crate::certify::seal::sealed_json(&v).unwrap());
    assert!(e.contains("`guarantee`") && e.contains("estimated"), "{e}");
}

#[test]
fn domain_and_hashes_are_checked_against_what_is_given() {
    let f = CertificateFile::theorem1(base());
    let a = Against {
        model_hash: Some("other"),
        ..Default::default()
    };
    let e = f.recheck("c.json", &a).unwrap_err().to_string();
    assert!(e.starts_with("c.json: `hash` = ab"), "{e}");
    let a = Against {
        dataset_hash: Some("zz"),
        ..Default::default()
    };
    let e = f.recheck("c.json", &a).unwrap_err().to_string();
    assert!(e.contains("`dataset_hash`"), "{e}");
}

#[test]
fn unsealed_files_are_refused_unless_accepted_and_then_estimated() {
    let mut v = serde_json::to_value(CertificateFile::theorem1(base())).unwrap();
    let plain = serde_json::to_string_pretty(&v).unwrap();
    let e = refused(&plain);
    assert!(
        e.contains("no `checksum`") && e.contains("--accept-unsealed"),
        "{e}"
    );
    let (f, seal) = CertificateFile::parse(&plain, "c.json", true).unwrap();
    assert_eq!(seal, Seal::Absent);
    assert_eq!(f.tier(), Tier::Estimated);
    assert!(f
        .guarantee
        .assumptions
        .iter()
        .any(|a| a.contains("unsealed")));
    // Without `guarantee`: refused when sealed, `estimated` when accepted unsealed.
    v.as_object_mut().unwrap().remove("guarantee");
    let sealed = crate::certify::seal::sealed_json(&v).unwrap();
    let e = refused(&sealed);
    assert!(e.contains("no `guarantee`"), "{e}");
    let (f, _) =
        CertificateFile::parse(&serde_json::to_string(&v).unwrap(), "c.json", true).unwrap();
    assert_eq!(f.tier(), Tier::Estimated);
}

#[test]
fn a_failed_check_is_refused() {
    let mut f = CertificateFile::theorem1(base());
    f.check = Some(CheckSummary {
        states: 100,
        exceedances: 2,
        passed: false,
        report: "check.json".into(),
    });
    let text = f.sealed().unwrap();
    let e = refused(&text);
    assert!(e.contains("check failed") && e.contains("2 of 100"), "{e}");
}

/// A certificate in a scaled norm states it (`norm`, `epsilon_per_input`), its band is
/// per input U_d ⊕ [−s_u·ε, s_u·ε], and both are re-checked naming the key; one without
/// `norm` (an older file) reads as unscaled: its band is checked against ε itself.
#[test]
fn a_scaled_certificate_states_its_norm_and_older_ones_read_as_unscaled() {
    let mut c = base();
    let norm = crate::certify::norm::Norm {
        x_scale: vec![1.0, 2.0],
        u_scale: vec![5.0],
    };
    c.epsilon_per_input = norm.per_input(c.eps);
    c.clamp_lo = vec![-5.0 - c.epsilon_per_input[0]];
    c.clamp_hi = vec![5.0 + c.epsilon_per_input[0]];
    c.scales = Some(norm);
    let text = CertificateFile::theorem1(c.clone()).sealed().unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["norm"]["u_scale"][0], 5.0);
    assert_eq!(v["epsilon_per_input"][0], c.epsilon_per_input[0]);
    let (back, _) = CertificateFile::parse(&text, "c.json", false).unwrap();
    back.recheck("c.json", &Against::default()).unwrap();
    assert_eq!(back.base.eps_per_input(), c.epsilon_per_input);
    let e = refused(&reseal(
        &text,
        "\"u_scale\": [\n      5.0",
        "\"u_scale\": [\n      0.5",
    ));
    assert!(e.contains("epsilon_per_input[0]"), "{e}");
    let e = refused(&reseal(
        &text,
        "\"u_scale\": [\n      5.0",
        "\"u_scale\": [\n      -1.0",
    ));
    assert!(e.contains("norm.u_scale[0]"), "{e}");
    // The same numbers without `norm` and `epsilon_per_input`: unscaled, so the band
    // U_d ⊕ [−5ε, 5ε] is outside U_d ⊕ [−ε, ε].
    let mut old: serde_json::Value = serde_json::from_str(&text).unwrap();
    let o = old.as_object_mut().unwrap();
    o.remove("norm");
    o.remove("epsilon_per_input");
    o.remove("checksum");
    let old = crate::certify::seal::sealed_json(&old).unwrap();
    let e = refused(&old);
    assert!(e.contains("clamp_lo[0]") && e.contains("ε_0 = "), "{e}");
    let (f, _) = CertificateFile::parse(
        &CertificateFile::theorem1(base()).sealed().unwrap(),
        "c.json",
        false,
    )
    .unwrap();
    assert!(f.base.norm().is_unit());
    assert_eq!(f.base.eps_per_input(), vec![f.base.eps]);
}
