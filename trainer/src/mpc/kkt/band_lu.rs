//! The banded LU with partial pivoting of the KKT systems ([`BandLu`], LAPACK's `gbtf2`):
//! `P A = L U` in place on band storage, row interchanges within the band, U with bandwidth
//! ≤ kl + ku; solves for one or many right-hand sides; structural zeros skipped.

/// `$self.solve_many_m::<M>($b, $m)` with `M = $m` a constant for `m ≤ 15`, else 0.
macro_rules! by_rhs_count {
    ($m:expr, $self:ident, $b:ident) => {
        by_rhs_count!(@ $m, $self, $b, 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15)
    };
    (@ $m:expr, $self:ident, $b:ident, $($n:literal)*) => {
        match $m {
            $($n => $self.solve_many_m::<$n>($b, $n),)*
            m => $self.solve_many_m::<0>($b, m),
        }
    };
}

/// A square banded matrix (lower bandwidth `kl`, upper `ku`) with room for the fill of LU
/// with partial pivoting, factorised in place (`P A = L U`).
///
/// Storage is row-major by band: row i holds columns `i − kl ..= i + kl + ku`.
///
/// The factorisation and the solves skip what is structurally zero within the band: each
/// row's entries right of its last nonzero (a row's extent grows only to that of the pivot
/// rows that update it) and each column's multipliers below its last nonzero one. The terms
/// skipped are products with an exact zero, so the results are the full band's values (for a
/// nonsingular matrix; with a zero pivot, where the full band's solves spread infinities and
/// NaNs, fewer entries may be non-finite).
#[derive(Debug, Clone, Default)]
pub struct BandLu {
    n: usize,
    kl: usize,
    ku: usize,
    w: usize,
    pub(super) a: Vec<f64>,
    piv: Vec<usize>,
    /// Per row position: the last column that may hold a nonzero (of U after the factor).
    end: Vec<usize>,
    /// Per column k of L: the last row with a possibly nonzero multiplier (k if none).
    lend: Vec<usize>,
    /// Work space of the factorisation (column ends).
    cend: Vec<usize>,
    /// Smallest over largest |U_ii| after [`BandLu::factor`] (0 if a pivot is 0 or not finite).
    pub pivot_ratio: f64,
}

impl BandLu {
    /// Resets to the n×n zero matrix with the given bandwidths, reusing the allocation.
    pub fn reset(&mut self, n: usize, kl: usize, ku: usize) {
        self.n = n;
        self.kl = kl;
        self.ku = ku;
        self.w = 2 * kl + ku + 1;
        self.a.clear();
        self.a.resize(n * self.w, 0.0);
        self.piv.clear();
        self.piv.resize(n, 0);
        self.pivot_ratio = 0.0;
    }

    /// Dimension n.
    pub fn dim(&self) -> usize {
        self.n
    }

    /// Index of entry (i, j) in the band storage, if inside the band.
    pub(super) fn slot(&self, i: usize, j: usize) -> Option<usize> {
        if i >= self.n || j >= self.n || j + self.kl < i || j > i + self.ku {
            return None;
        }
        Some(i * self.w + (j + self.kl - i))
    }

    /// Adds v to entry (i, j). Returns false (and changes nothing) if (i, j) is outside the
    /// band `−kl ≤ j − i ≤ ku` or the matrix.
    pub fn add(&mut self, i: usize, j: usize, v: f64) -> bool {
        if i >= self.n || j >= self.n || j + self.kl < i || j > i + self.ku {
            return false;
        }
        self.a[i * self.w + (j + self.kl - i)] += v;
        true
    }

    /// LU factorisation with partial pivoting, in place. Sets [`BandLu::pivot_ratio`]; a zero
    /// pivot column is skipped (the factor is then singular, ratio 0).
    pub fn factor(&mut self) {
        let (n, kl, w) = (self.n, self.kl, self.w);
        // Each row's last nonzero column and each column's last nonzero row, from the values
        // (entry t of row i is column i + t − kl).
        let mut row_end: Vec<usize> = (0..n).collect();
        let mut col_end: Vec<usize> = (0..n).collect();
        for i in 0..n {
            for (t, &v) in self.a[i * w..(i + 1) * w].iter().enumerate() {
                if v != 0.0 && i + t >= kl && i + t - kl < n {
                    let j = i + t - kl;
                    row_end[i] = row_end[i].max(j);
                    col_end[j] = col_end[j].max(i);
                }
            }
        }
        self.factor_with_ends(&row_end, &col_end);
    }

    /// [`BandLu::factor`] given, for every row, a column beyond which it holds only zeros
    /// (`row_end[i] ≥ i`), and for every column a row below which it holds only zeros
    /// (`col_end[j] ≥ j`) — e.g. from the sparsity pattern. The same values as
    /// [`BandLu::factor`] (the entries skipped are exact zeros).
    pub fn factor_with_ends(&mut self, row_end: &[usize], col_end: &[usize]) {
        let (n, kl, ku, w) = (self.n, self.kl, self.ku, self.w);
        let ubw = kl + ku;
        let (mut mn, mut mx) = (f64::INFINITY, 0.0f64);
        self.end.clear();
        self.end.extend_from_slice(&row_end[..n]);
        // `cend[j]`: the last row (of those not yet eliminated) that may hold a nonzero in
        // column j; grows with the rows that fill column j and with row interchanges.
        let mut cend = std::mem::take(&mut self.cend);
        cend.clear();
        cend.extend_from_slice(&col_end[..n]);
        self.lend.clear();
        self.lend.resize(n, 0);
        for k in 0..n {
            let last = (k + kl).min(n - 1).min(cend[k].max(k));
            // Entry (i, k) of row i ≥ k sits at i·w + (k + kl − i).
            let mut p = k;
            let mut best = self.a[k * w + kl].abs();
            for i in k + 1..=last {
                let v = self.a[i * w + k + kl - i].abs();
                if v > best {
                    best = v;
                    p = i;
                }
            }
            self.piv[k] = p;
            // Columns k..k+len of a row are contiguous; beyond `end` they are zeros.
            let rk0 = k * w + kl;
            if p != k {
                let len = self.end[k].max(self.end[p]).clamp(k, k + ubw) - k + 1;
                let (head, tail) = self.a.split_at_mut(p * w);
                let rp0 = k + kl - p;
                head[rk0..rk0 + len].swap_with_slice(&mut tail[rp0..rp0 + len]);
                // The former row k, now row p, puts nonzeros into row p of its columns.
                for c in &mut cend[k + 1..=self.end[k].clamp(k, k + ubw)] {
                    *c = (*c).max(p);
                }
                self.end.swap(k, p);
            }
            let ek = self.end[k].clamp(k, k + ubw);
            let len = ek - k + 1;
            self.lend[k] = k;
            let d = self.a[rk0];
            let ad = d.abs();
            if !ad.is_finite() {
                mn = 0.0;
            }
            mn = mn.min(ad);
            mx = mx.max(ad);
            if d == 0.0 || !d.is_finite() {
                continue;
            }
            let inv = 1.0 / d;
            // Rows k+1..=last, chunk q = row i = k+1+q: its entry (i, j) is at offset
            // j + kl − i, so (i, k) is at kl − (q + 1) and columns k+1.. follow it.
            let (head, tail) = self.a.split_at_mut((k + 1) * w);
            let rk = &head[rk0 + 1..rk0 + len];
            let ends = &mut self.end[k + 1..];
            for (q, row) in tail.chunks_exact_mut(w).take(last - k).enumerate() {
                let ri0 = kl - (q + 1);
                let l = row[ri0] * inv;
                row[ri0] = l;
                if l != 0.0 {
                    for (x, y) in row[ri0 + 1..ri0 + len].iter_mut().zip(rk) {
                        *x -= l * y;
                    }
                    ends[q] = ends[q].max(ek);
                    self.lend[k] = k + 1 + q;
                }
            }
            // Rows up to lend[k] now may hold nonzeros in columns k+1..=ek.
            for c in &mut cend[k + 1..=ek] {
                *c = (*c).max(self.lend[k]);
            }
        }
        self.cend = cend;
        self.pivot_ratio = if n == 0 {
            1.0
        } else if mx > 0.0 && mx.is_finite() && mn.is_finite() {
            mn / mx
        } else {
            0.0
        };
    }

    /// Solves `A x = b` in place with the factors of [`BandLu::factor`] (b has length n).
    pub fn solve_in_place(&self, b: &mut [f64]) {
        let (n, kl, w) = (self.n, self.kl, self.w);
        let ubw = kl + self.ku;
        for k in 0..n {
            let p = self.piv[k];
            if p != k {
                b.swap(k, p);
            }
            let bk = b[k];
            if bk != 0.0 {
                // Entry (i, k) is at i·w + k + kl − i: a stride of w − 1 down the column.
                let mut idx = k * w + kl + (w - 1);
                for bi in &mut b[k + 1..=self.lend[k]] {
                    *bi -= self.a[idx] * bk;
                    idx += w - 1;
                }
            }
        }
        for k in (0..n).rev() {
            let len = self.end[k].clamp(k, k + ubw) - k + 1;
            let rk0 = k * w + kl;
            let row = &self.a[rk0 + 1..rk0 + len];
            let s: f64 = row.iter().zip(&b[k + 1..k + len]).map(|(a, x)| a * x).sum();
            b[k] = (b[k] - s) / self.a[rk0];
        }
    }

    /// [`BandLu::solve_in_place`] for `m` right-hand sides at once: `b` is row-major n × m
    /// (row i holds the i-th entry of every right-hand side). Each column sees the single
    /// solve's operations in the same order (the same bits); the columns' independent sums
    /// overlap, and each factor entry is read once for all of them.
    pub fn solve_many_in_place(&self, b: &mut [f64], m: usize) {
        // A constant count for the sensitivities' nx ≤ 15 columns (unrolled loops).
        by_rhs_count!(m, self, b)
    }

    /// [`BandLu::solve_many_in_place`] with `M` right-hand sides (0: `m`).
    #[inline(always)]
    fn solve_many_m<const M: usize>(&self, b: &mut [f64], m: usize) {
        let m = if M == 0 { m } else { M };
        if m == 0 {
            return;
        }
        let (n, kl, w) = (self.n, self.kl, self.w);
        let ubw = kl + self.ku;
        for k in 0..n {
            let p = self.piv[k];
            if p != k {
                for c in 0..m {
                    b.swap(k * m + c, p * m + c);
                }
            }
            let (head, tail) = b.split_at_mut((k + 1) * m);
            let bk = &head[k * m..];
            if bk.iter().all(|&v| v == 0.0) {
                continue;
            }
            let mut idx = k * w + kl + (w - 1);
            for bi in tail.chunks_exact_mut(m).take(self.lend[k] - k) {
                let a = self.a[idx];
                for (x, &v) in bi.iter_mut().zip(bk) {
                    // (As the single solve, which skips a zero b_k.)
                    *x = if v != 0.0 { *x - a * v } else { *x };
                }
                idx += w - 1;
            }
        }
        // The initial value of `Iterator::sum` (the single solve's dot products).
        let zero: f64 = std::iter::empty::<f64>().sum();
        const G: usize = 16;
        for c0 in (0..m).step_by(G) {
            let g = G.min(m - c0);
            for k in (0..n).rev() {
                let len = self.end[k].clamp(k, k + ubw) - k + 1;
                let rk0 = k * w + kl;
                let mut s = [zero; G];
                for (j, &a) in self.a[rk0 + 1..rk0 + len].iter().enumerate() {
                    let x = &b[(k + 1 + j) * m + c0..(k + 1 + j) * m + c0 + g];
                    for (sc, &xc) in s.iter_mut().zip(x) {
                        *sc += a * xc;
                    }
                }
                let d = self.a[rk0];
                for (bc, sc) in b[k * m + c0..k * m + c0 + g].iter_mut().zip(&s) {
                    *bc = (*bc - sc) / d;
                }
            }
        }
    }
}
