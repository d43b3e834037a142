//! The setpoint is held exactly, end to end: `trainer run` on a double integrator with the
//! setpoint x_ref = (0.5, 0), u_ref = 0 (an equilibrium: the plant rests there with u = 0).
//! Checked against `trainer solve`'s κ(x_ref):
//! - both nets of the model files reproduce κ(x_ref) in f64 to a few ulps of their output's
//!   rounding scale (`learn::setpoint::output_rounding_scale`);
//! - the exported controller (`weights.bin` decoded and evaluated by `controller-core` in
//!   f32) within the certified f32 allowance of `export_report.json`;
//! - the closed loop started at x_ref (`closed_loop.x0`) ends where the linearisation of the
//!   loop at x_ref puts it: e_{k+1} = (A + B K) e_k + B (r + δ_k) + w_k (A, B the plant,
//!   K = ∂κ_NN/∂x at x_ref, r = κ_NN(x_ref) − u_eq the net's input error at the equilibrium,
//!   δ_k the f64 rounding of the net's evaluation, |δ_k| ≤ 4ε·scale, w_k that of the plant
//!   step, |w_k|∞ ≤ 2ε‖x_ref‖∞), so
//!   ‖e_N‖∞ ≤ Σ_{j<N} ‖M^j B‖∞ (|r| + 4ε·scale) + Σ_{j<N} ‖M^j‖∞ 2ε‖x_ref‖∞, M = A + B K
//!   (×2 for the second-order terms at this scale); `final_offset` must not exceed it
//!   (without the hold, r is the net's fit error and the first check fails).
//!
//! And the compiled-in pendulum controller at its setpoint (the origin) equals the MPC's
//! κ(0) within its certificate's f32 allowance.

use ampc_tests::{config, tempdir, trainer};
use controller_core::demo::weights::Net;
use std::path::Path;

/// Reads the first data row of a CSV written by `trainer solve` / `trainer eval`.
fn row(p: &Path) -> std::collections::HashMap<String, f64> {
    let text = std::fs::read_to_string(p).unwrap();
    let mut lines = text.lines();
    let head: Vec<&str> = lines.next().unwrap().split(',').collect();
    let vals: Vec<&str> = lines.next().unwrap().split(',').collect();
    head.iter()
        .zip(vals)
        .filter_map(|(h, v)| v.parse::<f64>().ok().map(|v| (h.to_string(), v)))
        .collect()
}

fn json(p: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// Σ_{j<n} ‖M^j‖∞ (the induced ∞-norm: largest row sum) for a 2×2 M.
fn power_sum(m: [[f64; 2]; 2], n: usize) -> f64 {
    let (mut p, mut sum) = ([[1.0f64, 0.0], [0.0, 1.0]], 0.0);
    for _ in 0..n {
        sum += (p[0][0].abs() + p[0][1].abs()).max(p[1][0].abs() + p[1][1].abs());
        let q = p;
        p = [
            [
                m[0][0] * q[0][0] + m[0][1] * q[1][0],
                m[0][0] * q[0][1] + m[0][1] * q[1][1],
            ],
            [
                m[1][0] * q[0][0] + m[1][1] * q[1][0],
                m[1][0] * q[0][1] + m[1][1] * q[1][1],
            ],
        ];
    }
    sum
}

/// Σ_{j<n} ‖M^j b‖∞ for a 2×2 M and a 2-vector b.
fn drift_gain(m: [[f64; 2]; 2], b: [f64; 2], n: usize) -> f64 {
    let (mut v, mut sum) = (b, 0.0);
    for _ in 0..n {
        sum += v[0].abs().max(v[1].abs());
        v = [
            m[0][0] * v[0] + m[0][1] * v[1],
            m[1][0] * v[0] + m[1][1] * v[1],
        ];
    }
    sum
}

#[test]
fn run_holds_a_nonzero_setpoint_exactly() {
    let dir = tempdir();
    let d = dir.path();
    let steps = 40usize;
    let text = std::fs::read_to_string(config("double_integrator.toml"))
        .unwrap()
        .replace("[domain]", "x_ref = [0.5, 0.0]\nu_ref = [0.0]\n\n[domain]")
        .replace("counts = [21, 11]", "counts = [9, 5]")
        + "\n[training]\nepochs = 100\nbatch_size = 9\nvalidation_n = 40\nlog_every = 50\n"
        // The exported net is one of the two trained here (no refined net of another size).
        + "\n[refine]\nenabled = \"off\"\n\n[certify]\nstatistical = 300\nclosed_loop = 300\n"
        + &format!(
            "\n[closed_loop]\nsteps = {steps}\nx0 = [0.5, 0.0]\nrandom_initial_states = 2\nnoise_runs = 1\nseeds = 2\n"
        )
        + "\n[plots]\nerror_map_grid = [12, 8]\npng_scale = 1.0\n";
    let cfg_path = d.join("di.toml");
    std::fs::write(&cfg_path, &text).unwrap();
    let cfg = cfg_path.to_str().unwrap();
    let out = d.join("runs");
    let o = trainer(&["run", cfg, "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let run = out.join("double_integrator");

    // κ(x_ref) and its sensitivity from the solver.
    let states = d.join("xref.csv");
    std::fs::write(&states, "x1,x2\n0.5,0\n").unwrap();
    let solved = d.join("solved.csv");
    let o = trainer(&[
        "solve",
        "--config",
        cfg,
        "--states",
        states.to_str().unwrap(),
        "--out",
        solved.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let kappa = row(&solved)["u1"];

    let problem = trainer::problem::ProblemConfig::load(&cfg_path).unwrap();
    let ts = problem.ocp.ts;
    // The built-in double integrator (mass 1): RK4 of ẋ = (v, u) is exact.
    let (a, b) = ([[1.0, ts], [0.0, 1.0]], [0.5 * ts * ts, ts]);
    let cl = json(&run.join("closed_loop.json"));
    let mut f64_residual = 0.0f64;
    for name in ["nominal", "regularized"] {
        let model_path = run.join(format!("model_{name}.bin"));
        let model = trainer::certify::Model::load(&model_path).unwrap();
        assert!(
            model.settings.hold_setpoint,
            "{name}: the model records the hold"
        );
        let evaluated = d.join(format!("eval_{name}.csv"));
        let o = trainer(&[
            "eval",
            "--raw",
            "--model",
            model_path.to_str().unwrap(),
            "--states",
            states.to_str().unwrap(),
            "--out",
            evaluated.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let e = row(&evaluated);
        let r = e["u1"] - kappa;
        let scale = trainer::learn::setpoint::output_rounding_scale(&model.mlp, &[0.5, 0.0])[0];
        assert!(
            r.abs() <= 4.0 * f64::EPSILON * scale,
            "{name}: κ_NN(x_ref) = {} vs κ(x_ref) = {kappa} (rounding scale {scale})",
            e["u1"]
        );
        if name == "regularized" {
            f64_residual = r.abs();
        }
        // The loop from x_ref: e_N bounded by the drift of the residual through the
        // linearised loop (κ(x_ref) is the plant's equilibrium input 0 to solver precision,
        // so the net's input there is r + κ(x_ref)).
        let k = [e["du1_dx1"], e["du1_dx2"]];
        let acl = [
            [a[0][0] + b[0] * k[0], a[0][1] + b[0] * k[1]],
            [a[1][0] + b[1] * k[0], a[1][1] + b[1] * k[1]],
        ];
        // u_eq = 0: the double integrator rests at (0.5, 0) with no force.
        let x_ref_max: f64 = 0.5;
        let bound = 2.0
            * (drift_gain(acl, b, steps) * (e["u1"].abs() + 4.0 * f64::EPSILON * scale)
                + power_sum(acl, steps) * 2.0 * f64::EPSILON * x_ref_max);
        let first = &cl[name][0];
        assert_eq!(first["x0"], serde_json::json!([0.5, 0.0]));
        let off: Vec<f64> = first["final_offset"]
            .as_array()
            .expect("final_offset per state")
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect();
        assert_eq!(off.len(), 2);
        assert!(
            off.iter().all(|v| *v <= bound),
            "{name}: final offset {off:?} above the linearised drift bound {bound:e}"
        );
    }
    // Every run reports its final offset, one per state.
    for (k, runs) in cl.as_object().unwrap() {
        for r in runs.as_array().unwrap() {
            assert_eq!(r["final_offset"].as_array().map(Vec::len), Some(2), "{k}");
        }
    }
    let report = std::fs::read_to_string(run.join("report.md")).unwrap();
    assert!(report.contains("Final offset |x − x_ref|"), "{report}");
    assert!(report.contains("Setpoint x_ref = (0.5, 0)"), "{report}");

    // The exported controller, as the device computes it (f32, libm tanh, clamp).
    let blob = std::fs::read(run.join("weights.bin")).unwrap();
    let dec = controller_core::blob::decode::<2, 1, Net>(&blob).expect("weights.bin decodes");
    let u32 = dec.controller.evaluate(&[0.5, 0.0]);
    let allowance = json(&run.join("export_report.json"))["f32_allowance_libm"]
        .as_f64()
        .unwrap();
    // |u_f32 − κ| ≤ |u_f32 − κ_NN,f64| + |κ_NN,f64 − κ| (x_ref is exact in f32).
    assert!(
        (f64::from(u32.u[0]) - kappa).abs() <= allowance + f64_residual,
        "device u(x_ref) = {} vs κ(x_ref) = {kappa}, f32 allowance {allowance}",
        u32.u[0]
    );
}

#[test]
fn compiled_in_pendulum_controller_holds_the_origin() {
    let cfg = trainer::problem::ProblemConfig::default();
    let (l, _) = trainer::mpc::law::MpcLaw::new(&cfg).solve(&[0.0, 0.0], None);
    let c = &controller_core::demo::CERTIFICATE;
    let got = controller_core::demo::evaluate(&[0.0, 0.0]);
    // |u_f32 − κ_NN,f64| ≤ the certified f32 allowance, and κ_NN,f64(0) = κ(0) to f64
    // rounding (far below it).
    assert!(
        (f64::from(got.u[0]) - l.u[0]).abs() <= c.f32_allowance,
        "u(0) = {} vs κ(0) = {}, allowance {}",
        got.u[0],
        l.u[0],
        c.f32_allowance
    );
}
