//! `plant`: the pendulum ẋ1 = x2, ẋ2 = u/(m l²) − (g/l) sin(x1 + π), one RK4 step in f32.

/// Mass m [kg].
pub const M: f32 = 1.0;
/// Length l [m].
pub const L: f32 = 1.0;
/// Gravity g [m/s²].
pub const G: f32 = 9.81;
/// Sampling time Ts [s].
pub const TS: f32 = 0.05;

/// The vector field f(x, u).
pub fn f(x: [f32; 2], u: f32) -> [f32; 2] {
    [
        x[1],
        u / (M * L * L) - (G / L) * libm::sinf(x[0] + core::f32::consts::PI),
    ]
}

/// One classical RK4 step of length [`TS`] with `u` held constant.
pub fn rk4_step(x: [f32; 2], u: f32) -> [f32; 2] {
    let add = |a: [f32; 2], b: [f32; 2], h: f32| [a[0] + h * b[0], a[1] + h * b[1]];
    let k1 = f(x, u);
    let k2 = f(add(x, k1, 0.5 * TS), u);
    let k3 = f(add(x, k2, 0.5 * TS), u);
    let k4 = f(add(x, k3, TS), u);
    let mut y = x;
    for i in 0..2 {
        y[i] = x[i] + (TS / 6.0) * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn upright_is_an_equilibrium_and_hanging_is_stable() {
        // sin(0 + π) is not exactly 0 in f32 (π_f32 ≠ π): a tiny residual drift only.
        let x = rk4_step([0.0, 0.0], 0.0);
        assert!(x[0].abs() < 1e-8 && x[1].abs() < 1e-6, "{x:?}");
        // Small angle, no torque: the pendulum near upright falls away (x1 grows).
        let x = rk4_step([0.01, 0.0], 0.0);
        assert!(x[0] > 0.01);
        // Torque accelerates (ẋ2 ≈ u at the bottom) and gravity pulls back towards hanging:
        // after one step x2 is just below u·Ts = 0.5.
        let x = rk4_step([-core::f32::consts::PI, 0.0], 10.0);
        assert!(x[1] > 0.49 && x[1] < 0.5, "{x:?}");
    }
}
