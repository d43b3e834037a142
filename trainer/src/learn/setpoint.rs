//! The setpoint hold: the bias correction that makes a trained net reproduce the MPC's
//! input at the setpoint exactly,
//!
//! ```text
//! κ̂_NN(x) = κ_NN(x) − κ_NN(x_ref) + κ(x_ref) = κ_NN(x) + c,   c = κ(x_ref) − κ_NN(x_ref)
//! ```
//!
//! with κ(x_ref) the MPC's own solve at x_ref (a label from the solver, not u_ref: with
//! active constraints or a u_ref that is no equilibrium input they differ). The constant c is
//! folded into the last layer's bias (b_m ← b_m + c ⊘ s, s the output half-widths), so every
//! later stage — the model file, the certificate (for the corrected net: ε_D changes, L_NN
//! does not, a bias does not enter any Lipschitz bound), the export and the device — sees
//! the corrected net. A net that fits κ at x_ref only up to an error leaves a steady-state
//! offset around the setpoint; the corrected one has x_ref as a fixed point of the closed
//! loop exactly when the MPC has.
//!
//! [`Hold`] holds (x_ref, κ(x_ref)); [`Hold::apply`] folds the constant in and then corrects
//! the f64 rounding of the output formula u = o + s ∘ (b + W a) by a few residual steps, so
//! that the net's output at x_ref equals κ(x_ref) to the last bits (to a few ulps where no
//! bias reproduces it exactly).

use crate::learn::mlp::Mlp;
use crate::mpc::law::MpcLaw;
use crate::problem::ProblemConfig;

/// The setpoint to hold and the MPC's input there.
#[derive(Debug, Clone, PartialEq)]
pub struct Hold {
    /// The setpoint x_ref (`ocp.x_ref`, else the origin).
    pub x_ref: Vec<f64>,
    /// κ(x_ref), the MPC's solution at x_ref.
    pub u: Vec<f64>,
}

/// κ(x_ref) could not be computed.
#[derive(Debug, thiserror::Error)]
#[error(
    "cannot hold the setpoint: the MPC at x_ref = {state} ended with status {status} (no \
     label); check ocp.x_ref, or set training.hold_setpoint = false"
)]
pub struct HoldError {
    /// The setpoint, named by state (e.g. `(pos = 0.5, vel = 0)`).
    pub state: String,
    /// The solver's status there.
    pub status: String,
}

impl Hold {
    /// Solves the MPC of `cfg` at its setpoint (cold start); an error names the state when
    /// the solve gives no label.
    pub fn solve(cfg: &ProblemConfig) -> Result<Hold, HoldError> {
        let x_ref = cfg.ocp.x_ref_or_origin(cfg.system.nx());
        let (label, _) = MpcLaw::new(cfg).solve(&x_ref, None);
        if !label.status.is_labelled() {
            let names: Vec<String> = match cfg.system.expr_model() {
                Some(m) => m.state_names().to_vec(),
                None => (1..=x_ref.len()).map(|i| format!("x{i}")).collect(),
            };
            let parts: Vec<String> = names
                .iter()
                .zip(&x_ref)
                .map(|(n, v)| format!("{n} = {v}"))
                .collect();
            return Err(HoldError {
                state: format!("({})", parts.join(", ")),
                status: format!("{:?}", label.status),
            });
        }
        Ok(Hold { x_ref, u: label.u })
    }

    /// [`solve`](Self::solve) when `enabled` (the `hold_setpoint` setting of the training
    /// that will use it), else `None`.
    pub fn if_enabled(cfg: &ProblemConfig, enabled: bool) -> Result<Option<Hold>, HoldError> {
        enabled.then(|| Hold::solve(cfg)).transpose()
    }

    /// Folds c = κ(x_ref) − κ_NN(x_ref) into the last layer's bias of `mlp`, then takes up
    /// to four residual steps against the f64 rounding of the output, keeping the bias with
    /// the smallest residual. Returns the largest remaining |κ_NN(x_ref) − κ(x_ref)|.
    pub fn apply(&self, mlp: &mut Mlp) -> f64 {
        let nu = self.u.len();
        let residual = |m: &Mlp| -> Vec<f64> {
            let p = m.predict(&self.x_ref);
            (0..nu).map(|r| self.u[r] - p[r]).collect()
        };
        let last = mlp.layers.len() - 1;
        let mut d = residual(mlp);
        let mut best = (d.clone(), mlp.layers[last].b.clone());
        for _ in 0..5 {
            if d.iter().all(|v| *v == 0.0) {
                break;
            }
            for (r, dv) in d.iter().enumerate() {
                mlp.layers[last].b[r] += dv / mlp.out_half[r];
            }
            d = residual(mlp);
            for r in 0..nu {
                // Per output: the bias of row r moves output r only.
                if d[r].abs() < best.0[r].abs() {
                    best.0[r] = d[r];
                    best.1[r] = mlp.layers[last].b[r];
                }
            }
        }
        mlp.layers[last].b = best.1;
        best.0.iter().fold(0.0f64, |m, v| m.max(v.abs()))
    }
}

/// The scale of the f64 rounding of the net's output at `x`, per output r:
/// |o_r| + s_r·(|b_r| + Σ_i |w_ri a_i|) over the last layer (a the last hidden activations).
/// The output u = o + s·(b + W a) is a rounded sum of these terms, so no bias can bring it
/// closer to a target than about one ulp of this scale: "exact in f64" means within a few
/// ulps of it.
pub fn output_rounding_scale(m: &Mlp, x: &[f64]) -> Vec<f64> {
    let mut a: Vec<f64> = (0..x.len())
        .map(|c| (x[c] - m.in_center[c]) / m.in_half[c])
        .collect();
    let n = m.layers.len();
    for l in &m.layers[..n - 1] {
        a = (0..l.out)
            .map(|r| {
                let z = l.b[r] + (0..l.inp).map(|c| l.w[r * l.inp + c] * a[c]).sum::<f64>();
                m.activation.eval(z).0
            })
            .collect();
    }
    let l = &m.layers[n - 1];
    (0..l.out)
        .map(|r| {
            let sum = l.b[r].abs()
                + (0..l.inp)
                    .map(|c| (l.w[r * l.inp + c] * a[c]).abs())
                    .sum::<f64>();
            m.out_center[r].abs() + m.out_half[r] * sum
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::Activation;

    /// A 2-8-8-1 net with seeded weights and a nonzero bias, over the pendulum's boxes.
    fn net(seed: u64) -> Mlp {
        let mut m = Mlp::new(
            &[2, 8, 8, 1],
            Activation::Tanh,
            seed,
            &[-1.0, -0.5],
            &[1.0, 0.5],
            &[-15.0],
            &[15.0],
        );
        for (k, l) in m.layers.iter_mut().enumerate() {
            for (i, b) in l.b.iter_mut().enumerate() {
                *b = 0.1 * crate::rng::uniform(seed, 100 + k as u64, i as u64) - 0.05;
            }
        }
        m
    }

    #[test]
    fn corrected_net_reproduces_the_label_and_keeps_its_slopes() {
        for seed in 0..50u64 {
            let mut m = net(seed);
            let x_ref = vec![
                0.6 * crate::rng::uniform(seed, 7, 0) - 0.3,
                0.2 * crate::rng::uniform(seed, 7, 1) - 0.1,
            ];
            let u = vec![3.0 * crate::rng::uniform(seed, 7, 2) - 1.5];
            let before = m.clone();
            let h = Hold { x_ref, u };
            let res = h.apply(&mut m);
            let got = m.predict(&h.x_ref)[0];
            // What f64 can resolve: the output u = o + s·(b + Σ w_i a_i) is a rounded sum,
            // exact to a few ulps of the magnitude of its terms.
            let tol = 4.0 * f64::EPSILON * output_rounding_scale(&m, &h.x_ref)[0];
            assert!(
                (got - h.u[0]).abs() <= tol,
                "seed {seed}: {got} vs {} (tolerance {tol:e})",
                h.u[0]
            );
            assert_eq!(res, (got - h.u[0]).abs());
            // Only the last bias moved; the net moved by the same constant everywhere.
            assert_eq!(m.layers[..2], before.layers[..2]);
            assert_eq!(m.layers[2].w, before.layers[2].w);
            let c = h.u[0] - before.predict(&h.x_ref)[0];
            for k in 0..20u64 {
                let x = [
                    2.0 * crate::rng::uniform(seed, 9, 2 * k) - 1.0,
                    crate::rng::uniform(seed, 9, 2 * k + 1) - 0.5,
                ];
                let shift = m.predict(&x)[0] - before.predict(&x)[0];
                assert!(
                    (shift - c).abs() <= 1e-12 * (1.0 + c.abs()),
                    "{shift} vs {c}"
                );
            }
        }
    }
}
