//! [`Slacks`]: the soft problem's slacks eliminated stage by stage, so that the Riccati
//! recursion ([`super::riccati`]) factorises the soft problem's QPs as well as the hard
//! one's.
//!
//! In the soft problem each slack σ enters rows of one stage k (`aᵀz_k + c σ ≤ h`, c = −1)
//! and rows of its own (σ ≥ 0), and the objective with the curvature sc = 2·l2. In
//! `H̃ = H + Gᵀ W G` its row and column are
//! ```text
//! D_σ = sc + Σ_{rows r ∋ σ} w_r c_r²         (diagonal),
//! g_σ = Σ_{stage rows r ∋ σ} w_r c_r a_r      (coupling to stage k's variables),
//! ```
//! and nothing else. Eliminating σ (a Schur complement on a 1 × 1 block) leaves stage k's
//! block `H̃_k − g_σ g_σᵀ / D_σ` and right-hand side `r_k − g_σ r_σ / D_σ`; after the solve,
//! `Δσ = (r_σ − g_σᵀ Δz_k) / D_σ`. Stage k's block gets `Σ_r w_r a_r a_rᵀ − g gᵀ/D`, formed
//! without cancellation (the weights w = ν/t reach 1e14 as μ → 0, where the plain
//! difference loses every digit): with ω_r = w_r c_r², b_r = a_r / c_r and e = D − Σ_r ω_r
//! (sc and the slack's own rows),
//! ```text
//! Σ_r ω_r b_r b_rᵀ − (Σ_r ω_r b_r)(Σ_r ω_r b_r)ᵀ / D
//!     = [ e Σ_r ω_r b_r b_rᵀ + Σ_{r<q} ω_r ω_q (b_r − b_q)(b_r − b_q)ᵀ ] / D,
//! ```
//! a sum of positive semidefinite terms (from W·Σ ω b bᵀ − (Σ ω b)(Σ ω b)ᵀ =
//! Σ_{r<q} ω_r ω_q (b_r − b_q)(b_r − b_q)ᵀ, W = Σ ω_r).

use crate::mpc::ocp::{Ocp, MAX_ROW};

/// One slack: its variable, its stage and its rows.
#[derive(Debug, Clone, Default)]
struct Slack {
    /// Index of σ in z.
    var: usize,
    /// Rows with stage variables: (row, σ's coefficient c_r).
    stage_rows: Vec<(usize, f64)>,
    /// Rows in σ alone: (row, coefficient).
    own_rows: Vec<(usize, f64)>,
}

/// The slacks of an OCP grouped by stage, with the coupling of the last factorisation.
#[derive(Debug, Clone, Default)]
pub struct Slacks {
    nx: usize,
    nz: usize,
    /// The horizon N (stage N holds x_N only).
    n: usize,
    /// Slacks of each stage (indices into `slacks`).
    of_stage: Vec<Vec<usize>>,
    slacks: Vec<Slack>,
    /// D_σ of the last factorisation, per slack.
    d: Vec<f64>,
    /// g_σ of the last factorisation in stage coordinates (nz per slack).
    g: Vec<f64>,
}

/// How the rows of an OCP split for the Riccati recursion: rows in one stage's variables
/// (per stage) and the slacks, or `None` when some row spans two stages, holds two slacks,
/// or a slack has no row in a stage or rows in two.
pub(super) fn split(ocp: &Ocp) -> Option<(Vec<Vec<usize>>, Slacks)> {
    let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
    let nz = nx + nu;
    let nw = ocp.is();
    let mut rows_of = vec![Vec::new(); n + 1];
    let mut slacks: Vec<Slack> = (nw..ocp.n_var)
        .map(|var| Slack {
            var,
            ..Slack::default()
        })
        .collect();
    let mut stage_of_slack: Vec<Option<usize>> = vec![None; ocp.n_slack];
    for (r, row) in ocp.rows.iter().enumerate() {
        let entries = row.idx[..row.len].iter().zip(&row.coef[..row.len]);
        let mut stage = None;
        let mut slack = None;
        for (&i, &c) in entries {
            if i >= ocp.n_var {
                return None;
            }
            if i >= nw {
                if slack.is_some() {
                    return None;
                }
                slack = Some((i - nw, c));
            } else if *stage.get_or_insert(i / nz) != i / nz {
                return None;
            }
        }
        match (stage, slack) {
            (Some(s), None) => rows_of[s].push(r),
            (Some(s), Some((j, c))) => {
                if *stage_of_slack[j].get_or_insert(s) != s || c == 0.0 {
                    return None;
                }
                slacks[j].stage_rows.push((r, c));
            }
            (None, Some((j, c))) => slacks[j].own_rows.push((r, c)),
            (None, None) => {}
        }
    }
    let mut of_stage = vec![Vec::new(); n + 1];
    for (j, s) in stage_of_slack.iter().enumerate() {
        of_stage[(*s)?].push(j);
    }
    let m = slacks.len();
    Some((
        rows_of,
        Slacks {
            nx,
            nz,
            n,
            of_stage,
            slacks,
            d: vec![0.0; m],
            g: vec![0.0; m * nz],
        },
    ))
}

impl Slacks {
    /// The first index and the number of stage `s`'s variables (x_N alone at s = N).
    fn span(&self, s: usize) -> (usize, usize) {
        (s * self.nz, if s < self.n { self.nz } else { self.nx })
    }

    /// Subtracts the Schur complement of stage `s`'s slacks from the stage block `h` (nz ×
    /// nz, stage coordinates; its rows without slacks already added) for the row weights
    /// `w`, and keeps D_σ, g_σ for [`reduce`](Self::reduce) and [`recover`](Self::recover).
    /// The slacks' rows' own `w_r a_r a_rᵀ` are included, in the cancellation-free form of
    /// the module doc.
    pub(super) fn add_to_stage(&mut self, ocp: &Ocp, w: &[f64], s: usize, h: &mut [f64]) {
        let nz = self.nz;
        let (off, size) = self.span(s);
        // Stage coordinate of z index i, if i is one of stage s's variables.
        let local = |i: usize| (i >= off && i < off + size).then(|| i - off);
        let sc = ocp.slack_curvature();
        for &j in &self.of_stage[s] {
            let sl = &self.slacks[j];
            let e = sc + sl.own_rows.iter().map(|&(r, c)| w[r] * c * c).sum::<f64>();
            let omega: f64 = sl.stage_rows.iter().map(|&(r, c)| w[r] * c * c).sum();
            let d = e + omega;
            self.d[j] = d;
            let g = &mut self.g[j * nz..(j + 1) * nz];
            g.fill(0.0);
            for &(r, c) in &sl.stage_rows {
                let row = &ocp.rows[r];
                for a in 0..row.len {
                    if let Some(ia) = local(row.idx[a]) {
                        g[ia] += w[r] * c * row.coef[a];
                    }
                }
            }
            // e Σ_r ω_r b_r b_rᵀ / D = e Σ_r w_r a_r a_rᵀ / D.
            for &(r, _) in &sl.stage_rows {
                let row = &ocp.rows[r];
                let f = e * w[r] / d;
                for a in 0..row.len {
                    let Some(ia) = local(row.idx[a]) else {
                        continue;
                    };
                    for b in 0..row.len {
                        if let Some(ib) = local(row.idx[b]) {
                            h[ia * nz + ib] += f * row.coef[a] * row.coef[b];
                        }
                    }
                }
            }
            // Σ_{r<q} ω_r ω_q (b_r − b_q)(b_r − b_q)ᵀ / D.
            for (i, &(r, cr)) in sl.stage_rows.iter().enumerate() {
                for &(q, cq) in &sl.stage_rows[i + 1..] {
                    let f = w[r] * cr * cr * w[q] * cq * cq / d;
                    let mut diff = [0.0; 2 * MAX_ROW];
                    let mut idx = [0usize; 2 * MAX_ROW];
                    let mut len = 0;
                    for (row, c, sign) in [(&ocp.rows[r], cr, 1.0), (&ocp.rows[q], cq, -1.0)] {
                        for a in 0..row.len {
                            let Some(ia) = local(row.idx[a]) else {
                                continue;
                            };
                            let v = sign * row.coef[a] / c;
                            match idx[..len].iter().position(|&k| k == ia) {
                                Some(p) => diff[p] += v,
                                None => {
                                    idx[len] = ia;
                                    diff[len] = v;
                                    len += 1;
                                }
                            }
                        }
                    }
                    for a in 0..len {
                        for b in 0..len {
                            h[idx[a] * nz + idx[b]] += f * diff[a] * diff[b];
                        }
                    }
                }
            }
        }
    }

    /// Before the recursion's solve: `r_k ← r_k − g_σ r_σ / D_σ` for every slack (`rhs` in
    /// the natural order (d, λ)).
    pub(super) fn reduce(&self, rhs: &mut [f64]) {
        for (s, js) in self.of_stage.iter().enumerate() {
            let (off, size) = self.span(s);
            for &j in js {
                let f = rhs[self.slacks[j].var] / self.d[j];
                let g = &self.g[j * self.nz..j * self.nz + size];
                for (r, &gi) in rhs[off..off + size].iter_mut().zip(g) {
                    *r -= gi * f;
                }
            }
        }
    }

    /// After the recursion's solve: `Δσ = (r_σ − g_σᵀ Δz_k) / D_σ` into σ's entry of `rhs`
    /// (which still holds r_σ).
    pub(super) fn recover(&self, rhs: &mut [f64]) {
        for (s, js) in self.of_stage.iter().enumerate() {
            let (off, size) = self.span(s);
            for &j in js {
                let g = &self.g[j * self.nz..j * self.nz + size];
                let gz: f64 = rhs[off..off + size].iter().zip(g).map(|(a, b)| a * b).sum();
                let v = self.slacks[j].var;
                rhs[v] = (rhs[v] - gz) / self.d[j];
            }
        }
    }

    /// Whether there are no slacks (the hard problem).
    pub(super) fn is_empty(&self) -> bool {
        self.slacks.is_empty()
    }
}
