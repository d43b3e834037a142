"""JAX anchor of the training benchmark: the work of `trainer train` (regularized, default
`[training]` settings) on the embedded pendulum's 350-point grid, written in plain JAX.

Reproduces trainer/src/learn/{train.rs, mlp/mod.rs, mlp/loss.rs}:
  * net 2-10-10-1, tanh hidden, linear output; a0 = (x - c)/h (c, h: centre/half-width of
    [domain] lo/hi), u = o + s*y (o, s: centre/half-width of ocp.u_lo/u_hi);
    Glorot-uniform weights, zero biases (JAX's RNG, not the trainer's: other initial weights);
  * loss = l1/B sum|u - k|^2 + l2/B sum_{jac usable} |du/dx - dk/dx|_F^2 + l3 sum_j |W~_j|_F^2,
    (l1, l2, l3) = (1, 3, 0.05), W~_1 = W_1 diag(1/h), W~_last = diag(s) W_last; du/dx by
    jax.jacfwd of the per-sample net (value as aux), vmapped;
  * Adam lr 1e-2, betas 0.9/0.999, eps 1e-8 (bias-corrected as in train.rs), minibatch 35,
    2000 epochs x 10 minibatches = 20,000 steps, reshuffled every epoch; float32.
Data (mirrors TrainSet::from_dataset, exactly, from the CSV columns): rows whose `status` is
not `converged`/`soft` are dropped; rows with a non-empty `degenerate` or a non-finite
Jacobian keep their value term and drop their Jacobian term (B stays the batch size). A last
partial minibatch (n not a multiple of the batch size) is handled by padding with weight 0.

Usage:
  /work/main/target/release/trainer sample --out /tmp/jaxp.bin --quiet   # also writes /tmp/jaxp.csv
  python3 tests/reference/jax_train.py /tmp/jaxp.csv                     # pendulum defaults
  python3 tests/reference/jax_train.py /tmp/jaxp.csv --mode step --runs 3
  python3 tests/reference/jax_train.py data.csv --lo -1,-1 --hi 1,1 --u-lo -1 --u-hi 1

Timing: `--mode scan` (default, the fastest form measured): one jitted function runs all
epochs (lax.scan over epochs, each a per-epoch permutation + lax.scan over its minibatch
steps). `--mode step`: one jitted Adam step, driven by a Python loop (shuffling in numpy).
TIMED: a full 20,000-step run (shuffles, forward/Jacobian passes, gradients, Adam updates),
ended by block_until_ready. NOT TIMED: CSV loading, initialisation, the warm-up call (one
full untimed run, which includes compilation), the final metrics. The trainer's own run
additionally logs loss/eps_D/validation R^2 every 20 epochs and labels 1000 validation
states; neither is done here. XLA may use several threads (the trainer trains on one); to
pin it to one: XLA_FLAGS="--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1".

Printed: the wall seconds of each timed run, the final loss terms, train eps_D =
max_i |k_i - k_NN(x_i)| and R^2 on the training set (net evaluated in float64 from the
trained float32 weights), for the raw net and with the setpoint hold that `trainer train`
applies by default (bias shifted so that k_NN(x_ref) = k(x_ref); pendulum: x_ref = 0,
k(0) = 0 as `trainer solve` gives; options --x-ref, --k-ref).

Written and run with JAX 0.10.2 (jaxlib CPU), NumPy 2.4.6, Python 3. Needs only jax + numpy.
"""

import argparse
import csv
import math
import time

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

TWO_PI = 2.0 * math.pi


def floats(s):
    return [float(v) for v in s.split(",")]


def load_csv(path):
    """(x, u, du, use_jac) of the labelled rows, as TrainSet::from_dataset keeps them."""
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    cols = rows[0].keys()
    nx = sum(1 for c in cols if c[0] == "x" and c[1:].isdigit())
    nu = sum(1 for c in cols if c[0] == "u" and c[1:].isdigit())
    x, u, du, use_jac = [], [], [], []
    for r in rows:
        if r.get("status", "converged") not in ("converged", "soft"):
            continue  # unlabelled: dropped
        x.append([float(r[f"x{i}"]) for i in range(1, nx + 1)])
        u.append([float(r[f"u{j}"]) for j in range(1, nu + 1)])
        d = [[float(r.get(f"du{j}_dx{i}") or "nan") for i in range(1, nx + 1)]
             for j in range(1, nu + 1)]
        ok = not r.get("degenerate") and np.isfinite(d).all()
        du.append(d if ok else np.zeros((nu, nx)).tolist())
        use_jac.append(ok)
    return np.array(x), np.array(u), np.array(du), np.array(use_jac, dtype=np.float64)


def init_params(key, widths):
    params = []
    for inp, out in zip(widths[:-1], widths[1:]):
        key, k = jax.random.split(key)
        lim = math.sqrt(6.0 / (inp + out))
        w = jax.random.uniform(k, (out, inp), jnp.float32, -lim, lim)
        params.append((w, jnp.zeros((out,), jnp.float32)))
    return params


def make(sc, lam, lr, epochs, bs, n):
    c, h, o, s = (jnp.asarray(v, jnp.float32) for v in sc)
    l1, l2, l3 = lam
    steps = -(-n // bs)  # minibatches per epoch (last one padded with weight 0)
    pad = steps * bs - n
    b1, b2, eps = 0.9, 0.999, 1e-8

    def net1(params, x):  # one state -> (u, u); u twice so jacfwd returns the value as aux
        a = (x - c) / h
        for w, b in params[:-1]:
            a = jnp.tanh(w @ a + b)
        w, b = params[-1]
        u = o + s * (w @ a + b)
        return u, u

    jac_and_val = jax.vmap(jax.jacfwd(net1, argnums=1, has_aux=True), in_axes=(None, 0))

    def loss(params, x, u, du, mj, wt):
        j, y = jac_and_val(params, x)  # (B, nu, nx), (B, nu)
        inv_b = 1.0 / jnp.sum(wt)
        val = l1 * inv_b * jnp.sum(wt[:, None] * (y - u) ** 2)
        jac = l2 * inv_b * jnp.sum((wt * mj)[:, None, None] * (j - du) ** 2)
        ws = [w for w, _ in params]
        ws[0] = ws[0] / h[None, :]
        ws[-1] = s[:, None] * ws[-1]
        reg = l3 * sum(jnp.sum(w * w) for w in ws)
        return val + jac + reg, (val, jac, reg)

    grad = jax.grad(lambda *a: loss(*a)[0])

    def adam_step(state, batch):
        params, m, v, t = state
        g = grad(params, *batch)
        t = t + 1.0
        c1, c2 = 1.0 - b1 ** t, 1.0 - b2 ** t
        m = jax.tree.map(lambda m, g: b1 * m + (1.0 - b1) * g, m, g)
        v = jax.tree.map(lambda v, g: b2 * v + (1.0 - b2) * g * g, v, g)
        params = jax.tree.map(lambda p, m, v: p - lr * (m / c1) / (jnp.sqrt(v / c2) + eps),
                              params, m, v)
        return (params, m, v, t), None

    def batches(data, idx, wt):  # idx, wt: (steps, bs)
        x, u, du, mj = data
        return (x[idx], u[idx], du[idx], mj[idx], wt)

    def state0(params):
        z = jax.tree.map(jnp.zeros_like, params)
        return (params, z, jax.tree.map(jnp.zeros_like, params), jnp.float32(0.0))

    wt_ep = jnp.concatenate([jnp.ones(n), jnp.zeros(pad)]).astype(jnp.float32).reshape(steps, bs)

    @jax.jit
    def train_scan(params, key, data):
        def epoch(state, e):
            perm = jax.random.permutation(jax.random.fold_in(key, e), n)
            idx = jnp.concatenate([perm, jnp.zeros(pad, perm.dtype)]).reshape(steps, bs)
            state, _ = lax.scan(adam_step, state, batches(data, idx, wt_ep))
            return state, None

        state, _ = lax.scan(epoch, state0(params), jnp.arange(epochs))
        return state[0]

    step_jit = jax.jit(lambda state, batch: adam_step(state, batch)[0])

    def train_step(params, key, data):
        rng = np.random.default_rng(int(jax.random.randint(key, (), 0, 2**31 - 1)))
        state = state0(params)
        wt, data = np.asarray(wt_ep), tuple(np.asarray(d) for d in data)
        for _ in range(epochs):
            idx = np.concatenate([rng.permutation(n), np.zeros(pad, np.int64)]).reshape(steps, bs)
            x, u, du, mj, w = batches(data, idx, wt)  # numpy gathers
            for k in range(steps):
                state = step_jit(state, (x[k], u[k], du[k], mj[k], w[k]))
        return state[0]

    full_loss = jax.jit(lambda p, data: loss(p, *data, jnp.ones(n, jnp.float32))[1])
    return train_scan, train_step, full_loss


def forward64(params, x, sc):
    c, h, o, s = sc
    a = ((x - c) / h).T
    for w, b in params[:-1]:
        a = np.tanh(np.asarray(w, np.float64) @ a + np.asarray(b, np.float64)[:, None])
    w, b = params[-1]
    return (o[:, None] + s[:, None] * (np.asarray(w, np.float64) @ a
                                       + np.asarray(b, np.float64)[:, None])).T


def stats(pred, u):
    eps_d = np.max(np.linalg.norm(pred - u, axis=1))
    r2 = 1.0 - np.sum((pred - u) ** 2) / np.sum((u - u.mean(axis=0)) ** 2)
    return eps_d, r2


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("csv", help="CSV written by `trainer sample` (x*, u*, du*_dx*, status, degenerate)")
    p.add_argument("--lo", type=floats, default=[-TWO_PI, -1.0], help="domain lo (pendulum)")
    p.add_argument("--hi", type=floats, default=[TWO_PI, 1.0], help="domain hi (pendulum)")
    p.add_argument("--u-lo", type=floats, default=[-15.0], help="ocp.u_lo (pendulum)")
    p.add_argument("--u-hi", type=floats, default=[15.0], help="ocp.u_hi (pendulum)")
    p.add_argument("--hidden", type=lambda s: [int(v) for v in s.split(",")], default=[10, 10])
    p.add_argument("--lambda", dest="lam", type=floats, default=[1.0, 3.0, 0.05])
    p.add_argument("--lr", type=float, default=1e-2)
    p.add_argument("--epochs", type=int, default=2000)
    p.add_argument("--batch", type=int, default=35)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--mode", choices=["scan", "step"], default="scan")
    p.add_argument("--runs", type=int, default=1, help="timed runs after the warm-up")
    p.add_argument("--x-ref", type=floats, default=None, help="setpoint (default origin)")
    p.add_argument("--k-ref", type=floats, default=None, help="k(x_ref) (default 0)")
    a = p.parse_args()

    x, u, du, mj = load_csv(a.csv)
    n, nx, nu = x.shape[0], x.shape[1], u.shape[1]
    lo, hi, ulo, uhi = (np.array(v) for v in (a.lo, a.hi, a.u_lo, a.u_hi))
    sc = ((lo + hi) / 2, (hi - lo) / 2, (ulo + uhi) / 2, (uhi - ulo) / 2)
    data = tuple(jnp.asarray(v, jnp.float32) for v in (x, u, du, mj))
    key_init, key_shuf = jax.random.split(jax.random.PRNGKey(a.seed))
    params0 = init_params(key_init, [nx, *a.hidden, nu])
    train_scan, train_step, full_loss = make(sc, a.lam, a.lr, a.epochs, a.batch, n)
    train = train_scan if a.mode == "scan" else train_step
    steps = a.epochs * -(-n // a.batch)
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}; {n} labelled points "
          f"({int(mj.sum())} with a Jacobian label); {steps} Adam steps; mode {a.mode}")

    t0 = time.perf_counter()
    jax.block_until_ready(train(params0, key_shuf, data))  # warm-up: compile + one full run
    print(f"warm-up (compile + run, not the benchmark): {time.perf_counter() - t0:.3f} s")
    for r in range(a.runs):
        t0 = time.perf_counter()
        params = jax.block_until_ready(train(params0, key_shuf, data))
        print(f"timed run {r + 1}: {time.perf_counter() - t0:.3f} s wall")

    val, jac, reg = (float(v) for v in full_loss(params, data))
    print(f"final loss on the training set: {val + jac + reg:.6g} "
          f"(value {val:.6g}, jacobian {jac:.6g}, weights {reg:.6g})")
    eps_d, r2 = stats(forward64(params, x, sc), u)
    print(f"raw net:            eps_D = {eps_d:.6g}   R2(train) = {r2:.6f}")
    x_ref = np.array(a.x_ref or [0.0] * nx)
    k_ref = np.array(a.k_ref or [0.0] * nu)
    shift = k_ref - forward64(params, x_ref[None, :], sc)[0]
    eps_d, r2 = stats(forward64(params, x, sc) + shift, u)
    print(f"with setpoint hold: eps_D = {eps_d:.6g}   R2(train) = {r2:.6f}   (shift {shift})")


if __name__ == "__main__":
    main()
