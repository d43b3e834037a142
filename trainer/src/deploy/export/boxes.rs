//! The grid of sub-boxes of X behind the f32 allowance ([`Grid`]) and the maximum of a
//! per-box bound over it ([`Grid::max_of`]), pruned through coarse boxes:
//!
//! ```text
//! fine boxes: k per axis; on axis i, box j spans [l + s·j, l + s·(j+1)], s = (h − l)/k,
//!             the first box starting at l and the last ending at h exactly
//! coarse box C: g per axis of those fine boxes (fewer at the upper end), with the fine
//!             boxes' computed end points
//! max_B b(B) = max over the coarse boxes with b(C) > M of max_{B ⊂ C} b(B),
//!             M the running maximum, coarse boxes taken by decreasing b(C)
//! ```
//!
//! A bound that is sound on a box is sound on every part of it, so a coarse box with
//! b(C) ≤ M needs no finer look: M already covers it, and the result is a sound bound over
//! X. For a bound that grows with the box it is exactly the maximum over all fine boxes:
//! interval arithmetic evaluated in one fixed order does grow (every rounded f64 operation
//! is monotone), given monotone `tanh` and error tables, which the allowance's analysis
//! uses; the tests compare the two on several nets. The order of the coarse boxes and the batches they
//! are bounded in do not depend on the thread count, so neither does the result.

use rayon::prelude::*;

/// Fine boxes bounded per parallel batch (at least one coarse box's worth).
const BATCH: usize = 512;

/// The k-per-axis grid of sub-boxes of `[lo, hi]` and its coarse grouping.
pub(super) struct Grid<'a> {
    lo: &'a [f64],
    hi: &'a [f64],
    k: usize,
    g: usize,
}

impl<'a> Grid<'a> {
    /// `k` boxes per axis over `[lo, hi]`; coarse boxes of about √k fine boxes per axis.
    pub(super) fn new(lo: &'a [f64], hi: &'a [f64], k: usize) -> Self {
        let g = ((k as f64).sqrt().round() as usize).max(2);
        Grid { lo, hi, k, g }
    }

    /// Number of fine boxes.
    pub(super) fn boxes(&self) -> usize {
        self.k.pow(self.lo.len() as u32)
    }

    /// Coarse boxes per axis.
    fn coarse_per_axis(&self) -> usize {
        self.k.div_ceil(self.g)
    }

    /// Axis i's interval of fine boxes `first ..= last` (their computed end points).
    fn span(&self, i: usize, first: usize, last: usize) -> (f64, f64) {
        let (l, h) = (self.lo[i], self.hi[i]);
        let step = (h - l) / self.k as f64;
        let a = if first == 0 {
            l
        } else {
            l + step * first as f64
        };
        // Adjacent boxes share the computed end point, so the union covers X.
        let b = if last + 1 == self.k {
            h
        } else {
            l + step * (last + 1) as f64
        };
        (a, b)
    }

    /// Fills `(a, b)` with fine box `n` (index (n / kⁱ) mod k along axis i).
    pub(super) fn fine_box(&self, n: usize, a: &mut [f64], b: &mut [f64]) {
        let mut rest = n;
        for i in 0..self.lo.len() {
            let j = rest % self.k;
            rest /= self.k;
            (a[i], b[i]) = self.span(i, j, j);
        }
    }

    /// Fills `(a, b)` with coarse box `c` (the same numbering on the coarse grid).
    fn coarse(&self, c: usize, a: &mut [f64], b: &mut [f64]) {
        let kc = self.coarse_per_axis();
        let mut rest = c;
        for i in 0..self.lo.len() {
            let j = rest % kc;
            rest /= kc;
            let first = j * self.g;
            let last = (first + self.g).min(self.k) - 1;
            (a[i], b[i]) = self.span(i, first, last);
        }
    }

    /// The fine boxes of coarse box `c`.
    fn fine_of(&self, c: usize) -> Vec<usize> {
        let (nx, kc) = (self.lo.len(), self.coarse_per_axis());
        let mut out = vec![0usize];
        let (mut rest, mut stride) = (c, 1usize);
        for _ in 0..nx {
            let j = rest % kc;
            rest /= kc;
            let first = j * self.g;
            let last = (first + self.g).min(self.k);
            out = out
                .iter()
                .flat_map(|&n| (first..last).map(move |f| n + f * stride))
                .collect();
            stride *= self.k;
        }
        out
    }

    /// The maximum of `bound` over the fine boxes, with the coarse pruning of the module
    /// doc: NaN if a bound it evaluates is NaN (a NaN coarse bound makes it evaluate every
    /// fine box; a fine box inside a pruned coarse box is covered by that box's finite
    /// bound and not evaluated). `bound(scratch, a, b)` bounds the box `[a, b]`;
    /// `scratch` is made once per worker by `init`.
    pub(super) fn max_of<S, I, F>(&self, init: I, bound: F) -> f64
    where
        I: Fn() -> S + Sync + Send,
        F: Fn(&mut S, &[f64], &[f64]) -> f64 + Sync + Send,
    {
        let nx = self.lo.len();
        let scratch = || (init(), vec![0.0; nx], vec![0.0; nx]);
        let fine_max = |ns: &[usize]| {
            ns.par_iter()
                .map_init(scratch, |(s, a, b), &n| {
                    self.fine_box(n, a, b);
                    bound(s, a, b)
                })
                .reduce(|| 0.0, max_or_nan)
        };
        let n_coarse = self.coarse_per_axis().pow(nx as u32);
        if self.k < 2 || n_coarse >= self.boxes() {
            return fine_max(&(0..self.boxes()).collect::<Vec<_>>());
        }
        let mut coarse: Vec<(f64, usize)> = (0..n_coarse)
            .into_par_iter()
            .map_init(scratch, |(s, a, b), c| {
                self.coarse(c, a, b);
                (bound(s, a, b), c)
            })
            .collect();
        if coarse.iter().any(|(v, _)| v.is_nan()) {
            // No order to prune by: every fine box.
            return fine_max(&(0..self.boxes()).collect::<Vec<_>>());
        }
        coarse.sort_by(|x, y| y.0.total_cmp(&x.0).then(x.1.cmp(&y.1)));
        let mut worst = 0.0f64;
        let mut next = 0;
        while next < coarse.len() && coarse[next].0 > worst {
            let mut batch = Vec::new();
            while next < coarse.len() && coarse[next].0 > worst && batch.len() < BATCH {
                batch.extend(self.fine_of(coarse[next].1));
                next += 1;
            }
            worst = max_or_nan(worst, fine_max(&batch));
            if worst.is_nan() {
                break;
            }
        }
        worst
    }
}

/// The larger of two values, NaN when either is (`f64::max` drops a NaN, which would hide a
/// non-finite bound).
pub(super) fn max_or_nan(a: f64, b: f64) -> f64 {
    if a.is_nan() || b.is_nan() {
        f64::NAN
    } else {
        a.max(b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every fine box's bound, for comparison.
    fn every<F: Fn(&[f64], &[f64]) -> f64>(g: &Grid, f: F) -> f64 {
        let nx = g.lo.len();
        let (mut a, mut b) = (vec![0.0; nx], vec![0.0; nx]);
        (0..g.boxes()).fold(0.0, |m, n| {
            g.fine_box(n, &mut a, &mut b);
            max_or_nan(m, f(&a, &b))
        })
    }

    /// The coarse boxes' fine boxes partition the grid, and each coarse box is the union
    /// (the hull) of its fine boxes, with the same end points.
    #[test]
    fn coarse_boxes_partition_the_fine_grid() {
        for (nx, k) in [(1, 256), (2, 7), (3, 6), (2, 2)] {
            let lo: Vec<f64> = (0..nx).map(|i| -1.0 - i as f64).collect();
            let hi: Vec<f64> = (0..nx).map(|i| 0.3 + i as f64).collect();
            let g = Grid::new(&lo, &hi, k);
            let kc = g.coarse_per_axis().pow(nx as u32);
            let mut seen = vec![0u32; g.boxes()];
            let (mut a, mut b, mut fa, mut fb) =
                (vec![0.0; nx], vec![0.0; nx], vec![0.0; nx], vec![0.0; nx]);
            for c in 0..kc {
                g.coarse(c, &mut a, &mut b);
                let mut hull = (vec![f64::INFINITY; nx], vec![f64::NEG_INFINITY; nx]);
                for n in g.fine_of(c) {
                    seen[n] += 1;
                    g.fine_box(n, &mut fa, &mut fb);
                    for i in 0..nx {
                        hull.0[i] = hull.0[i].min(fa[i]);
                        hull.1[i] = hull.1[i].max(fb[i]);
                    }
                }
                assert_eq!((a.clone(), b.clone()), hull, "nx {nx} k {k} coarse {c}");
            }
            assert!(seen.iter().all(|&s| s == 1), "nx {nx} k {k}: {seen:?}");
        }
    }

    /// With a bound that grows with the box, the pruned maximum is the maximum over every
    /// fine box; with NaN anywhere it is NaN.
    #[test]
    fn pruned_maximum_is_the_maximum_over_every_box() {
        let lo = [-2.0, -1.0, 0.5];
        let hi = [1.5, 3.0, 0.9];
        let g = Grid::new(&lo, &hi, 12);
        // A bumpy function's interval-like bound: its value at the box centre plus a
        // Lipschitz term in the box's width (grows with the box).
        let f = |a: &[f64], b: &[f64]| {
            let c: Vec<f64> = a.iter().zip(b).map(|(a, b)| 0.5 * (a + b)).collect();
            let w: f64 = a.iter().zip(b).map(|(a, b)| b - a).sum();
            (3.0 * c[0]).sin().abs() + (c[1] * c[2]).cos().powi(2) + 4.0 * w
        };
        let pruned = g.max_of(|| (), |_, a, b| f(a, b));
        assert_eq!(pruned, every(&g, f));
        let nan = g.max_of(|| (), |_, a, b| if a[0] > 0.0 { f64::NAN } else { f(a, b) });
        assert!(nan.is_nan());
    }
}
