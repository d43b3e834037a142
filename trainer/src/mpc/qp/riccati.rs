//! The interior-point Newton system of the OCP's QP, factorised by a Riccati recursion (the
//! soft problem's slacks eliminated first, stage by stage: [`super::slacks`]).
//!
//! Owns [`RiccatiKkt`], the solver of
//! ```text
//! ⎡ H̃   Eᵀ ⎤ ⎡d⎤   ⎡r_d⎤
//! ⎣ E    0 ⎦ ⎣λ⎦ = ⎣r_e⎦ ,    H̃ = H + Gᵀ W G,
//! ```
//! with E the linearised constraints `x_0 = e_0`, `A_k x_k + B_k u_k − x_{k+1} = e_{k+1}` and
//! every inequality row inside one stage, so that H̃ is block diagonal with stage blocks
//! `[Q_k S_kᵀ; S_k R_k]` (terminal: Q_N). With `λ_k = P_k x_k − p_k` (k ≥ 1) the stationarity
//! rows of stage k give the backward recursion (HPIPM's, Frison & Diehl 2020, unconstrained
//! stage form)
//! ```text
//! P_N = Q_N,  R̃_k = R_k + B_kᵀ P_{k+1} B_k = L_k L_kᵀ,  S̃_k = S_k + B_kᵀ P_{k+1} A_k,
//! P_k = Q_k + A_kᵀ P_{k+1} A_k − S̃_kᵀ R̃_k⁻¹ S̃_k,
//! p_N = q_N,  v = P_{k+1} e_{k+1} + p_{k+1},  y_k = L_k⁻¹(r_k + B_kᵀ v),
//! p_k = q_k + A_kᵀ v − (L_k⁻¹ S̃_k)ᵀ y_k,
//! ```
//! ((q_k, r_k) the stage's part of r_d) and the forward pass `x_0 = e_0`,
//! `u_k = L_k⁻ᵀ(y_k − L_k⁻¹S̃_k x_k)`, `x_{k+1} = A_k x_k + B_k u_k − e_{k+1}`,
//! `λ_{k+1} = P_{k+1} x_{k+1} − p_{k+1}`, `λ_0 = p_0 − P_0 x_0`. Cost O(N(nx + nu)³) per
//! factorisation and O(N(nx + nu)²) per solve, against O(N·b²) and O(N·b) with the band
//! LU's half-bandwidth b ≈ 2nx + nu. The recursion needs every R̃_k positive definite, which
//! holds when the QP is strictly convex on the dynamics' null space (the SQP's Hessian
//! passes that test or is convexified block by block; Gᵀ W G ⪰ 0 only adds). A pivot below
//! `1e-13·max(1, |R̃_k[j, j]|)` (its own diagonal entry: an active bound weights one input's
//! entry by up to 1e14) reports failure and the caller uses the band LU instead.

use super::slacks::Slacks;
use crate::mpc::ocp::Ocp;

/// Relative size below which a Cholesky pivot of R̃_k counts as not positive.
const PIVOT_TOL: f64 = 1e-13;

/// Workspace of the Riccati factorisation for one OCP structure (hard problem only).
#[derive(Debug, Clone, Default)]
pub struct RiccatiKkt {
    nx: usize,
    nu: usize,
    n: usize,
    /// Rows of each stage without a slack (stage s: `rows_of[s]`).
    rows_of: Vec<Vec<usize>>,
    /// The soft problem's slacks, eliminated stage by stage (none for the hard problem).
    slacks: Slacks,
    /// P_k, k = 0..=N (nx × nx each).
    p: Vec<f64>,
    /// Cholesky factor L_k of R̃_k (nu × nu, lower), k < N.
    l: Vec<f64>,
    /// L_k⁻¹ S̃_k (nu × nx), k < N.
    st: Vec<f64>,
    /// The stage block H̃_k being formed (nz × nz).
    h: Vec<f64>,
    pa: Vec<f64>,
    pb: Vec<f64>,
    /// y_k (nu), k < N.
    y: Vec<f64>,
    /// p_k (nx), k = 0..=N.
    pv: Vec<f64>,
    v: Vec<f64>,
}

impl RiccatiKkt {
    /// Workspace for `ocp`, or `None` when the recursion does not apply: a row whose
    /// variables lie in two stages, or a slack of the soft problem in two stages' rows
    /// ([`super::slacks::split`]).
    pub fn new(ocp: &Ocp) -> Option<Self> {
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let nz = nx + nu;
        let (rows_of, slacks) = super::slacks::split(ocp)?;
        Some(RiccatiKkt {
            nx,
            nu,
            n,
            rows_of,
            slacks,
            p: vec![0.0; (n + 1) * nx * nx],
            l: vec![0.0; n * nu * nu],
            st: vec![0.0; n * nu * nx],
            h: vec![0.0; nz * nz],
            pa: vec![0.0; nx * nx],
            pb: vec![0.0; nx * nu],
            y: vec![0.0; n * nu],
            pv: vec![0.0; (n + 1) * nx],
            v: vec![0.0; nx],
        })
    }

    /// H̃_s = H_s + Σ_{r in stage s} w_r a_r a_rᵀ into `self.h`.
    fn stage_block(&mut self, ocp: &Ocp, hess: &[f64], w: &[f64], s: usize) {
        let nz = self.nx + self.nu;
        self.h
            .copy_from_slice(&hess[s * nz * nz..(s + 1) * nz * nz]);
        let off = s * nz;
        for &r in &self.rows_of[s] {
            let row = &ocp.rows[r];
            let wr = w[r];
            for a in 0..row.len {
                let (ia, ca) = (row.idx[a] - off, row.coef[a] * wr);
                for b in 0..row.len {
                    self.h[ia * nz + row.idx[b] - off] += ca * row.coef[b];
                }
            }
        }
        if !self.slacks.is_empty() {
            self.slacks.add_to_stage(ocp, w, s, &mut self.h);
        }
    }

    /// Factorises for the stage Hessian blocks `hess`, the dynamics Jacobians and the row
    /// weights `w`. Returns false if some R̃_k is not (numerically) positive definite.
    pub fn factor(
        &mut self,
        ocp: &Ocp,
        hess: &[f64],
        jac_x: &[f64],
        jac_u: &[f64],
        w: &[f64],
    ) -> bool {
        by_nx!(self.nx, self.factor_nx(ocp, hess, jac_x, jac_u, w))
    }

    /// [`RiccatiKkt::factor`] with the state dimension a constant `NX` (0: `self.nx`), and
    /// the input dimension a constant too for `nu ≤ 4`.
    pub(super) fn factor_nx<const NX: usize>(
        &mut self,
        ocp: &Ocp,
        hess: &[f64],
        jac_x: &[f64],
        jac_u: &[f64],
        w: &[f64],
    ) -> bool {
        match self.nu {
            1 => self.factor_k::<NX, 1>(ocp, hess, jac_x, jac_u, w),
            2 => self.factor_k::<NX, 2>(ocp, hess, jac_x, jac_u, w),
            3 => self.factor_k::<NX, 3>(ocp, hess, jac_x, jac_u, w),
            4 => self.factor_k::<NX, 4>(ocp, hess, jac_x, jac_u, w),
            _ => self.factor_k::<NX, 0>(ocp, hess, jac_x, jac_u, w),
        }
    }

    /// The factorisation with dimensions `NX`, `NU` (0: runtime sizes).
    #[inline(always)]
    fn factor_k<const NX: usize, const NU: usize>(
        &mut self,
        ocp: &Ocp,
        hess: &[f64],
        jac_x: &[f64],
        jac_u: &[f64],
        w: &[f64],
    ) -> bool {
        let nx = if NX == 0 { self.nx } else { NX };
        let nu = if NU == 0 { self.nu } else { NU };
        let n = self.n;
        let nz = nx + nu;
        self.stage_block(ocp, hess, w, n);
        for i in 0..nx {
            for j in 0..nx {
                self.p[n * nx * nx + i * nx + j] = self.h[i * nz + j];
            }
        }
        for k in (0..n).rev() {
            self.stage_block(ocp, hess, w, k);
            let a = &jac_x[k * nx * nx..(k + 1) * nx * nx];
            let b = &jac_u[k * nx * nu..(k + 1) * nx * nu];
            let (head, tail) = self.p.split_at_mut((k + 1) * nx * nx);
            let pn = &tail[..nx * nx];
            let pk = &mut head[k * nx * nx..];
            let (pa, pb, h) = (&mut self.pa, &mut self.pb, &self.h);
            // pa = P A, pb = P B. Every entry is summed over l in ascending order from 0 (the
            // bits of the dot-product form): P A row by row as axpys (contiguous,
            // vectorisable), P B as dot products (no loop over the runtime nu innermost).
            pa.fill(0.0);
            for (prow, parow) in pn.chunks_exact(nx).zip(pa.chunks_exact_mut(nx)) {
                for (&p, arow) in prow.iter().zip(a.chunks_exact(nx)) {
                    for (d, &v) in parow.iter_mut().zip(arow) {
                        *d += p * v;
                    }
                }
            }
            for (prow, pbrow) in pn.chunks_exact(nx).zip(pb.chunks_exact_mut(nu)) {
                for (j, d) in pbrow.iter_mut().enumerate() {
                    let mut acc = 0.0;
                    for (l, &p) in prow.iter().enumerate() {
                        acc += p * b[l * nu + j];
                    }
                    *d = acc;
                }
            }
            let lk = &mut self.l[k * nu * nu..(k + 1) * nu * nu];
            let st = &mut self.st[k * nu * nx..(k + 1) * nu * nx];
            // R̃ = R + Bᵀ P B (lower triangle), S̃ = S + Bᵀ P A; each entry summed over l in
            // ascending order from the Hessian's entry.
            for i in 0..nu {
                let hrow = &h[(nx + i) * nz..(nx + i + 1) * nz];
                lk[i * nu..i * nu + i + 1].copy_from_slice(&hrow[nx..nx + i + 1]);
                st[i * nx..(i + 1) * nx].copy_from_slice(&hrow[..nx]);
            }
            // (Input row i outermost: the l loop inside has the constant trip count nx.)
            for (i, strow) in st.chunks_exact_mut(nx).enumerate() {
                for ((brow, pbrow), parow) in b
                    .chunks_exact(nu)
                    .zip(pb.chunks_exact(nu))
                    .zip(pa.chunks_exact(nx))
                {
                    let bi = brow[i];
                    for (d, &v) in lk[i * nu..i * nu + i + 1].iter_mut().zip(pbrow) {
                        *d += bi * v;
                    }
                    for (d, &v) in strow.iter_mut().zip(parow) {
                        *d += bi * v;
                    }
                }
            }
            // Cholesky R̃ = L Lᵀ in place; pivot j is judged against its own diagonal entry
            // (an active bound on one input weights its entry by up to 1e14, and must not
            // make a well-scaled pivot of another input count as zero).
            for j in 0..nu {
                let mut d = lk[j * nu + j];
                let scale = d.abs().max(1.0);
                for l in 0..j {
                    d -= lk[j * nu + l] * lk[j * nu + l];
                }
                if d.is_nan() || d <= PIVOT_TOL * scale || !d.is_finite() {
                    return false;
                }
                let d = d.sqrt();
                lk[j * nu + j] = d;
                for i in j + 1..nu {
                    let mut v = lk[i * nu + j];
                    for l in 0..j {
                        v -= lk[i * nu + l] * lk[j * nu + l];
                    }
                    lk[i * nu + j] = v / d;
                }
            }
            // S̃ ← L⁻¹ S̃ (row i after rows l < i: each entry as column by column).
            for i in 0..nu {
                for c in 0..nx {
                    let mut v = st[i * nx + c];
                    for l in 0..i {
                        v -= lk[i * nu + l] * st[l * nx + c];
                    }
                    st[i * nx + c] = v / lk[i * nu + i];
                }
            }
            // P_k = Q + Aᵀ P A − S̃ᵀ R̃⁻¹ S̃ (upper triangle computed row by row as axpys,
            // each entry in the order Q, then l ascending; mirrored).
            for i in 0..nx {
                let row = &mut pk[i * nx + i..(i + 1) * nx];
                row.copy_from_slice(&h[i * nz + i..i * nz + nx]);
                for (arow, parow) in a.chunks_exact(nx).zip(pa.chunks_exact(nx)) {
                    let ali = arow[i];
                    for (d, &v) in row.iter_mut().zip(&parow[i..]) {
                        *d += ali * v;
                    }
                }
                for srow in st.chunks_exact(nx) {
                    let sli = srow[i];
                    for (d, &v) in row.iter_mut().zip(&srow[i..]) {
                        *d -= sli * v;
                    }
                }
            }
            for i in 0..nx {
                for j in i + 1..nx {
                    pk[j * nx + i] = pk[i * nx + j];
                }
            }
        }
        self.p.iter().all(|v| v.is_finite())
    }

    /// Solves the system for `rhs = (r_d, r_e)` in place (natural order `(d, λ)`), with the
    /// factors of the last successful [`RiccatiKkt::factor`].
    pub fn solve_in_place(&mut self, ocp: &Ocp, jac_x: &[f64], jac_u: &[f64], rhs: &mut [f64]) {
        by_nx!(self.nx, self.solve_nx(ocp, jac_x, jac_u, rhs))
    }

    /// [`RiccatiKkt::solve_in_place`] with the state dimension a constant `NX` (0: `self.nx`),
    /// and the input dimension a constant too for `nu ≤ 4`.
    pub(super) fn solve_nx<const NX: usize>(
        &mut self,
        ocp: &Ocp,
        jac_x: &[f64],
        jac_u: &[f64],
        rhs: &mut [f64],
    ) {
        match self.nu {
            1 => self.solve_k::<NX, 1>(ocp, jac_x, jac_u, rhs),
            2 => self.solve_k::<NX, 2>(ocp, jac_x, jac_u, rhs),
            3 => self.solve_k::<NX, 3>(ocp, jac_x, jac_u, rhs),
            4 => self.solve_k::<NX, 4>(ocp, jac_x, jac_u, rhs),
            _ => self.solve_k::<NX, 0>(ocp, jac_x, jac_u, rhs),
        }
    }

    /// The solve with dimensions `NX`, `NU` (0: runtime sizes).
    #[inline(always)]
    fn solve_k<const NX: usize, const NU: usize>(
        &mut self,
        ocp: &Ocp,
        jac_x: &[f64],
        jac_u: &[f64],
        rhs: &mut [f64],
    ) {
        let nx = if NX == 0 { self.nx } else { NX };
        let nu = if NU == 0 { self.nu } else { NU };
        let n = self.n;
        let nz = nx + nu;
        let nv = ocp.n_var;
        self.slacks.reduce(rhs);
        // Backward: p_N = q_N.
        self.pv[n * nx..(n + 1) * nx].copy_from_slice(&rhs[n * nz..n * nz + nx]);
        for k in (0..n).rev() {
            let a = &jac_x[k * nx * nx..(k + 1) * nx * nx];
            let b = &jac_u[k * nx * nu..(k + 1) * nx * nu];
            let pn = &self.p[(k + 1) * nx * nx..(k + 2) * nx * nx];
            let e = &rhs[nv + (k + 1) * nx..nv + (k + 2) * nx];
            let (head, tail) = self.pv.split_at_mut((k + 1) * nx);
            let pvn = &tail[..nx];
            // v = P e + p.
            for i in 0..nx {
                let mut acc = pvn[i];
                for j in 0..nx {
                    acc += pn[i * nx + j] * e[j];
                }
                self.v[i] = acc;
            }
            let lk = &self.l[k * nu * nu..(k + 1) * nu * nu];
            let st = &self.st[k * nu * nx..(k + 1) * nu * nx];
            let y = &mut self.y[k * nu..(k + 1) * nu];
            // y = L⁻¹(r + Bᵀ v).
            for i in 0..nu {
                let mut acc = rhs[k * nz + nx + i];
                for l in 0..nx {
                    acc += b[l * nu + i] * self.v[l];
                }
                for l in 0..i {
                    acc -= lk[i * nu + l] * y[l];
                }
                y[i] = acc / lk[i * nu + i];
            }
            // p_k = q + Aᵀ v − (L⁻¹S̃)ᵀ y.
            let pk = &mut head[k * nx..];
            for i in 0..nx {
                let mut acc = rhs[k * nz + i];
                for l in 0..nx {
                    acc += a[l * nx + i] * self.v[l];
                }
                for l in 0..nu {
                    acc -= st[l * nx + i] * y[l];
                }
                pk[i] = acc;
            }
        }
        // Forward: x_0 = e_0, λ_0 = p_0 − P_0 x_0.
        for i in 0..nx {
            rhs[i] = rhs[nv + i];
        }
        for i in 0..nx {
            let mut acc = self.pv[i];
            for j in 0..nx {
                acc -= self.p[i * nx + j] * rhs[j];
            }
            rhs[nv + i] = acc;
        }
        for k in 0..n {
            let a = &jac_x[k * nx * nx..(k + 1) * nx * nx];
            let b = &jac_u[k * nx * nu..(k + 1) * nx * nu];
            let lk = &self.l[k * nu * nu..(k + 1) * nu * nu];
            let st = &self.st[k * nu * nx..(k + 1) * nu * nx];
            let y = &self.y[k * nu..(k + 1) * nu];
            let (ix, iu, ixn) = (k * nz, k * nz + nx, (k + 1) * nz);
            // u = L⁻ᵀ(y − (L⁻¹S̃) x).
            for i in (0..nu).rev() {
                let mut acc = y[i];
                for j in 0..nx {
                    acc -= st[i * nx + j] * rhs[ix + j];
                }
                for l in i + 1..nu {
                    acc -= lk[l * nu + i] * rhs[iu + l];
                }
                rhs[iu + i] = acc / lk[i * nu + i];
            }
            // x_{k+1} = A x + B u − e_{k+1}.
            for r in 0..nx {
                let mut acc = -rhs[nv + (k + 1) * nx + r];
                for j in 0..nx {
                    acc += a[r * nx + j] * rhs[ix + j];
                }
                for j in 0..nu {
                    acc += b[r * nu + j] * rhs[iu + j];
                }
                rhs[ixn + r] = acc;
            }
            // λ_{k+1} = P_{k+1} x_{k+1} − p_{k+1}.
            let pn = &self.p[(k + 1) * nx * nx..(k + 2) * nx * nx];
            for i in 0..nx {
                let mut acc = -self.pv[(k + 1) * nx + i];
                for j in 0..nx {
                    acc += pn[i * nx + j] * rhs[ixn + j];
                }
                rhs[nv + (k + 1) * nx + i] = acc;
            }
        }
        self.slacks.recover(rhs);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mpc::kkt::{BandedKkt, KktLayout};
    use crate::problem::ProblemConfig;
    use crate::rng::uniform;

    fn load(name: &str) -> ProblemConfig {
        let path = std::path::PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../configs/"))
            .join(name);
        ProblemConfig::load(&path).unwrap()
    }

    /// The Riccati solve equals the band LU's on random convex data with random row weights,
    /// on the hard and the soft problems (slacks eliminated, [`super::super::slacks`]) of the
    /// cart-pole (nu = 1), the planar quadrotor (nu = 2; θ's slack in two rows), the
    /// 12-state chain (nu = 4) and the DC motor and the spring (path constraints in states,
    /// and in states and inputs, with their slacks; a terminal constraint).
    #[test]
    fn riccati_solve_matches_the_band_lu() {
        for (name, soft) in [
            "cartpole.toml",
            "planar_quadrotor.toml",
            "mass_chain12.toml",
            "dc_motor.toml",
            "stiff_spring_setpoint.toml",
        ]
        .into_iter()
        .flat_map(|n| [(n, false), (n, true)])
        {
            let cfg = load(name);
            let ocp = Ocp::new(&cfg, soft);
            if soft {
                assert!(ocp.n_slack > 0, "{name}");
            }
            let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
            let nz = nx + nu;
            let mut seed = 0u64;
            let mut rnd = |lo: f64, hi: f64| {
                seed += 1;
                lo + (hi - lo) * uniform(11, seed, 0)
            };
            // H_k = M Mᵀ + 0.1 I (symmetric positive definite), random A, B, weights.
            let mut hess = vec![0.0; (n + 1) * nz * nz];
            for s in 0..=n {
                let m: Vec<f64> = (0..nz * nz).map(|_| rnd(-1.0, 1.0)).collect();
                for i in 0..nz {
                    for j in 0..nz {
                        let v: f64 = (0..nz).map(|l| m[i * nz + l] * m[j * nz + l]).sum();
                        hess[s * nz * nz + i * nz + j] = v + if i == j { 0.1 } else { 0.0 };
                    }
                }
                if s == n {
                    for i in 0..nz {
                        for j in 0..nz {
                            if i >= nx || j >= nx {
                                hess[s * nz * nz + i * nz + j] = 0.0;
                            }
                        }
                    }
                }
            }
            let jx: Vec<f64> = (0..n * nx * nx).map(|_| rnd(-1.5, 1.5)).collect();
            let ju: Vec<f64> = (0..n * nx * nu).map(|_| rnd(-1.0, 1.0)).collect();
            let w: Vec<f64> = (0..ocp.rows.len()).map(|_| rnd(0.0, 100.0)).collect();
            let rhs: Vec<f64> = (0..ocp.n_var + ocp.n_eq).map(|_| rnd(-1.0, 1.0)).collect();
            let mut band = BandedKkt::new(KktLayout::new(&ocp, Vec::new()));
            assert!(band.set_base(&ocp, &hess, &jx, &ju));
            let ratio = band.factor_weighted(&w);
            assert!(ratio > 1e-14, "{name} {soft}: {ratio}");
            let mut want = rhs.clone();
            assert!(band.solve_in_place(&mut want, &mut Vec::new()));
            let mut ric = RiccatiKkt::new(&ocp).unwrap();
            assert!(ric.factor(&ocp, &hess, &jx, &ju, &w));
            let mut got = rhs.clone();
            ric.solve_in_place(&ocp, &jx, &ju, &mut got);
            let scale = want.iter().fold(1.0f64, |m, v| m.max(v.abs()));
            let err = want
                .iter()
                .zip(&got)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(err <= 1e-9 * scale, "{name} {soft}: {err} (scale {scale})");
        }
    }

    /// A heavily weighted input (an active bound's barrier weight, 1e15) beside a
    /// well-scaled one: each Cholesky pivot is judged against its own diagonal entry, so the
    /// factorisation is accepted (it was refused when the pivots were judged against the
    /// largest diagonal entry of R̃_k) and its solve matches the band LU's.
    #[test]
    fn riccati_accepts_a_well_scaled_pivot_beside_a_heavily_weighted_input() {
        let cfg = load("planar_quadrotor.toml");
        let ocp = Ocp::new(&cfg, false);
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let nz = nx + nu;
        let mut hess = vec![0.0; (n + 1) * nz * nz];
        for s in 0..=n {
            for i in 0..if s < n { nz } else { nx } {
                hess[s * nz * nz + i * nz + i] = 1.0;
            }
        }
        let jx = vec![0.0; n * nx * nx];
        let ju = vec![0.0; n * nx * nu];
        let mut w = vec![0.0; ocp.rows.len()];
        let row = ocp
            .rows
            .iter()
            .position(|r| r.len == 1 && r.idx[0] == ocp.iu(0))
            .unwrap();
        w[row] = 1e15;
        let mut ric = RiccatiKkt::new(&ocp).unwrap();
        assert!(ric.factor(&ocp, &hess, &jx, &ju, &w));
        let rhs: Vec<f64> = (0..ocp.n_var + ocp.n_eq)
            .map(|i| uniform(3, i as u64, 0) - 0.5)
            .collect();
        let mut got = rhs.clone();
        ric.solve_in_place(&ocp, &jx, &ju, &mut got);
        let mut band = BandedKkt::new(KktLayout::new(&ocp, Vec::new()));
        assert!(band.set_base(&ocp, &hess, &jx, &ju));
        assert!(band.factor_weighted(&w) > 0.0);
        let mut want = rhs;
        assert!(band.solve_in_place(&mut want, &mut Vec::new()));
        let err = want
            .iter()
            .zip(&got)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(err <= 1e-12, "{err}");
    }

    /// An indefinite input block is refused (the caller then uses the band LU).
    #[test]
    fn riccati_refuses_an_indefinite_reduced_hessian() {
        let cfg = load("pendulum.toml");
        let ocp = Ocp::new(&cfg, false);
        let (nx, nu, n) = (ocp.nx, ocp.nu, ocp.horizon);
        let nz = nx + nu;
        let mut hess = vec![0.0; (n + 1) * nz * nz];
        for s in 0..n {
            hess[s * nz * nz + nx * nz + nx] = -1.0;
        }
        let jx = vec![0.0; n * nx * nx];
        let ju = vec![0.0; n * nx * nu];
        let w = vec![0.0; ocp.rows.len()];
        let mut ric = RiccatiKkt::new(&ocp).unwrap();
        assert!(!ric.factor(&ocp, &hess, &jx, &ju, &w));
    }

    /// The SQP with the Riccati factorisation reaches the same solutions as with the band
    /// LU: the optimal u₀ of cold solves of random cart-pole and quadrotor states agree to
    /// 1e-9, and a Gymnasium cart-pole state whose hard solve is infeasible from the cold
    /// start, then re-solved from the soft optimum (as `MpcLaw` does), converges with both;
    /// the soft optimum itself is the same with both (to 1e-7).
    #[test]
    fn sqp_with_riccati_matches_sqp_with_band_lu() {
        use crate::mpc::sqp::{PrimalDual, SqpSolver, SqpStatus};
        for name in ["cartpole.toml", "planar_quadrotor.toml"] {
            let cfg = load(name);
            let (mut a, mut b) = (SqpSolver::new(&cfg, false), SqpSolver::new(&cfg, false));
            b.without_riccati();
            for i in 0..10u64 {
                let x: Vec<f64> = (0..cfg.system.nx())
                    .map(|j| {
                        let (lo, hi) = (cfg.domain.lo[j], cfg.domain.hi[j]);
                        lo + (hi - lo) * uniform(5, i, j as u64)
                    })
                    .collect();
                let ra = a.solve(&x, a.cold_start(&x));
                let rb = b.solve(&x, b.cold_start(&x));
                assert_eq!(ra.status, rb.status, "{name} {x:?}");
                if ra.status == SqpStatus::Converged {
                    let iu = a.ocp.iu(0);
                    let d = (ra.point.z[iu] - rb.point.z[iu]).abs();
                    assert!(
                        d <= 1e-9 * (1.0 + rb.point.z[iu].abs()),
                        "{name} {x:?}: {d}"
                    );
                }
            }
        }
        let cfg = load("cartpole_public.toml");
        let x = [
            1.438790191344952,
            1.324773908567753,
            -0.08079984530966929,
            0.9398151471643426,
        ];
        let mut soft = SqpSolver::new(&cfg, true);
        let s = soft.solve(&x, soft.cold_start(&x));
        assert_eq!(s.status, SqpStatus::Converged);
        // The soft problem's QPs by Riccati (slacks eliminated) and by the band LU reach
        // the same soft optimum.
        let mut band = SqpSolver::new(&cfg, true);
        band.without_riccati();
        let sb = band.solve(&x, band.cold_start(&x));
        assert_eq!(sb.status, SqpStatus::Converged);
        let d = s
            .point
            .z
            .iter()
            .zip(&sb.point.z)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs() / (1.0 + b.abs())));
        assert!(d <= 1e-7, "soft optima differ by {d}");
        for riccati in [true, false] {
            let mut h = SqpSolver::new(&cfg, false);
            if !riccati {
                h.without_riccati();
            }
            assert_eq!(h.solve(&x, h.cold_start(&x)).status, SqpStatus::Infeasible);
            let start = PrimalDual {
                z: s.point.z[..h.ocp.n_var].to_vec(),
                lam: s.point.lam.clone(),
                nu: vec![0.0; h.ocp.rows.len()],
            };
            assert_eq!(h.solve(&x, start).status, SqpStatus::Converged, "{riccati}");
        }
    }
}
