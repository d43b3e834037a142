//! Skipping fruitless retrainings ([`Stale`]): after a warm-started retraining of the
//! refinement that returned its starting net, the next retrainings wait until the labelled
//! points have grown by a factor [`Stale::GROWTH`].

use super::RefineState;
use crate::certify::Model;
use crate::learn::mlp::Mlp;

/// A warm-started retraining returns its best checkpoint, which is its starting net when no
/// epoch did better ([`KeepBest`](crate::learn::train::KeepBest)). After such a retraining, retraining again on almost the
/// same data costs a whole training and almost always ends the same way: the next
/// retrainings are skipped (the net kept, the cells only split) until the labelled points
/// have grown by [`Stale::GROWTH`] over those of the retraining that kept its start. This
/// changes only which net the cells are bounded for (every bound is computed for the net
/// in use, as in a round that does not retrain); a retraining that changed the net is never
/// followed by a skip.
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct Stale {
    /// The labelled points when the last retraining kept its starting net (None: it did
    /// not, or there was none).
    kept_at: Option<usize>,
}

impl Stale {
    /// Growth of the labelled points after which a retraining that kept its start is tried
    /// again.
    const GROWTH: f64 = 1.25;

    /// Records the retraining from `start` (None: a new net) on `st` that returned `net`,
    /// and returns `net`.
    pub(super) fn record(&mut self, start: Option<Model>, net: Model, st: &RefineState) -> Model {
        *self = Stale::after(start.as_ref().map(|m| &m.mlp), &net.mlp, st);
        net
    }

    /// The state after a retraining from `start` (None: a new net) that returned `net`.
    fn after(start: Option<&Mlp>, net: &Mlp, st: &RefineState) -> Stale {
        Stale::of(start, net, labelled(st))
    }

    /// [`Stale::after`] with `n` labelled points.
    fn of(start: Option<&Mlp>, net: &Mlp, n: usize) -> Stale {
        let kept = start.is_some_and(|s| same_weights(s, net));
        Stale {
            kept_at: kept.then_some(n),
        }
    }

    /// Whether this round's retraining is skipped.
    pub(super) fn skips(&self, st: &RefineState) -> bool {
        self.skips_at(labelled(st))
    }

    /// [`Stale::skips`] with `n` labelled points.
    fn skips_at(&self, n: usize) -> bool {
        self.kept_at
            .is_some_and(|k| (n as f64) < Stale::GROWTH * k as f64)
    }
}

/// The labelled points of `st`.
fn labelled(st: &RefineState) -> usize {
    st.points.iter().filter(|p| p.labelled()).count()
}

/// Whether two nets have the same weights and scaling, but for the last layer's bias (the
/// setpoint hold folds a correction into it after every training, also when the training
/// returned its starting net).
fn same_weights(a: &Mlp, b: &Mlp) -> bool {
    let n = a.layers.len();
    n == b.layers.len()
        && a.in_center == b.in_center
        && a.in_half == b.in_half
        && a.out_center == b.out_center
        && a.out_half == b.out_half
        && a.layers
            .iter()
            .zip(&b.layers)
            .enumerate()
            .all(|(k, (x, y))| x.w == y.w && (k + 1 == n || x.b == y.b))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::Activation;

    fn net(seed: u64) -> Mlp {
        let (lo, hi) = ([-1.0, -2.0], [1.0, 2.0]);
        Mlp::new(
            &[2, 4, 1],
            Activation::Tanh,
            seed,
            &lo,
            &hi,
            &[-3.0],
            &[3.0],
        )
    }

    /// A retraining that returned its start (up to the last bias, which the setpoint hold
    /// moves) makes the next ones wait for 25 % more points; a changed net, a new net or
    /// a changed hidden bias never does.
    #[test]
    fn a_kept_start_skips_until_the_points_grow() {
        let a = net(1);
        let mut held = a.clone();
        held.layers[1].b[0] += 1e-9;
        let s = Stale::of(Some(&a), &held, 1000);
        assert!(s.skips_at(1000) && s.skips_at(1249));
        assert!(!s.skips_at(1250));
        assert!(!Stale::of(Some(&a), &net(2), 1000).skips_at(1000));
        assert!(!Stale::of(None, &a, 1000).skips_at(1000));
        let mut hidden = a.clone();
        hidden.layers[0].b[0] += 1e-9;
        assert!(!Stale::of(Some(&a), &hidden, 1000).skips_at(1000));
        assert!(!Stale::default().skips_at(0));
    }
}
