#!/usr/bin/env python3
"""Coefficients of controller_core::activation::tanh_fast (numpy + scipy).

Near-minimax odd (7, 6) rational t(x) = x P(x²)/Q(x²) for the absolute error on [0, 8]:
bisection on δ of the linear feasibility problem |x P − tanh(x) Q| ≤ δ Q, Q(0) = 1, Q > 0,
x P ≤ (1 − 10⁻⁶) Q (keeps the f32 result below 1) on a grid, in the variable (x/8)².
Then x = y/K with K = p₃/q₃ makes both polynomials monic in w = y²; everything is rounded
to f32. The printed error is a dense-sample estimate in f32 arithmetic; the bound the crate
uses comes from its exhaustive test (`exhaustive_error_bounds`), not from here.
Usage: python3 controller-core/tools/fit_fast_tanh.py
"""
import numpy as np
from scipy.optimize import linprog

C, M, N, MU = 8.0, 3, 3, 1e-6
f32 = np.float32


def feasible(delta, u, zp, zq, th):
    """P, Q (Q(0) = 1) with |xP − th·Q| ≤ δQ, Q ≥ 10⁻⁶, xP ≤ (1 − μ)Q on the grid, or None."""
    one = zq[:, 0]
    rows = [
        (np.hstack([zp, -(th + delta)[:, None] * zq[:, 1:]]), (th + delta) * one),
        (np.hstack([-zp, (th - delta)[:, None] * zq[:, 1:]]), -(th - delta) * one),
        (np.hstack([0 * zp, -zq[:, 1:]]), one - 1e-6),
        (np.hstack([zp, -(1 - MU) * zq[:, 1:]]), (1 - MU) * one),
    ]
    a = np.vstack([r[0] for r in rows])
    b = np.concatenate([r[1] for r in rows])
    s = np.abs(a).max(1)
    r = linprog(np.zeros(a.shape[1]), A_ub=a / s[:, None], b_ub=b / s,
                bounds=[(None, None)] * a.shape[1], method="highs")
    return r.x if r.status == 0 else None


def main():
    x = np.sort(np.concatenate([np.linspace(0, C, 3000)[1:], np.linspace(0, 0.05, 50)[1:]]))
    u = (x / C) ** 2
    zp = np.stack([(x / C) * u**i for i in range(M + 1)], 1)
    zq = np.stack([u**i for i in range(N + 1)], 1)
    th = np.tanh(x)
    lo, hi = 0.0, 1e-2
    best = feasible(hi, u, zp, zq, th)
    for _ in range(40):
        mid = (lo + hi) / 2 if lo > 0 else hi / 4
        r = feasible(mid, u, zp, zq, th)
        lo, hi, best = (mid, hi, best) if r is None else (lo, mid, r)
        if hi - lo < 1e-3 * hi:
            break
    p = [best[i] / C ** (2 * i + 1) for i in range(M + 1)]
    q = [1.0] + [best[M + i] / C ** (2 * i) for i in range(1, N + 1)]
    k = p[M] / q[N]  # K^(2(N−M)−1) = q_N/p_M with N = M
    a = [p[i] / k ** (2 * i + 1) for i in range(M + 1)]
    b = [q[i] / k ** (2 * i) for i in range(N + 1)]
    a, b = [v / a[M] for v in a], [v / b[N] for v in b]
    fy, fa, fb = f32(k * 2.0**-28), [f32(v) for v in a[:M]], [f32(v) for v in b[:N]]
    print(f"grid minimax delta {hi:.3e}, K = {k!r}")
    print(f"FAST_Y = {fy!r}\nFAST_A = {[repr(v) for v in fa]}\nFAST_B = {[repr(v) for v in fb]}")
    xs = np.linspace(0, C, 2_000_001).astype(f32)
    y = ((xs * f32(2.0**28)).astype(np.float64).astype(np.int64).astype(f32)) * fy
    w = y * y
    num = y * (fa[0] + w * (fa[1] + w * (fa[2] + w)))
    den = fb[0] + w * (fb[1] + w * (fb[2] + w))
    t = num / den
    err = np.abs(t.astype(np.float64) - np.tanh(xs.astype(np.float64)))
    print(f"dense f32 sample: max error {err.max():.3e}, max t {t.max()!r}")


if __name__ == "__main__":
    main()
