//! `[ocp.online_check]`: [`OnlineCheck`], the safety-augmented controller's online check
//! (`controller_core::safe`, issue 41) imposed on the MPC, so that the MPC's optimal input
//! sequence passes the device's check wherever the OCP is feasible — the terminal
//! ingredients of Hose et al. (TCST 2025) shared by the OCP that labels the data and the check
//! that accepts a sequence online:
//!
//! ```text
//! (x_N − x_c)ᵀ P_f (x_N − x_c) ≤ α_c                     terminal set (α_c below the check's α)
//! x_lo + b_s ≤ x_k ≤ x_hi − b_s        k = 1 … N−1        state box, the check's stage margin
//! x_lo + b_f ≤ x_N ≤ x_hi − b_f                           state box, the check's terminal margin
//! V_f(x_N) = (x_N − x_r)ᵀ V (x_N − x_r)                   replaces `ocp.p` (the check's cost)
//! ```
//!
//! `trainer run` fills it when `[closed_loop] safety = true` and `safety_terminal` is on (the
//! default) from the generated safe plant's terminal set, terminal cost and margins
//! (`pipeline::safety::labelling_problem`); it can also be written by hand. Only the MPC reads
//! it, through [`ProblemConfig::mpc_problem`] (the OCP the SQP transcribes): the generated
//! device plant, the terminal design, the closed-loop violation count and every other reader
//! of `[ocp]` see the problem without it, so the check itself is never changed by it. It is part
//! of the problem hash (the labels depend on it).

use super::{MatrixSpec, ProblemConfig, StageBounds};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// The online check imposed on the MPC (module doc).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OnlineCheck {
    /// Centre x_c of the terminal set (nx entries).
    pub centre: Vec<f64>,
    /// P_f: the terminal set's matrix (nx × nx, symmetric positive semidefinite).
    pub p_f: Vec<Vec<f64>>,
    /// α_c: the level imposed on x_N (finite, > 0).
    pub alpha: f64,
    /// V: the terminal cost's matrix, replacing `ocp.p` in the MPC's objective (nx × nx).
    pub terminal_cost: Vec<Vec<f64>>,
    /// b_s: how far inside the state box x_1 … x_{N−1} must stay, per state (physical units,
    /// finite, ≥ 0).
    pub stage_box_margin: Vec<f64>,
    /// b_f: how far inside the state box x_N must stay, per state.
    pub terminal_box_margin: Vec<f64>,
}

impl OnlineCheck {
    /// The terminal set as an `[ocp] terminal_constraints` expression over the state names
    /// `names`: `Σ P_ij (x_i − c_i)(x_j − c_j) <= α_c` (zero entries left out).
    pub fn constraint_text(&self, names: &[String]) -> String {
        let mut terms = Vec::new();
        for (i, row) in self.p_f.iter().enumerate() {
            for (j, w) in row.iter().enumerate() {
                if *w != 0.0 {
                    terms.push(format!(
                        "({w:e}) * ({} - ({:e})) * ({} - ({:e}))",
                        names[i], self.centre[i], names[j], self.centre[j]
                    ));
                }
            }
        }
        if terms.is_empty() {
            terms.push("0".into());
        }
        format!("{} <= {:e}", terms.join(" + "), self.alpha)
    }
}

impl ProblemConfig {
    /// The OCP the MPC solves: the problem itself without `ocp.online_check`; with it, a copy
    /// whose terminal weight is the check's V, whose state bounds are tightened by b_s
    /// (k = 1 … N−1) and b_f (k = N) as stage-dependent bounds (on top of `ocp.stages` when
    /// present), and whose terminal constraints end with the terminal set (module doc). The
    /// copy has no `online_check`, so this is idempotent.
    pub fn mpc_problem(&self) -> Cow<'_, ProblemConfig> {
        let Some(c) = &self.ocp.online_check else {
            return Cow::Borrowed(self);
        };
        let mut m = self.clone();
        let o = &self.ocp;
        let n = o.horizon;
        let tighten = |k: usize| -> (Vec<f64>, Vec<f64>) {
            let b = if k == n {
                &c.terminal_box_margin
            } else {
                &c.stage_box_margin
            };
            let (lo, hi) = o.x_bounds(k);
            (
                lo.iter().zip(b).map(|(l, b)| l + b).collect(),
                hi.iter().zip(b).map(|(h, b)| h - b).collect(),
            )
        };
        let (x_lo, x_hi): (Vec<_>, Vec<_>) = (1..=n).map(tighten).unzip();
        m.ocp.stages = Some(StageBounds {
            x_lo,
            x_hi,
            u_lo: (0..n).map(|k| o.u_bounds(k).0.to_vec()).collect(),
            u_hi: (0..n).map(|k| o.u_bounds(k).1.to_vec()).collect(),
            margins: o.stages.as_ref().map_or(vec![], |s| s.margins.clone()),
        });
        m.ocp.p = MatrixSpec::Full(c.terminal_cost.clone());
        m.ocp
            .terminal_constraints
            .push(c.constraint_text(&self.system.names().states));
        m.ocp.online_check = None;
        Cow::Owned(m)
    }

    /// `ocp.online_check`: dimensions, finite entries, α_c > 0, margins ≥ 0 and smaller than
    /// half the box they tighten, P_f and V symmetric positive semidefinite.
    pub(super) fn validate_online_check(&self) -> Result<(), super::ConfigError> {
        use super::{check_matrix, invalid};
        let Some(c) = &self.ocp.online_check else {
            return Ok(());
        };
        let nx = self.system.nx();
        let key = "ocp.online_check";
        if c.centre.len() != nx || c.centre.iter().any(|v| !v.is_finite()) {
            return Err(invalid(
                format!("{key}.centre"),
                format!("expected {nx} finite entries"),
            ));
        }
        check_matrix(
            &format!("{key}.p_f"),
            &MatrixSpec::Full(c.p_f.clone()),
            nx,
            false,
        )?;
        check_matrix(
            &format!("{key}.terminal_cost"),
            &MatrixSpec::Full(c.terminal_cost.clone()),
            nx,
            false,
        )?;
        if !(c.alpha.is_finite() && c.alpha > 0.0) {
            return Err(invalid(
                format!("{key}.alpha"),
                format!("must be finite and > 0, got {}", c.alpha),
            ));
        }
        let o = &self.ocp;
        for (name, b) in [
            ("stage_box_margin", &c.stage_box_margin),
            ("terminal_box_margin", &c.terminal_box_margin),
        ] {
            if b.len() != nx {
                return Err(invalid(
                    format!("{key}.{name}"),
                    format!("expected {nx} entries, got {}", b.len()),
                ));
            }
            for (i, v) in b.iter().enumerate() {
                let half = 0.5 * (o.x_hi[i] - o.x_lo[i]);
                if !(v.is_finite() && *v >= 0.0 && (*v < half || !half.is_finite())) {
                    return Err(invalid(
                        format!("{key}.{name}[{i}]"),
                        format!(
                            "must be finite, ≥ 0 and below half the state box's width, got {v}"
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(nx: usize) -> OnlineCheck {
        OnlineCheck {
            centre: vec![0.0; nx],
            p_f: (0..nx)
                .map(|i| (0..nx).map(|j| f64::from(u8::from(i == j)) * 2.0).collect())
                .collect(),
            alpha: 0.5,
            terminal_cost: (0..nx)
                .map(|i| (0..nx).map(|j| f64::from(u8::from(i == j)) * 3.0).collect())
                .collect(),
            stage_box_margin: vec![0.01; nx],
            terminal_box_margin: vec![0.02; nx],
        }
    }

    /// Without the block the MPC's problem is the problem itself; with it, the copy carries
    /// the tightened bounds per stage, V as P, the terminal set as the last terminal
    /// constraint (which compiles and measures 2·|x|² − 0.5), and no block (idempotent).
    #[test]
    fn the_mpc_problem_carries_the_check() {
        let mut cfg = ProblemConfig::default();
        assert!(matches!(cfg.mpc_problem(), Cow::Borrowed(_)));
        cfg.ocp.online_check = Some(check(2));
        cfg.validate().unwrap();
        let m = cfg.mpc_problem().into_owned();
        assert!(m.ocp.online_check.is_none());
        assert_eq!(m.mpc_problem().as_ref(), &m);
        let n = cfg.ocp.horizon;
        for k in 1..=n {
            let (lo, hi) = m.ocp.x_bounds(k);
            let b = if k == n { 0.02 } else { 0.01 };
            for i in 0..2 {
                let (l0, h0) = (cfg.ocp.x_lo[i], cfg.ocp.x_hi[i]);
                assert_eq!(lo[i], l0 + b, "stage {k}");
                assert_eq!(hi[i], h0 - b, "stage {k}");
            }
        }
        assert_eq!(m.ocp.u_bounds(0).0, &cfg.ocp.u_lo[..]);
        assert_eq!(m.p()[(1, 1)], 3.0);
        let cs = m.constraint_set().unwrap().unwrap();
        let last = cs.items.len() - 1;
        assert!(cs.items[last].terminal);
        let x = [0.3, -0.4];
        let mut g = vec![0.0f64; cs.len()];
        cs.eval(&x, &[0.0], &mut g, &mut Vec::new());
        assert!((g[last] - (2.0 * 0.25 - 0.5)).abs() < 1e-12, "{g:?}");
        m.validate().unwrap();
    }

    type Case = (Box<dyn Fn(&mut OnlineCheck)>, &'static str);

    /// Bad blocks are refused naming the key.
    #[test]
    fn a_bad_block_names_its_key() {
        let mut cfg = ProblemConfig::default();
        let cases: Vec<Case> = vec![
            (Box::new(|c| c.alpha = 0.0), "ocp.online_check.alpha"),
            (
                Box::new(|c| c.centre.pop().map(|_| ()).unwrap_or(())),
                "ocp.online_check.centre",
            ),
            (Box::new(|c| c.p_f[0][0] = -1.0), "ocp.online_check.p_f"),
            (
                Box::new(|c| c.stage_box_margin[1] = f64::NAN),
                "ocp.online_check.stage_box_margin[1]",
            ),
            (
                Box::new(|c| c.terminal_box_margin = vec![0.0]),
                "ocp.online_check.terminal_box_margin",
            ),
        ];
        for (f, key) in cases {
            let mut c = check(2);
            f(&mut c);
            cfg.ocp.online_check = Some(c);
            let e = cfg.validate().unwrap_err().to_string();
            assert!(e.contains(key), "{key}: {e}");
        }
    }
}
