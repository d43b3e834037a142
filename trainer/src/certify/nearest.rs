//! [`KdTree`]: the exact nearest-neighbour distance to a fixed set of points, the inner
//! query of the covering radius's branch and bound
//! (`certificate::scattered_covering_radius`):
//! ```text
//! d²(c) = min_i Σ_k (c_k − p_ik)²        (k = 0, …, d−1 summed in that order)
//! ```
//! The tree splits the points at the median of their widest axis down to leaves of at most
//! [`LEAF`] points; a query visits the nearer side first and skips a side whose splitting
//! plane is at least the best distance away. Each candidate's squared distance is summed
//! in the same order as the brute-force minimum, so the result is bit-identical to it.

/// Points per leaf.
pub const LEAF: usize = 8;

enum Node {
    /// Indices `start..end` of `order`.
    Leaf { start: usize, end: usize },
    /// Split on `axis` at `value`: `left` holds points ≤ value, `right` the others.
    Split {
        axis: usize,
        value: f64,
        left: Box<Node>,
        right: Box<Node>,
    },
}

/// A k-d tree over row-major points of dimension `d` (module doc).
pub struct KdTree<'a> {
    points: &'a [f64],
    d: usize,
    order: Vec<usize>,
    root: Node,
}

impl<'a> KdTree<'a> {
    /// The tree of `points` (row-major, `d` per point; `d ≥ 1`).
    pub fn new(points: &'a [f64], d: usize) -> Self {
        let n = points.len() / d.max(1);
        let mut order: Vec<usize> = (0..n).collect();
        let root = build(points, d.max(1), &mut order, 0);
        KdTree {
            points,
            d: d.max(1),
            order,
            root,
        }
    }

    /// min over the points of the squared distance to `c` (+∞ without points).
    pub fn nearest_sq(&self, c: &[f64]) -> f64 {
        let mut best = f64::INFINITY;
        self.visit(&self.root, c, &mut best);
        best
    }

    fn visit(&self, node: &Node, c: &[f64], best: &mut f64) {
        match node {
            Node::Leaf { start, end } => {
                for &i in &self.order[*start..*end] {
                    let p = &self.points[i * self.d..(i + 1) * self.d];
                    let mut s = 0.0;
                    for k in 0..self.d {
                        let t = c[k] - p[k];
                        s += t * t;
                        if s >= *best {
                            break;
                        }
                    }
                    *best = best.min(s);
                }
            }
            Node::Split {
                axis,
                value,
                left,
                right,
            } => {
                let gap = c[*axis] - value;
                let (near, far) = if gap <= 0.0 {
                    (left, right)
                } else {
                    (right, left)
                };
                self.visit(near, c, best);
                // Every point of the far side is at least |gap| away along `axis`.
                if gap * gap < *best {
                    self.visit(far, c, best);
                }
            }
        }
    }
}

fn build(points: &[f64], d: usize, idx: &mut [usize], offset: usize) -> Node {
    let n = idx.len();
    if n <= LEAF {
        return Node::Leaf {
            start: offset,
            end: offset + n,
        };
    }
    let at = |i: usize, k: usize| points[i * d + k];
    let axis = (0..d)
        .max_by(|&a, &b| {
            let spread = |k: usize| {
                let (lo, hi) = idx
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &i| {
                        (l.min(at(i, k)), h.max(at(i, k)))
                    });
                hi - lo
            };
            spread(a).total_cmp(&spread(b))
        })
        .unwrap_or(0);
    let mid = n / 2;
    idx.select_nth_unstable_by(mid, |&a, &b| at(a, axis).total_cmp(&at(b, axis)));
    let value = at(idx[mid], axis);
    // Left: indices 0..=mid (all ≤ value); right: the rest (all ≥ value).
    let (l, r) = idx.split_at_mut(mid + 1);
    Node::Split {
        axis,
        value,
        left: Box::new(build(points, d, l, offset)),
        right: Box::new(build(points, d, r, offset + mid + 1)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::splitmix64;

    fn brute(points: &[f64], d: usize, c: &[f64]) -> f64 {
        points.chunks(d).fold(f64::INFINITY, |best, p| {
            let mut s = 0.0;
            for k in 0..d {
                let t = c[k] - p[k];
                s += t * t;
            }
            best.min(s)
        })
    }

    /// Bit-identical to the brute-force minimum at random queries, with duplicate points
    /// and coordinates tied on the splitting axis, in 1 to 7 dimensions.
    #[test]
    fn the_tree_agrees_with_brute_force() {
        let mut s = 7u64;
        let mut u = || {
            s += 1;
            (splitmix64(s) >> 11) as f64 / (1u64 << 53) as f64
        };
        for d in 1..=7 {
            for n in [0usize, 1, 5, 9, 100, 1000] {
                let mut pts: Vec<f64> = (0..n * d).map(|_| (u() * 8.0).round() / 4.0).collect();
                if n > 3 {
                    let dup = pts[..d].to_vec();
                    pts[d..2 * d].copy_from_slice(&dup);
                }
                let tree = KdTree::new(&pts, d);
                for _ in 0..200 {
                    let c: Vec<f64> = (0..d).map(|_| u() * 2.5 - 0.25).collect();
                    let (a, b) = (tree.nearest_sq(&c), brute(&pts, d, &c));
                    assert_eq!(a.to_bits(), b.to_bits(), "d {d} n {n} c {c:?}");
                }
            }
        }
    }
}
