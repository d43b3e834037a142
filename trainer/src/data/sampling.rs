//! Samplers of states in the box X = [lo, hi]: full grid, uniform random, Halton.
//!
//! Every sampler is a pure function of (settings, index): point `i` does not depend on
//! any other point, so shards and resumed runs produce the same states.
//! - Grid: per-axis counts c_j, `x_j = lo_j + (hi_j − lo_j)·t/(c_j − 1)` (endpoints
//!   included; a count of 1 gives the midpoint), axis 0 slowest, the last axis fastest.
//! - Random: `x_j = lo_j + (hi_j − lo_j)·U`, U from SplitMix64 keyed by (seed, i, j).
//! - Halton: radical inverses in the first n_x primes of `i + 1`, shifted modulo 1 by a
//!   seed-derived random vector (Cranley–Patterson rotation; seed 0 = the plain sequence).

use crate::problem::{Domain, SamplerKind, SamplingSettings};
use crate::rng::uniform;

const PRIMES: [u64; 16] = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53];

fn radical_inverse(mut i: u64, base: u64) -> f64 {
    let inv = 1.0 / base as f64;
    let (mut f, mut r) = (inv, 0.0);
    while i > 0 {
        r += (i % base) as f64 * f;
        i /= base;
        f *= inv;
    }
    r
}

/// The states of a sampling plan.
#[derive(Debug, Clone, PartialEq)]
pub struct Sampler {
    kind: SamplerKind,
    counts: Vec<usize>,
    n: usize,
    seed: u64,
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl Sampler {
    /// A sampler over `domain` (validated settings).
    pub fn new(s: &SamplingSettings, domain: &Domain) -> Self {
        Sampler {
            kind: s.sampler,
            counts: s.counts.clone(),
            n: s.n,
            seed: s.seed,
            lo: domain.lo.clone(),
            hi: domain.hi.clone(),
        }
    }

    /// Number of states.
    pub fn len(&self) -> usize {
        match self.kind {
            SamplerKind::Grid => self.counts.iter().product(),
            _ => self.n,
        }
    }

    /// The domain's widths hi − lo per coordinate (the scale of distances between states).
    pub fn widths(&self) -> Vec<f64> {
        self.hi.iter().zip(&self.lo).map(|(h, l)| h - l).collect()
    }

    /// Whether there are no states.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// State number `i` (0 ≤ i < len) into `x`.
    pub fn point(&self, i: usize, x: &mut [f64]) {
        let d = self.lo.len();
        match self.kind {
            SamplerKind::Grid => {
                let mut rem = i;
                for j in (0..d).rev() {
                    let c = self.counts[j];
                    let t = rem % c;
                    rem /= c;
                    x[j] = if c == 1 {
                        0.5 * (self.lo[j] + self.hi[j])
                    } else if t + 1 == c {
                        self.hi[j]
                    } else {
                        self.lo[j] + (self.hi[j] - self.lo[j]) * t as f64 / (c - 1) as f64
                    };
                }
            }
            SamplerKind::Random => {
                for j in 0..d {
                    x[j] = self.lo[j]
                        + (self.hi[j] - self.lo[j]) * uniform(self.seed, i as u64, j as u64);
                }
            }
            // Not a plan (rejected by validation): no state.
            SamplerKind::Adaptive | SamplerKind::Imported => x[..d].fill(f64::NAN),
            SamplerKind::Halton => {
                for j in 0..d {
                    let shift = if self.seed == 0 {
                        0.0
                    } else {
                        uniform(self.seed, u64::MAX, j as u64)
                    };
                    let t =
                        (radical_inverse(i as u64 + 1, PRIMES[j % PRIMES.len()]) + shift).fract();
                    x[j] = self.lo[j] + (self.hi[j] - self.lo[j]) * t;
                }
            }
        }
    }

    /// All states, row by row.
    pub fn points(&self) -> Vec<Vec<f64>> {
        (0..self.len())
            .map(|i| {
                let mut x = vec![0.0; self.lo.len()];
                self.point(i, &mut x);
                x
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dom() -> Domain {
        Domain {
            lo: vec![-2.0, -1.0],
            hi: vec![2.0, 1.0],
        }
    }

    #[test]
    fn grid_includes_endpoints_and_is_lexicographic() {
        let s = SamplingSettings {
            sampler: SamplerKind::Grid,
            counts: vec![3, 2],
            ..Default::default()
        };
        let p = Sampler::new(&s, &dom()).points();
        assert_eq!(
            p,
            vec![
                vec![-2.0, -1.0],
                vec![-2.0, 1.0],
                vec![0.0, -1.0],
                vec![0.0, 1.0],
                vec![2.0, -1.0],
                vec![2.0, 1.0]
            ]
        );
    }

    #[test]
    fn samplers_are_seeded_and_inside_the_box() {
        for kind in [SamplerKind::Random, SamplerKind::Halton] {
            let s = SamplingSettings {
                sampler: kind,
                n: 1000,
                seed: 5,
                ..Default::default()
            };
            let a = Sampler::new(&s, &dom()).points();
            assert_eq!(a, Sampler::new(&s, &dom()).points());
            let b = Sampler::new(
                &SamplingSettings {
                    seed: 6,
                    ..s.clone()
                },
                &dom(),
            )
            .points();
            assert_ne!(a, b);
            for x in &a {
                assert!((-2.0..2.0).contains(&x[0]) && (-1.0..1.0).contains(&x[1]));
            }
            // Roughly uniform: each quadrant holds about a quarter of the points.
            let q = a.iter().filter(|x| x[0] < 0.0 && x[1] < 0.0).count();
            assert!((200..300).contains(&q), "{kind:?}: {q}");
        }
    }

    #[test]
    fn halton_seed_zero_is_the_plain_sequence() {
        let s = SamplingSettings {
            sampler: SamplerKind::Halton,
            n: 3,
            seed: 0,
            ..Default::default()
        };
        let d = Domain {
            lo: vec![0.0, 0.0],
            hi: vec![1.0, 1.0],
        };
        let p = Sampler::new(&s, &d).points();
        assert_eq!(p[0], vec![0.5, 1.0 / 3.0]);
        assert_eq!(p[1], vec![0.25, 2.0 / 3.0]);
        assert!((p[2][0] - 0.75).abs() < 1e-15 && (p[2][1] - 1.0 / 9.0).abs() < 1e-15);
    }
}
