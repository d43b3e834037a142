// A controller file in the exporter's format whose fallback lies outside its clamp band
// (as a hand edit could make it): `include_controller!` must refuse to compile it.

/// State dimension.
pub const NX: usize = 1;
/// Input dimension.
pub const NU: usize = 1;
/// The network type: 1 → 1.
pub type Net = Dense<1, 1>;
/// The network.
pub const NET: Net = Dense::new([[2.0]], [0.0]);
/// Lower corner of X.
pub const X_LO: [f32; 1] = [-1.0];
/// Upper corner of X.
pub const X_HI: [f32; 1] = [1.0];
/// The certificate for the libm tanh.
pub const CERTIFICATE_LIBM: Certificate<1, 1> = Certificate {
    eps: 0.5,
    guarantee: Guarantee::Estimated,
    eps_nn: 0.5,
    eps_d: 0.0,
    l_nn: 2.0,
    l_nn_method: "hand-written",
    l_mpc: 0.0,
    l_mpc_is_estimate: true,
    covering_radius: 0.0,
    f32_allowance: 0.0,
    f32_observed: 0.0,
    tanh: "libm",
    tanh_max_abs_err: 0.0,
    domain_lo: [-1.0],
    domain_hi: [1.0],
    u_lo: [-2.0],
    u_hi: [2.0],
    actuator_lo: [-3.0],
    actuator_hi: [3.0],
    clamp_lo: [-2.5],
    clamp_hi: [2.5],
    fallback: [2.75],
    excluded: &[],
    hash: "hand-written",
    placeholder: true,
};
/// The certificate for the fast tanh (the same numbers).
pub const CERTIFICATE_FAST: Certificate<1, 1> = CERTIFICATE_LIBM;
