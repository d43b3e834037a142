//! The dense kernels of the LipSDP search ([`DenseWork`]): K(T) = L Lᵀ (Cholesky), the solve
//! K⁻¹N₁ᵀ, the products N₁K⁻¹N₁ᵀ and K⁻¹N₁ᵀv, `W̃_j x` — on column-major buffers allocated
//! once per search, each with the operations of the `nalgebra` routine it replaces, in the
//! same order:
//! ```text
//! Cholesky (left-looking):  L_{j:,j} ← K_{j:,j} + Σ_{k<j} (−L_{j,k})·L_{j:,k};  L_{jj} ← √L_{jj};  L_{j+1:,j} ← L_{j+1:,j} / L_{jj}
//! forward:  b_i ← b_i / L_ii,  b_{i+1:} ← (−b_i)·L_{i+1:,i} + b_{i+1:}   (each entry's terms in this order, rows four at a time)
//! backward: b_i ← (b_i − L_{i+1:,i}·b_{i+1:}) / L_ii   (dot: 8 partial sums, then the tail)
//!           (both substitutions on two columns at a time: independent chains, interleaved)
//! A·x:      y ← A_{:,0}·x_0,  y ← A_{:,c}·x_c + y  (c = 1, 2, …)
//! ```
//! (each row's leading zeros L_{j,k} skipped in the factorisation: the structural zeros of
//! block-tridiagonal K, which add ±0 and so change at most the sign of a zero entry),
//! so the search's results are those of the allocating `nalgebra` version bit for bit
//! (checked by the tests of the parent module), at a fraction of the cost: the search
//! evaluates ρ(T) thousands of times.

/// Reusable buffers of one LipSDP search (column-major n × n and n × n0 matrices).
#[derive(Debug, Clone, Default)]
pub(super) struct DenseWork {
    /// K(T), overwritten by its Cholesky factor L (lower triangle).
    pub k: Vec<f64>,
    /// The hidden-layer sizes whose block structure `k`'s zeros are laid out for.
    pub k_shape: Vec<usize>,
    /// N₁ᵀ (n × n0).
    pub nt: Vec<f64>,
    /// K⁻¹N₁ᵀ (n × n0).
    pub kin: Vec<f64>,
    /// K⁻¹N₁ᵀv (n).
    pub w: Vec<f64>,
    /// `W̃_j w_{j−1}` (sized for the widest hidden layer).
    pub wp: Vec<f64>,
    /// The eigendecomposition of A = N₁K⁻¹N₁ᵀ at the last T whose value was computed
    /// (`None` after a T where K(T) is not positive definite).
    pub eig: Option<nalgebra::SymmetricEigen<f64, nalgebra::Dyn>>,
    /// Its softmax weights exp((λᵢ − λ_max)/μ).
    pub wts: Vec<f64>,
    /// Their sum.
    pub z: f64,
}

/// Cholesky factorisation of the n × n column-major `m` in place (lower triangle; the upper
/// one is not read): `false` where a pivot is zero, negative or NaN (as `nalgebra`).
pub(super) fn cholesky_in_place(m: &mut [f64], n: usize) -> bool {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked just above), the one requirement of calling a
        // `#[target_feature(enable = "avx")]` function.
        return unsafe { cholesky_avx(m, n) };
    }
    cholesky_impl(m, n)
}

/// [`cholesky_impl`] compiled with AVX (4 f64 lanes; the same IEEE operations — no fused
/// multiply-add — hence the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn cholesky_avx(m: &mut [f64], n: usize) -> bool {
    cholesky_impl(m, n)
}

#[inline(always)]
fn cholesky_impl(m: &mut [f64], n: usize) -> bool {
    for j in 0..n {
        let (left, right) = m.split_at_mut(j * n);
        let col_j = &mut right[..n];
        // Row j of L left of the diagonal: its leading zeros (the structural zeros of
        // block-tridiagonal K) would add ±0 products only, which change no entry but a
        // zero's sign, so the sums start at the first nonzero.
        let k0 = (0..j).find(|&k| left[k * n + j] != 0.0).unwrap_or(j);
        // L_{r,j} ← K_{r,j} + Σ_k (−L_{j,k})·L_{r,k}, k in order, for four rows at a time
        // (the accumulators in registers), then the remaining rows one by one.
        let mut r = j;
        while r + 4 <= n {
            let mut acc: [f64; 4] = col_j[r..r + 4].try_into().expect("4 rows");
            for k in k0..j {
                let factor = -left[k * n + j];
                let x: &[f64; 4] = left[k * n + r..k * n + r + 4].try_into().expect("4 rows");
                for i in 0..4 {
                    acc[i] += factor * x[i];
                }
            }
            col_j[r..r + 4].copy_from_slice(&acc);
            r += 4;
        }
        for r in r..n {
            let mut y = col_j[r];
            for k in k0..j {
                y += -left[k * n + j] * left[k * n + r];
            }
            col_j[r] = y;
        }
        let diag = col_j[j];
        // Zero, negative or NaN: no factor (`try_sqrt` refuses what is not ≥ 0).
        if diag == 0.0 || diag.partial_cmp(&0.0) == Some(std::cmp::Ordering::Less) || diag.is_nan()
        {
            return false;
        }
        let denom = diag.sqrt();
        col_j[j] = denom;
        for y in &mut col_j[j + 1..] {
            *y /= denom;
        }
    }
    true
}

/// Solves L Lᵀ X = B in place for the `cols` columns of the n × cols column-major `b`, with
/// `l` the factor from [`cholesky_in_place`] (nalgebra's `Cholesky::solve_mut`).
pub(super) fn solve_cols(l: &[f64], n: usize, b: &mut [f64], cols: usize) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked just above), see `cholesky_in_place`.
        return unsafe { solve_avx(l, n, b, cols) };
    }
    solve_impl(l, n, b, cols)
}

/// [`solve_impl`] compiled with AVX (the same bits, see `cholesky_avx`).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn solve_avx(l: &[f64], n: usize, b: &mut [f64], cols: usize) {
    solve_impl(l, n, b, cols)
}

#[inline(always)]
fn solve_impl(l: &[f64], n: usize, b: &mut [f64], cols: usize) {
    // Two columns at a time: their substitutions are independent chains of dependent
    // divisions, which interleaved overlap; each column's operations are unchanged.
    if n == 0 {
        return;
    }
    let cols = cols.min(b.len() / n);
    let b = &mut b[..n * cols];
    let mut pairs = b.chunks_exact_mut(2 * n);
    for pair in &mut pairs {
        let (b0, b1) = pair.split_at_mut(n);
        solve_two(l, n, b0, b1);
    }
    for bc in pairs.into_remainder().chunks_exact_mut(n) {
        solve_one(l, n, bc);
    }
}

/// [`solve_one`] on two columns at once (the same operations on each).
#[inline(always)]
fn solve_two(l: &[f64], n: usize, b0: &mut [f64], b1: &mut [f64]) {
    let mut r = 0;
    while r + 4 <= n {
        let mut a0: [f64; 4] = b0[r..r + 4].try_into().expect("4 rows");
        let mut a1: [f64; 4] = b1[r..r + 4].try_into().expect("4 rows");
        for i in 0..r {
            let (f0, f1) = (-b0[i], -b1[i]);
            let x: &[f64; 4] = l[i * n + r..i * n + r + 4].try_into().expect("4 rows");
            for q in 0..4 {
                a0[q] += f0 * x[q];
                a1[q] += f1 * x[q];
            }
        }
        for q in 0..4 {
            let d = l[(r + q) * n + r + q];
            let (c0, c1) = (a0[q] / d, a1[q] / d);
            b0[r + q] = c0;
            b1[r + q] = c1;
            for q2 in q + 1..4 {
                let lq = l[(r + q) * n + r + q2];
                a0[q2] += -c0 * lq;
                a1[q2] += -c1 * lq;
            }
        }
        r += 4;
    }
    for r in r..n {
        let (mut y0, mut y1) = (b0[r], b1[r]);
        for i in 0..r {
            let lv = l[i * n + r];
            y0 += -b0[i] * lv;
            y1 += -b1[i] * lv;
        }
        let d = l[r * n + r];
        b0[r] = y0 / d;
        b1[r] = y1 / d;
    }
    for i in (0..n).rev() {
        let li = &l[i * n..(i + 1) * n];
        let (d0, d1) = (
            dot8(&li[i + 1..], &b0[i + 1..]),
            dot8(&li[i + 1..], &b1[i + 1..]),
        );
        b0[i] = (b0[i] - d0) / li[i];
        b1[i] = (b1[i] - d1) / li[i];
    }
}

/// L Lᵀ x = b for one column in place.
#[inline(always)]
fn solve_one(l: &[f64], n: usize, bc: &mut [f64]) {
    // L y = b: entry r gets `b_r + (−y_0)·L_{r,0} + (−y_1)·L_{r,1} + …` in order, then
    // y_r = b_r / L_rr (the column-by-column updates, reordered by rows): four rows at
    // a time, the terms of the rows above in registers, then the 4 × 4 triangle.
    let mut r = 0;
    while r + 4 <= n {
        let mut acc: [f64; 4] = bc[r..r + 4].try_into().expect("4 rows");
        for i in 0..r {
            let f = -bc[i];
            let x: &[f64; 4] = l[i * n + r..i * n + r + 4].try_into().expect("4 rows");
            for q in 0..4 {
                acc[q] += f * x[q];
            }
        }
        for q in 0..4 {
            let coeff = acc[q] / l[(r + q) * n + r + q];
            bc[r + q] = coeff;
            for q2 in q + 1..4 {
                acc[q2] += -coeff * l[(r + q) * n + r + q2];
            }
        }
        r += 4;
    }
    for r in r..n {
        let mut y = bc[r];
        for i in 0..r {
            y += -bc[i] * l[i * n + r];
        }
        bc[r] = y / l[r * n + r];
    }
    // Lᵀ x = y.
    for i in (0..n).rev() {
        let li = &l[i * n..(i + 1) * n];
        let dot = dot8(&li[i + 1..], &bc[i + 1..]);
        bc[i] = (bc[i] - dot) / li[i];
    }
}

/// Σ a_i b_i with `nalgebra`'s order: eight partial sums over whole blocks of 8, combined
/// as (s₀ + s₄), (s₁ + s₅), (s₂ + s₆), (s₃ + s₇) into 0, then the tail one by one.
#[inline(always)]
pub(super) fn dot8(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let mut acc = [0.0f64; 8];
    let mut i = 0;
    while n - i >= 8 {
        for (k, s) in acc.iter_mut().enumerate() {
            *s += a[i + k] * b[i + k];
        }
        i += 8;
    }
    let mut res = 0.0;
    res += acc[0] + acc[4];
    res += acc[1] + acc[5];
    res += acc[2] + acc[6];
    res += acc[3] + acc[7];
    for k in i..n {
        res += a[k] * b[k];
    }
    res
}

/// y = A x for the rows × cols column-major `a` (nalgebra's `gemv` with α = 1, β = 0:
/// column after column). `y` has `rows` entries.
pub(super) fn gemv_cols(a: &[f64], rows: usize, x: &[f64], y: &mut [f64]) {
    let mut cols = a.chunks_exact(rows).zip(x);
    if let Some((c0, &x0)) = cols.next() {
        for (y, &a) in y.iter_mut().zip(c0) {
            *y = a * x0;
        }
    } else {
        y.fill(0.0);
    }
    for (c, &xc) in cols {
        for (y, &a) in y.iter_mut().zip(c) {
            *y += a * xc;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{DMatrix, DVector};

    /// A symmetric positive definite n × n matrix with entries of mixed magnitude.
    fn spd(n: usize, seed: u64) -> DMatrix<f64> {
        let mut s = seed;
        let mut r = || {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        let b = DMatrix::from_fn(n, n, |_, _| r());
        &b * b.transpose() + DMatrix::identity(n, n) * 0.1
    }

    /// Factor, solve, dot and products give nalgebra's bits, for sizes around the dot's
    /// blocks of 8; a matrix that is not positive definite is refused by both.
    #[test]
    fn kernels_give_the_bits_of_nalgebra() {
        for n in [1, 2, 7, 8, 9, 16, 20, 21, 33] {
            for seed in 0..3 {
                let k = spd(n, seed * 31 + n as u64);
                let chol = nalgebra::Cholesky::new(k.clone()).expect("spd");
                let mut m = k.as_slice().to_vec();
                assert!(cholesky_in_place(&mut m, n));
                let l = chol.l();
                for c in 0..n {
                    for r in c..n {
                        assert_eq!(
                            m[c * n + r].to_bits(),
                            l[(r, c)].to_bits(),
                            "n {n} L[{r},{c}]"
                        );
                    }
                }
                // Pairs of columns and a single one (1, 2, 3 and 4 columns).
                for cols in 1..=4 {
                    let b = DMatrix::from_fn(n, cols, |r, c| ((r * 7 + c * 3) as f64).sin());
                    let x = chol.solve(&b);
                    let mut bb = b.as_slice().to_vec();
                    solve_cols(&m, n, &mut bb, cols);
                    for (a, e) in bb.iter().zip(x.as_slice()) {
                        assert_eq!(a.to_bits(), e.to_bits(), "n {n} solve, {cols} columns");
                    }
                }
                let cols = 3;
                let b = DMatrix::from_fn(n, cols, |r, c| ((r * 7 + c * 3) as f64).sin());
                let x = chol.solve(&b);
                let v = DVector::from_fn(cols, |i, _| 0.3 - i as f64);
                let y = &x * &v;
                let mut yy = vec![0.0; n];
                gemv_cols(x.as_slice(), n, v.as_slice(), &mut yy);
                for (a, e) in yy.iter().zip(y.as_slice()) {
                    assert_eq!(a.to_bits(), e.to_bits(), "n {n} gemv");
                }
                let (p, q) = (k.column(0), k.column(n - 1));
                assert_eq!(
                    dot8(p.as_slice(), q.as_slice()).to_bits(),
                    p.dot(&q).to_bits(),
                    "n {n} dot"
                );
                let mut neg = (-k).as_slice().to_vec();
                assert!(!cholesky_in_place(&mut neg, n));
                assert!(nalgebra::Cholesky::new(-spd(n, seed)).is_none());
            }
        }
    }
}
