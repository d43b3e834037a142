//! The placeholder pendulum [`ExportModel`]: an untrained, uncertified 2-10-10-1 network
//! that stands in for the trained one (controller-core's own weights before a run).

use super::{DenseF64, ExportModel, Guarantee, Scaling};

/// PLACEHOLDER pendulum network (2-10-10-1) until the trained one exists: deterministic
/// pseudo-random weights (xorshift, seed 0x5EED, uniform in ±1.5/√fan_in), normalisation by
/// the domain's half-widths, output scale 15 N·m. Not trained and not certified: the
/// certificate numbers are zero and `placeholder = true`.
pub fn placeholder_pendulum() -> ExportModel {
    let mut s: u64 = 0x5EED;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    let sizes = [2usize, 10, 10, 1];
    let layers = sizes
        .windows(2)
        .map(|d| {
            let g = 1.5 / (d[0] as f64).sqrt();
            DenseF64 {
                w: (0..d[1])
                    .map(|_| (0..d[0]).map(|_| g * next()).collect())
                    .collect(),
                b: (0..d[1]).map(|_| 0.1 * next()).collect(),
            }
        })
        .collect();
    let tau = std::f64::consts::TAU;
    ExportModel {
        name: "pendulum".into(),
        layers,
        input: Scaling {
            mean: vec![0.0, 0.0],
            scale: vec![tau, 1.0],
        },
        output: Scaling {
            mean: vec![0.0],
            scale: vec![15.0],
        },
        domain_lo: vec![-tau, -1.0],
        domain_hi: vec![tau, 1.0],
        u_lo: vec![-15.0],
        u_hi: vec![15.0],
        actuator_lo: vec![-15.0],
        actuator_hi: vec![15.0],
        fallback: None,
        eps: 0.0,
        eps_d: 0.0,
        l_nn: 0.0,
        l_nn_method: "placeholder (untrained network, no certificate)".into(),
        l_mpc: 0.0,
        l_mpc_is_estimate: true,
        covering_radius: 0.0,
        hash: "placeholder-2-10-10-1-seed-5eed".into(),
        placeholder: true,
        guarantee: Guarantee::Estimated,
        statistical: None,
        excluded: Vec::new(),
        rests_on: Vec::new(),
        u_scale: Vec::new(),
    }
}
