//! Export round trip: the committed `controller-core/src/generated/weights.{rs,bin}` are
//! exactly what `trainer::export` produces (byte for byte), and the core computes exactly
//! what the exporter's f32 model of the device computes (bit for bit).
//!
//! The committed weights are the paper's pendulum controller (sensitivity-regularized) as
//! `trainer run` produces it from the embedded `configs/pendulum.toml`: this test reruns
//! that pipeline (sample → train → certify → export) and compares the files byte for byte.
//! Regenerate them (and the C API's header `controller-core/capi/include/ampc.h`) with
//! `cargo run --release -p trainer -- run && cp runs/pendulum/weights.{rs,bin} controller-core/src/generated/`
//! and `trainer export … --c-header` (README, "The embedded side"), or with
//! `AMPC_BLESS=1 cargo test -p ampc-tests --test export_roundtrip` (writes the three files
//! from this test's own pipeline run).

use ampc_tests::tempdir;
use controller_core::activation;
use trainer::deploy::export::{self, Tanh};

fn committed(name: &str) -> Vec<u8> {
    let p = format!(
        "{}/../controller-core/src/generated/{name}",
        env!("CARGO_MANIFEST_DIR")
    );
    std::fs::read(&p).unwrap_or_else(|e| panic!("{p}: {e}"))
}

#[test]
fn committed_files_are_what_the_exporter_writes() {
    let (model, run_dir) = ampc_tests::trained_pendulum();
    assert!(!model.placeholder);
    let dir = tempdir();
    let (rs, bin) = (
        dir.path().join("weights.rs"),
        dir.path().join("weights.bin"),
    );
    let report = export::export_files(model, &rs, &bin).unwrap();
    let generated = format!(
        "{}/../controller-core/src/generated",
        env!("CARGO_MANIFEST_DIR")
    );
    let header_path = format!(
        "{}/../controller-core/capi/include/ampc.h",
        env!("CARGO_MANIFEST_DIR")
    );
    if std::env::var_os("AMPC_BLESS").is_some() {
        std::fs::copy(&rs, format!("{generated}/weights.rs")).unwrap();
        std::fs::copy(&bin, format!("{generated}/weights.bin")).unwrap();
        std::fs::write(
            &header_path,
            export::render_c_header(model, &report).unwrap(),
        )
        .unwrap();
    }
    // The pipeline's export stage wrote the same files.
    assert_eq!(
        std::fs::read(&rs).unwrap(),
        std::fs::read(run_dir.join("weights.rs")).unwrap()
    );
    assert!(report.f32_allowance[0] >= report.f32_observed[0]);
    assert!(report.f32_allowance[1] >= report.f32_observed[1]);
    let fresh = std::fs::read(&rs).unwrap();
    assert!(
        fresh == committed("weights.rs"),
        "controller-core/src/generated/weights.rs is stale: regenerate it with trainer export"
    );
    assert_eq!(std::fs::read(&bin).unwrap(), committed("weights.bin"));
    // The C API's header is the exporter's for the same model and allowances.
    let header = export::render_c_header(model, &report).unwrap();
    let p = header_path;
    assert!(
        std::fs::read_to_string(&p).unwrap_or_default() == header,
        "{p} is stale: regenerate it with trainer export --c-header"
    );
    assert_eq!(controller_core::CERTIFICATE.hash, model.hash);
}

#[test]
fn exporter_and_core_share_tanh_code_and_bounds() {
    assert_eq!(
        Tanh::Libm.max_abs_err(),
        activation::TANH_ACCURATE_MAX_ABS_ERR
    );
    assert_eq!(Tanh::Fast.max_abs_err(), activation::TANH_FAST_MAX_ABS_ERR);
    for ((a, d), (b, e)) in export::TANH_FAST_ERR_BINS
        .iter()
        .zip(activation::TANH_FAST_ERR_BINS)
    {
        assert_eq!((*a, *d), (f64::from(b), e));
    }
    for k in -2_000_000..2_000_000 {
        let x = k as f32 * 4e-6;
        assert_eq!(
            Tanh::Libm.eval(x).to_bits(),
            activation::tanh_accurate(x).to_bits()
        );
        assert_eq!(
            Tanh::Fast.eval(x).to_bits(),
            activation::tanh_fast(x).to_bits()
        );
    }
    // Every 4099th bit pattern: both signs, subnormals, both branches of the accurate tanh,
    // beyond both clips, infinities and NaNs (~10⁶ inputs).
    for bits in (0..=u32::MAX)
        .step_by(4099)
        .chain([0x7f80_0000, 0xff80_0000, 0x7fc0_0000])
    {
        let x = f32::from_bits(bits);
        assert_eq!(
            Tanh::Libm.eval(x).to_bits(),
            activation::tanh_accurate(x).to_bits(),
            "x = {x:e}"
        );
        assert_eq!(
            Tanh::Fast.eval(x).to_bits(),
            activation::tanh_fast(x).to_bits(),
            "x = {x:e}"
        );
    }
}

#[test]
fn core_matches_the_exporters_f32_model_bit_for_bit() {
    let (model, _) = ampc_tests::trained_pendulum();
    let folded = model.folded();
    let (lo, hi) = model.domain_f32();
    let tanh = if activation::TANH_KIND == "fast" {
        Tanh::Fast
    } else {
        Tanh::Libm
    };
    let mut s = 0x1234_5678_9abc_def1u64;
    let mut rnd = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    for _ in 0..200_000 {
        let x = [-8.0 + 16.0 * rnd(), -1.5 + 3.0 * rnd()];
        let y = export::eval_f32(&folded, &lo, &hi, &x, tanh)[0];
        let c = &controller_core::CERTIFICATE;
        let expect = y.clamp(c.clamp_lo[0], c.clamp_hi[0]);
        let got = controller_core::evaluate(&x).u[0];
        assert_eq!(got.to_bits(), expect.to_bits(), "x = {x:?}");
    }
}
