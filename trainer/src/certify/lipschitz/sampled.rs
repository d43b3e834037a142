//! Sampled estimates (not bounds from above): the lower bound on L_NN, max ‖∂κ_NN/∂x‖₂
//! over seeded samples of X refined by local search, and the estimates of L_MPC from
//! labelled points (max ‖∂κ/∂x‖₂ and neighbour difference quotients
//! ‖κ(x_i) − κ(x_j)‖/‖x_i − x_j‖).

use super::norm::jacobian_norm;
use crate::learn::mlp::{Mlp, Workspace};

/// Sampled lower bound on L_NN: max ‖∂κ_NN/∂x‖₂ over `n` seeded uniform points of the box,
/// the best 10 refined by a shrinking random local search (every value is an attained
/// ‖J(x)‖₂ at a point of X, so the result is a true lower bound).
///
/// The points are screened in blocks, in parallel, by the f32 lane engine
/// ([`crate::learn::mlp::Lanes::eval_batch`]), which only ranks them; the 10 largest are
/// evaluated in f64 ([`Mlp::eval_batch`]: each point's Jacobian bit for bit that of a single
/// evaluation) and searched side by side (their candidates in one block per step), so every
/// value taken is an f64 ‖J(x)‖₂. Each screen value depends only on its point and the
/// ranking on no order, so the result is the same for any number of threads.
pub fn sampled_lower_bound(mlp: &Mlp, lo: &[f64], hi: &[f64], n: usize, seed: u64) -> f64 {
    use rayon::prelude::*;
    /// Points per parallel task.
    const CHUNK: usize = 1024;
    let (nx, nu) = (mlp.nx(), mlp.nu());
    let norm_of = |j: &[f64]| jacobian_norm(j, nu, nx);
    let xs: Vec<f64> = (0..n)
        .flat_map(|i| {
            (0..nx).map(move |k| {
                lo[k] + (hi[k] - lo[k]) * crate::rng::uniform(seed, i as u64, k as u64)
            })
        })
        .collect();
    if nx == 0 {
        return 0.0;
    }
    // The screen: every sample's ‖J‖ in f32 (the lane engine), only to rank them.
    let screen: Vec<f64> = xs
        .par_chunks(CHUNK * nx)
        .flat_map_iter(|x| {
            let m = x.len() / nx;
            let (mut u, mut j) = (vec![0.0; m * nu], vec![0.0; m * nu * nx]);
            crate::learn::mlp::Lanes::default().eval_batch(mlp, x, &mut u, Some(&mut j));
            j.chunks_exact((nu * nx).max(1))
                .map(&norm_of)
                .collect::<Vec<_>>()
        })
        .collect();
    // The 10 largest of the screen (NaN first, as `total_cmp` ranks it; ties in index
    // order), then their norms in f64: every value below is an f64 evaluation.
    let mut order: Vec<usize> = (0..screen.len()).collect();
    let top = order.len().min(10);
    if top < order.len() {
        order.select_nth_unstable_by(top, |&a, &b| {
            screen[b].total_cmp(&screen[a]).then(a.cmp(&b))
        });
    }
    order.truncate(top);
    order.sort_by(|&a, &b| screen[b].total_cmp(&screen[a]).then(a.cmp(&b)));
    // The searches side by side: each iteration evaluates the candidates of all of them in
    // one block (each point's Jacobian bit for bit that of a single evaluation, so each
    // search takes the path it takes alone); search k draws its steps from key k.
    let ns = order.len();
    let mut x: Vec<f64> = order
        .iter()
        .flat_map(|&i| xs[i * nx..(i + 1) * nx].iter().copied())
        .collect();
    let mut ws = Workspace::default();
    let (mut u, mut j) = (vec![0.0; ns * nu], vec![0.0; ns * nu * nx]);
    mlp.eval_batch(&x, &mut u, Some(&mut j), &mut ws);
    let mut v: Vec<f64> = j.chunks_exact((nu * nx).max(1)).map(&norm_of).collect();
    let mut radius: Vec<f64> = (0..ns * nx)
        .map(|e| 0.05 * (hi[e % nx] - lo[e % nx]))
        .collect();
    let mut cand = vec![0.0; ns * nx];
    for it in 0..400 {
        for (k, ck) in cand.chunks_exact_mut(nx).enumerate() {
            for (d, c) in ck.iter_mut().enumerate() {
                let r = 2.0 * crate::rng::uniform(seed ^ 0x5151, (k * 1000 + it) as u64, d as u64)
                    - 1.0;
                *c = (x[k * nx + d] + r * radius[k * nx + d]).clamp(lo[d], hi[d]);
            }
        }
        mlp.eval_batch(&cand, &mut u, Some(&mut j), &mut ws);
        for k in 0..ns {
            let c = norm_of(&j[k * nu * nx..(k + 1) * nu * nx]);
            if c > v[k] {
                v[k] = c;
                x[k * nx..(k + 1) * nx].copy_from_slice(&cand[k * nx..(k + 1) * nx]);
            } else if it % 20 == 19 {
                radius[k * nx..(k + 1) * nx]
                    .iter_mut()
                    .for_each(|r| *r *= 0.5);
            }
        }
    }
    // Each search only raises its start's value: the largest is the bound.
    v.into_iter().fold(0.0, f64::max)
}

/// L_MPC estimates from labelled points: (max ‖∂κ/∂x‖₂ over the points, max difference
/// quotient ‖κ(x_i) − κ(x_j)‖/‖x_i − x_j‖ over each point's 2·nx nearest neighbours).
pub fn mpc_estimates(
    x: &[f64],
    u: &[f64],
    du: &[f64],
    use_jac: &[bool],
    nx: usize,
    nu: usize,
) -> (f64, f64) {
    let n = use_jac.len();
    let mut max_sens = 0.0f64;
    for i in 0..n {
        if use_jac[i] {
            max_sens = max_sens.max(jacobian_norm(&du[i * nu * nx..(i + 1) * nu * nx], nu, nx));
        }
    }
    let k = (2 * nx).min(n.saturating_sub(1));
    let stride = if n > 20_000 { n / 20_000 } else { 1 };
    let dist = |i: usize, j: usize| -> f64 {
        (0..nx)
            .map(|c| (x[i * nx + c] - x[j * nx + c]).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    // Each point's neighbours on its own (in parallel, a buffer per worker): the largest
    // quotient does not depend on the order, so the result is the same for every thread count.
    use rayon::prelude::*;
    let rows: Vec<usize> = (0..n).step_by(stride).collect();
    let max_q = rows
        .par_iter()
        .map_init(Vec::new, |near: &mut Vec<(f64, usize)>, &i| {
            near.clear();
            near.extend((0..n).filter(|&j| j != i).map(|j| (dist(i, j), j)));
            if near.len() > k {
                near.select_nth_unstable_by(k, |a, b| a.0.total_cmp(&b.0));
                near.truncate(k);
            }
            let mut q = 0.0f64;
            for &(d, j) in near.iter() {
                if d > 0.0 {
                    let du: f64 = (0..nu)
                        .map(|r| (u[i * nu + r] - u[j * nu + r]).powi(2))
                        .sum::<f64>()
                        .sqrt();
                    q = q.max(du / d);
                }
            }
            q
        })
        .reduce(|| 0.0f64, f64::max);
    (max_sens, max_q)
}
