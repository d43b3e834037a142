//! Sound enclosures of the network κ_NN, its Jacobian ∂κ_NN/∂x and the diagonal of its
//! Hessians ∂²κ_NN/∂x_j² over a box C = [lo, hi] of states, by interval bound propagation.
//!
//! With the physical-unit layers `z_j = W̃_j a_{j−1} + b̃_j`, `a_j = α(z_j)` and, along the
//! coordinate direction e_k, the first and second directional derivatives
//! ```text
//! t_0 = e_k,  s_0 = 0
//! dz_j = W̃_j t_{j−1},  d2z_j = W̃_j s_{j−1}
//! t_j = α′(z_j)·dz_j,  s_j = α″(z_j)·dz_j² + α′(z_j)·d2z_j
//! ∂κ_NN/∂x_k = W̃_m t_{m−1},  ∂²κ_NN/∂x_k² = W̃_m s_{m−1}
//! ```
//! every quantity is replaced by an interval that contains its value for every x ∈ C:
//! point matrix × interval vector is exact per entry (positive and negative weights take
//! opposite endpoints), α, α′, α″ are enclosed on an interval from their monotonicity
//! pieces (tanh: α′ is unimodal with its peak at 0, α″ has extrema at ±atanh(1/√3);
//! softplus: α′ is monotone, α″ unimodal), products and squares of intervals use the
//! endpoint rules. Every computed endpoint is widened outward by a relative 2⁻⁵⁰ plus
//! 10⁻³⁰⁰, which covers the round-to-nearest error of each operation, so the enclosures are
//! sound in floating point and not only in exact arithmetic.
//!
//! Intervals lose correlations (the "dependency problem"), so the enclosures are loose for
//! wide boxes; their width shrinks linearly with the box. The value enclosure is also
//! tightened by the mean-value form `κ_NN(mid) + Σ_k [∂_k] (x_k − mid_k)`.
//! ReLU has no second derivative at its kink: for a box on which a ReLU pre-activation
//! changes sign the Hessian enclosure is `None`.

use crate::learn::mlp::{Activation, Layer, Mlp};

/// A closed interval [lo, hi].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Iv {
    /// Lower end.
    pub lo: f64,
    /// Upper end.
    pub hi: f64,
}

const REL: f64 = 1.0 / (1u64 << 50) as f64;
const ABS: f64 = 1e-300;

#[inline]
fn down(v: f64) -> f64 {
    v - (v.abs() * REL + ABS)
}
#[inline]
fn up(v: f64) -> f64 {
    v + (v.abs() * REL + ABS)
}

impl Iv {
    /// The interval [lo, hi] widened outward by one rounding error.
    #[inline]
    pub fn new(lo: f64, hi: f64) -> Self {
        Iv {
            lo: down(lo),
            hi: up(hi),
        }
    }
    /// The degenerate interval [v, v] (exact).
    #[inline]
    pub fn point(v: f64) -> Self {
        Iv { lo: v, hi: v }
    }
    /// Largest absolute value.
    #[inline]
    pub fn mag(&self) -> f64 {
        self.lo.abs().max(self.hi.abs())
    }
    /// Width hi − lo.
    #[inline]
    pub fn width(&self) -> f64 {
        self.hi - self.lo
    }
    /// Whether v ∈ [lo, hi].
    #[inline]
    pub fn contains(&self, v: f64) -> bool {
        self.lo <= v && v <= self.hi
    }
    #[inline]
    fn add(self, o: Iv) -> Iv {
        Iv::new(self.lo + o.lo, self.hi + o.hi)
    }
    #[inline]
    fn mul(self, o: Iv) -> Iv {
        let p = [
            self.lo * o.lo,
            self.lo * o.hi,
            self.hi * o.lo,
            self.hi * o.hi,
        ];
        let (mut lo, mut hi) = (p[0], p[0]);
        for &v in &p[1..] {
            lo = lo.min(v);
            hi = hi.max(v);
        }
        Iv::new(lo, hi)
    }
    #[inline]
    fn sqr(self) -> Iv {
        if self.lo >= 0.0 {
            Iv::new(self.lo * self.lo, self.hi * self.hi)
        } else if self.hi <= 0.0 {
            Iv::new(self.hi * self.hi, self.lo * self.lo)
        } else {
            Iv::new(0.0, self.mag() * self.mag())
        }
    }
    #[inline]
    fn intersect(self, o: Iv) -> Iv {
        Iv {
            lo: self.lo.max(o.lo),
            hi: self.hi.min(o.hi),
        }
    }
}

/// `b + W v` for a point matrix (row-major out × inp) and an interval vector.
fn affine(w: &[f64], b: Option<&[f64]>, v: &[Iv], out: &mut Vec<Iv>) {
    let inp = v.len();
    out.clear();
    for (r, row) in w.chunks_exact(inp).enumerate() {
        let (mut lo, mut hi, mut mag) = b.map_or((0.0, 0.0, 0.0), |b| (b[r], b[r], b[r].abs()));
        for (&wc, vc) in row.iter().zip(v) {
            if wc >= 0.0 {
                lo += wc * vc.lo;
                hi += wc * vc.hi;
            } else {
                lo += wc * vc.hi;
                hi += wc * vc.lo;
            }
            mag += wc.abs() * vc.mag();
        }
        // Accumulated rounding of an (inp + 1)-term sum: ≤ (inp + 1)·u·Σ|terms|.
        let err = (inp as f64 + 2.0) * f64::EPSILON * mag + ABS;
        out.push(Iv::new(lo - err, hi + err));
    }
}

/// Enclosures of (α, α′, α″) over the interval z; α″ is `None` where it does not exist.
fn act_bounds(act: Activation, z: Iv) -> (Iv, Iv, Option<Iv>) {
    let (a_lo, d_lo, dd_lo) = act.eval(z.lo);
    let (a_hi, d_hi, dd_hi) = act.eval(z.hi);
    // α is non-decreasing for all three activations.
    let a = Iv::new(a_lo, a_hi);
    match act {
        Activation::Tanh => {
            // α′ = 1 − tanh²: increasing on (−∞, 0], decreasing on [0, ∞).
            let d = if z.lo <= 0.0 && z.hi >= 0.0 {
                Iv::new(d_lo.min(d_hi), 1.0)
            } else {
                Iv::new(d_lo.min(d_hi), d_lo.max(d_hi))
            };
            // α″ = −2 tanh (1 − tanh²): extrema ±4/(3√3) at z = ∓atanh(1/√3).
            let zs = (1.0 / 3f64.sqrt()).atanh();
            let peak = 4.0 / (3.0 * 3f64.sqrt());
            let mut lo = dd_lo.min(dd_hi);
            let mut hi = dd_lo.max(dd_hi);
            if z.lo <= -zs && -zs <= z.hi {
                hi = hi.max(peak);
            }
            if z.lo <= zs && zs <= z.hi {
                lo = lo.min(-peak);
            }
            // A little extra on the transcendental evaluations.
            let slack = 1e-14;
            (
                Iv::new(a.lo - slack, a.hi + slack),
                Iv::new(d.lo - slack, d.hi + slack),
                Some(Iv::new(lo - slack, hi + slack)),
            )
        }
        Activation::Softplus => {
            // α′ = sigmoid, increasing; α″ = s(1 − s): increasing up to z = 0, then decreasing.
            let d = Iv::new(d_lo, d_hi);
            let dd = if z.lo <= 0.0 && z.hi >= 0.0 {
                Iv::new(dd_lo.min(dd_hi), 0.25)
            } else {
                Iv::new(dd_lo.min(dd_hi), dd_lo.max(dd_hi))
            };
            let slack = 1e-14;
            (
                Iv::new(a.lo - slack, a.hi + slack),
                Iv::new(d.lo - slack, d.hi + slack),
                Some(Iv::new(dd.lo - slack, dd.hi + slack)),
            )
        }
        Activation::Relu => {
            if z.hi <= 0.0 {
                (a, Iv::point(0.0), Some(Iv::point(0.0)))
            } else if z.lo > 0.0 {
                (a, Iv::point(1.0), Some(Iv::point(0.0)))
            } else {
                (a, Iv { lo: 0.0, hi: 1.0 }, None)
            }
        }
    }
}

/// Enclosures over a box, per output i and input k.
#[derive(Debug, Clone, PartialEq)]
pub struct BoxBounds {
    /// κ_NN,i over the box (nu entries).
    pub value: Vec<Iv>,
    /// ∂κ_NN,i/∂x_k over the box (row-major nu × nx).
    pub jac: Vec<Iv>,
    /// ∂²κ_NN,i/∂x_k² over the box (row-major nu × nx); `None` if it does not exist
    /// everywhere on the box (ReLU kinks).
    pub hess_diag: Option<Vec<Iv>>,
}

/// Interval bound propagation for one network (its physical-unit layers, kept).
#[derive(Debug, Clone)]
pub struct NetBounder {
    layers: Vec<Layer>,
    act: Activation,
    mlp: Mlp,
}

impl NetBounder {
    /// Prepares the bounds of `mlp`.
    pub fn new(mlp: &Mlp) -> Self {
        NetBounder {
            layers: mlp.physical_layers(),
            act: mlp.activation,
            mlp: mlp.clone(),
        }
    }

    /// An outward-rounded enclosure of κ_NN(x) at one state: the interval forward pass on
    /// the point box [x, x] (every affine sum widened by its rounding bound, the activation
    /// enclosed on its interval with its slack), so it contains the exact value whatever
    /// the rounding of a plain f64 evaluation. Its width is a few rounding errors.
    pub fn value_at(&self, x: &[f64]) -> Vec<Iv> {
        let m = self.layers.len();
        let mut a: Vec<Iv> = x.iter().map(|v| Iv::point(*v)).collect();
        let mut z = Vec::new();
        for (j, l) in self.layers.iter().enumerate() {
            affine(&l.w, Some(&l.b), &a, &mut z);
            if j + 1 == m {
                break;
            }
            a = z.iter().map(|zi| act_bounds(self.act, *zi).0).collect();
        }
        z
    }

    /// Enclosures of κ_NN, ∂κ_NN/∂x and diag ∂²κ_NN/∂x² over the box [lo, hi].
    pub fn bounds(&self, lo: &[f64], hi: &[f64]) -> BoxBounds {
        let nx = self.mlp.nx();
        let nu = self.mlp.nu();
        let m = self.layers.len();
        let x: Vec<Iv> = lo
            .iter()
            .zip(hi)
            .map(|(&l, &h)| Iv { lo: l, hi: h })
            .collect();
        // Forward pass: pre-activation enclosures and α, α′, α″ on them.
        let mut a = x;
        let mut z = Vec::new();
        let mut d = Vec::with_capacity(m);
        let mut dd = Vec::with_capacity(m);
        let mut hess_ok = true;
        for (j, l) in self.layers.iter().enumerate() {
            affine(&l.w, Some(&l.b), &a, &mut z);
            if j + 1 == m {
                break;
            }
            let mut an = Vec::with_capacity(l.out);
            let mut dj = Vec::with_capacity(l.out);
            let mut ddj = Vec::with_capacity(l.out);
            for &zi in &z {
                let (av, dv, ddv) = act_bounds(self.act, zi);
                an.push(av);
                dj.push(dv);
                match ddv {
                    Some(v) => ddj.push(v),
                    None => {
                        hess_ok = false;
                        ddj.push(Iv::point(0.0));
                    }
                }
            }
            a = an;
            d.push(dj);
            dd.push(ddj);
        }
        let value_ibp = z.clone();
        // Directional derivatives along each e_k.
        let mut jac = vec![Iv::point(0.0); nu * nx];
        let mut hess = vec![Iv::point(0.0); nu * nx];
        let (mut t, mut s) = (Vec::new(), Vec::new());
        let (mut dz, mut d2z) = (Vec::new(), Vec::new());
        for k in 0..nx {
            t.clear();
            t.extend((0..nx).map(|c| Iv::point(if c == k { 1.0 } else { 0.0 })));
            s.clear();
            s.resize(nx, Iv::point(0.0));
            for (j, l) in self.layers.iter().enumerate() {
                affine(&l.w, None, &t, &mut dz);
                affine(&l.w, None, &s, &mut d2z);
                if j + 1 == m {
                    for i in 0..nu {
                        jac[i * nx + k] = dz[i];
                        hess[i * nx + k] = d2z[i];
                    }
                    break;
                }
                t.clear();
                s.clear();
                for r in 0..l.out {
                    t.push(d[j][r].mul(dz[r]));
                    s.push(dd[j][r].mul(dz[r].sqr()).add(d[j][r].mul(d2z[r])));
                }
            }
        }
        // Mean-value form for the value: κ(mid) + Σ_k J_k (x_k − mid_k).
        let mid: Vec<f64> = lo.iter().zip(hi).map(|(l, h)| 0.5 * (l + h)).collect();
        let mut u = vec![0.0; nu];
        let mut jm = vec![0.0; nu * nx];
        // The thread's workspace: a fresh one zero-fills its block buffers (tens of KiB), more
        // than the interval passes above cost.
        crate::learn::mlp::with_workspace(|ws| self.mlp.eval(&mid, &mut u, &mut jm, ws));
        let value = (0..nu)
            .map(|i| {
                let mut v = Iv::new(
                    u[i] - 1e-12 * (1.0 + u[i].abs()),
                    u[i] + 1e-12 * (1.0 + u[i].abs()),
                );
                for k in 0..nx {
                    let h = 0.5 * (hi[k] - lo[k]);
                    v = v.add(jac[i * nx + k].mul(Iv::new(-h, h)));
                }
                v.intersect(value_ibp[i])
            })
            .collect();
        BoxBounds {
            value,
            jac,
            hess_diag: hess_ok.then_some(hess),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::mlp::Workspace;
    use crate::rng::uniform;

    fn net(act: Activation, seed: u64, widths: &[usize]) -> Mlp {
        let nx = widths[0];
        let lo = vec![-2.0; nx];
        let hi = vec![3.0; nx];
        let mut m = Mlp::new(widths, act, seed, &lo, &hi, &[-5.0], &[5.0]);
        // Non-zero biases so that pre-activations are not centred.
        for (j, l) in m.layers.iter_mut().enumerate() {
            for (r, b) in l.b.iter_mut().enumerate() {
                *b = 0.8 * (2.0 * uniform(seed ^ 77, j as u64, r as u64) - 1.0);
            }
        }
        m
    }

    /// Central second difference of κ_NN along e_k.
    fn second(m: &Mlp, x: &[f64], k: usize, h: f64) -> f64 {
        let f = |dx: f64| {
            let mut y = x.to_vec();
            y[k] += dx;
            m.predict(&y)[0]
        };
        (f(h) - 2.0 * f(0.0) + f(-h)) / (h * h)
    }

    #[test]
    fn enclosures_contain_sampled_values_and_derivatives() {
        for (act, seed) in [
            (Activation::Tanh, 1),
            (Activation::Tanh, 2),
            (Activation::Softplus, 3),
            (Activation::Relu, 4),
        ] {
            let m = net(act, seed, &[2, 12, 9, 1]);
            let nb = NetBounder::new(&m);
            let mut ws = Workspace::default();
            for cell in 0..20u64 {
                let c: Vec<f64> = (0..2)
                    .map(|k| -2.0 + 5.0 * uniform(seed, cell, k as u64))
                    .collect();
                let w = [0.02, 0.1, 0.5, 2.0][cell as usize % 4];
                let lo: Vec<f64> = c.iter().map(|v| v - 0.5 * w).collect();
                let hi: Vec<f64> = c.iter().map(|v| v + 0.5 * w).collect();
                let b = nb.bounds(&lo, &hi);
                for s in 0..200u64 {
                    let x: Vec<f64> = (0..2)
                        .map(|k| {
                            lo[k] + (hi[k] - lo[k]) * uniform(seed + 100, cell * 1000 + s, k as u64)
                        })
                        .collect();
                    let (mut u, mut j) = ([0.0], [0.0; 2]);
                    m.eval(&x, &mut u, &mut j, &mut ws);
                    assert!(
                        b.value[0].contains(u[0]),
                        "{act:?} value {u:?} ∉ {:?}",
                        b.value[0]
                    );
                    for k in 0..2 {
                        assert!(
                            b.jac[k].contains(j[k]),
                            "{act:?} jac {} ∉ {:?}",
                            j[k],
                            b.jac[k]
                        );
                        if let Some(h) = &b.hess_diag {
                            // FD second derivative, with its truncation error allowance.
                            let d2 = second(&m, &x, k, 1e-4);
                            let tol = 1e-4 * (1.0 + d2.abs());
                            assert!(
                                h[k].lo - tol <= d2 && d2 <= h[k].hi + tol,
                                "{act:?} hess {d2} ∉ {:?}",
                                h[k]
                            );
                        }
                    }
                }
            }
        }
    }

    /// The point enclosure contains the f64 evaluation and is a few rounding errors wide.
    #[test]
    fn point_enclosures_contain_the_value_and_are_tight() {
        for act in [Activation::Tanh, Activation::Softplus, Activation::Relu] {
            let m = net(act, 5, &[2, 8, 8, 1]);
            let nb = NetBounder::new(&m);
            for i in 0..50u64 {
                let x = [uniform(3, i, 0) * 4.0 - 2.0, uniform(3, i, 1) * 2.0 - 1.0];
                let v = nb.value_at(&x);
                let u = m.predict(&x);
                for (e, u) in v.iter().zip(&u) {
                    assert!(e.contains(*u), "{act:?} {x:?}: {u} ∉ {e:?}");
                    assert!(e.width() < 1e-9 * (1.0 + u.abs()), "{act:?}: {e:?}");
                }
            }
        }
    }

    #[test]
    fn enclosures_shrink_to_the_true_values() {
        let m = net(Activation::Tanh, 9, &[2, 16, 16, 1]);
        let nb = NetBounder::new(&m);
        let x = [0.3, -0.7];
        let (mut u, mut j) = ([0.0], [0.0; 2]);
        m.eval(&x, &mut u, &mut j, &mut Workspace::default());
        let mut prev = f64::INFINITY;
        for e in 1..7 {
            let w = 10f64.powi(-e);
            let lo = [x[0] - w, x[1] - w];
            let hi = [x[0] + w, x[1] + w];
            let b = nb.bounds(&lo, &hi);
            let width = b.jac[0].width().max(b.jac[1].width());
            let hw = b.hess_diag.as_ref().unwrap()[0].width();
            assert!(b.jac[0].contains(j[0]) && b.jac[1].contains(j[1]));
            // Linear convergence of the Jacobian enclosure: width ≈ C·w.
            assert!(width < prev * 0.2, "width {width} after {prev}");
            assert!(width < 1e3 * w, "width {width} at w {w}");
            assert!(hw < 1e4 * w);
            prev = width;
        }
    }

    #[test]
    fn jacobian_enclosure_of_a_small_box_is_below_the_global_bound() {
        let m = net(Activation::Tanh, 5, &[2, 10, 10, 1]);
        let nb = NetBounder::new(&m);
        let global = crate::certify::lipschitz::naive_bound(&m);
        for cell in 0..50u64 {
            let c: Vec<f64> = (0..2)
                .map(|k| -2.0 + 5.0 * uniform(8, cell, k as u64))
                .collect();
            let lo: Vec<f64> = c.iter().map(|v| v - 0.01).collect();
            let hi: Vec<f64> = c.iter().map(|v| v + 0.01).collect();
            let b = nb.bounds(&lo, &hi);
            let local = (b.jac[0].mag().powi(2) + b.jac[1].mag().powi(2)).sqrt();
            assert!(local <= global, "local {local} > global {global}");
        }
    }
}
