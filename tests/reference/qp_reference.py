#!/usr/bin/env python3
"""Independent QP reference for a sound local certificate (not part of the build or CI).

For a problem whose MPC is a QP (linear plant, quadratic cost, affine constraints), builds
the condensed QP in NumPy from the problem file alone — its own reading of the plant's
expressions (evaluated by Python, affine so the matrices follow from unit perturbations),
RK4 written out here, the constraint placement of the README — and solves it with
quadprog (Goldfarb–Idnani dual active set, exact to rounding) at N seeded uniform states of
the domain. The deployed controller's output is `trainer eval` on the refined model,
clamped to the certificate's band [clamp_lo, clamp_hi]. Reports the largest
|kappa_QP - sat(kappa_NN)| (2-norm over the inputs) against the certificate's eps and the
number of exceedances; exits with status 1 if any state exceeds eps.

The OCP (trainer/src/mpc/ocp/mod.rs):
    min  sum_{k<N} (x_k - x_ref)'Q(x_k - x_ref) + (u_k - u_ref)'R(u_k - u_ref)
         + (x_N - x_ref)'P(x_N - x_ref)
    s.t. x_0 = x_s,  x_{k+1} = F(x_k, u_k)  (RK4 with ocp.rk4_substeps for kind = "ode",
                                              `next` for kind = "discrete",
                                              x1' = x2, x2' = u/mass for double_integrator)
         x_lo <= x_k <= x_hi, k = 1..N;  u_lo <= u_k <= u_hi, k = 0..N-1
         ocp.constraints: states only on x_1..x_N, inputs only on u_0..u_{N-1},
                          mixed on k = 1..N-1;  ocp.terminal_constraints on x_N.

Usage (from the repository root, after `trainer refine --config CFG --out DIR`):
    python3 tests/reference/qp_reference.py CFG DIR [--n 100000] [--seed 1] [--trainer BIN]
Needs Python >= 3.11, NumPy and `pip install quadprog`.
"""

import argparse
import json
import math
import re
import subprocess
import sys
import tempfile
import time
import tomllib

import numpy as np
import quadprog

FUNCS = {n: getattr(math, n) for n in ["sin", "cos", "tan", "exp", "log", "sqrt", "tanh"]}


def compile_exprs(exprs, names, params, defs):
    """Python callables for the expression strings (`^` is power)."""
    env = dict(FUNCS)
    env.update(params)
    env["pi"] = math.pi

    def conv(s):
        return s.replace("^", "**")

    def f(vals):
        scope = dict(env)
        scope.update(zip(names, vals))
        for d in defs:
            k, v = d.split("=", 1)
            scope[k.strip()] = eval(conv(v), {}, scope)
        return [float(eval(conv(e), {}, scope)) for e in exprs]

    return f


def plant(cfg):
    """(F(x, u) as a function, nx, nu)."""
    sysc = cfg["system"]
    kind = sysc["kind"]
    ocp = cfg["ocp"]
    if kind == "double_integrator":
        m = sysc.get("mass", 1.0)
        nx, nu, discrete = 2, 1, False
        rhs = lambda v: [v[1], v[2] / m]
    else:
        states, inputs = sysc["states"], sysc["inputs"]
        nx, nu = len(states), len(inputs)
        discrete = kind == "discrete"
        exprs = sysc["next"] if discrete else sysc["rhs"]
        rhs = compile_exprs(exprs, states + inputs, sysc.get("parameters", {}),
                            sysc.get("definitions", []))
    if discrete:
        return (lambda x, u: np.array(rhs(list(x) + list(u)))), nx, nu
    h = ocp["ts"] / ocp.get("rk4_substeps", 1)

    def step(x, u):
        x = np.array(x, float)
        f = lambda y: np.array(rhs(list(y) + list(u)))
        for _ in range(ocp.get("rk4_substeps", 1)):
            k1 = f(x)
            k2 = f(x + h / 2 * k1)
            k3 = f(x + h / 2 * k2)
            k4 = f(x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return x

    return step, nx, nu


def weight(spec, n):
    a = np.array(spec, float)
    return np.diag(a) if a.ndim == 1 else a.reshape(n, n)


def affine_parts(fun, n_in):
    """(J, c) with fun(v) = J v + c (fun affine: unit perturbations are exact)."""
    c = np.array(fun(np.zeros(n_in)), float)
    cols = [np.array(fun(np.eye(n_in)[j]), float) - c for j in range(n_in)]
    return np.array(cols).T.reshape(len(c), n_in), c


def constraint(text, names):
    """g(v) <= 0 from `lhs <= rhs` / `lhs >= rhs`, and which variables it uses."""
    op = "<=" if "<=" in text else ">="
    lhs, rhs = text.split(op)
    g = compile_exprs([f"({lhs}) - ({rhs})" if op == "<=" else f"({rhs}) - ({lhs})"], names, {}, [])
    used = [i for i, n in enumerate(names) if re.search(rf"\b{re.escape(n)}\b", text)]
    return (lambda v: g(v)[0]), used


def build(cfg):
    """Condensed QP data: cost 1/2 U'HU + (Fx x + f0)'U, constraints C U <= d0 + D x."""
    step, nx, nu = plant(cfg)
    o = cfg["ocp"]
    N = o["horizon"]
    J, c = affine_parts(lambda v: step(v[:nx], v[nx:]), nx + nu)
    A, B = J[:, :nx], J[:, nx:]
    Q, R, P = weight(o["q"], nx), weight(o["r"], nu), weight(o["p"], nx)
    xr = np.array(o.get("x_ref", [0.0] * nx))
    ur = np.array(o.get("u_ref", [0.0] * nu))
    # x_k = Phi_k x0 + Gam_k U + c_k
    Phi, Gam, cc = [np.eye(nx)], [np.zeros((nx, N * nu))], [np.zeros(nx)]
    for k in range(N):
        G = A @ Gam[-1]
        G[:, k * nu:(k + 1) * nu] += B
        Phi.append(A @ Phi[-1])
        Gam.append(G)
        cc.append(A @ cc[-1] + c)
    H = np.zeros((N * nu, N * nu))
    Fx = np.zeros((N * nu, nx))
    f0 = np.zeros(N * nu)
    for k in range(1, N + 1):
        W = P if k == N else Q
        H += 2 * Gam[k].T @ W @ Gam[k]
        Fx += 2 * Gam[k].T @ W @ Phi[k]
        f0 += 2 * Gam[k].T @ W @ (cc[k] - xr)
    for k in range(N):
        Ek = np.zeros((nu, N * nu))
        Ek[:, k * nu:(k + 1) * nu] = np.eye(nu)
        H += 2 * Ek.T @ R @ Ek
        f0 -= 2 * Ek.T @ R @ ur
    rows_C, rows_d, rows_D = [], [], []

    def add(a_x, a_u, k, b):
        """a_x' x_k + a_u' u_k <= b."""
        row = a_x @ Gam[k] if k >= 0 else np.zeros(N * nu)
        row = row.copy()
        if a_u is not None:
            row[k * nu:(k + 1) * nu] += a_u
        rows_C.append(row)
        rows_d.append(b - a_x @ cc[k])
        rows_D.append(-a_x @ Phi[k])

    for k in range(1, N + 1):
        for i in range(nx):
            e = np.eye(nx)[i]
            if math.isfinite(o["x_hi"][i]):
                add(e, None, k, o["x_hi"][i])
            if math.isfinite(o["x_lo"][i]):
                add(-e, None, k, -o["x_lo"][i])
    for k in range(N):
        for j in range(nu):
            e = np.eye(nu)[j]
            if math.isfinite(o["u_hi"][j]):
                add(np.zeros(nx), e, k, o["u_hi"][j])
            if math.isfinite(o["u_lo"][j]):
                add(np.zeros(nx), -e, k, -o["u_lo"][j])
    sysc = cfg["system"]
    names = (sysc.get("states", []) + sysc.get("inputs", [])) or ["x1", "x2", "u1"]
    for text in o.get("constraints", []):
        g, used = constraint(text, names)
        Jg, g0 = affine_parts(lambda v: [g(v)], nx + nu)
        a_x, a_u = Jg[0, :nx], Jg[0, nx:]
        s, i = any(u < nx for u in used), any(u >= nx for u in used)
        ks = range(1, N + 1) if s and not i else (range(N) if i and not s else range(1, N))
        for k in ks:
            add(a_x, a_u if i else None, k, -g0[0])
    for text in o.get("terminal_constraints", []):
        g, _ = constraint(text, names)
        Jg, g0 = affine_parts(lambda v: [g(v)], nx + nu)
        add(Jg[0, :nx], None, N, -g0[0])
    return H, Fx, f0, np.array(rows_C), np.array(rows_d), np.array(rows_D), nx, nu


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("config")
    ap.add_argument("refined", help="output directory of `trainer refine`")
    ap.add_argument("--n", type=int, default=100_000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--trainer", default="target/release/trainer")
    ap.add_argument("--json")
    a = ap.parse_args()
    with open(a.config, "rb") as fh:
        cfg = tomllib.load(fh)
    cert = json.load(open(f"{a.refined}/certificate.json"))
    eps = cert["eps"]
    H, Fx, f0, C, d0, D, nx, nu = build(cfg)
    lo, hi = np.array(cfg["domain"]["lo"]), np.array(cfg["domain"]["hi"])
    rng = np.random.default_rng(a.seed)
    xs = lo + (hi - lo) * rng.random((a.n, nx))
    t0 = time.time()
    kap = np.full((a.n, nu), np.nan)
    failed = 0
    for i, x in enumerate(xs):
        try:
            U = quadprog.solve_qp(H, -(Fx @ x + f0), -C.T, -(d0 + D @ x), 0)[0]
            kap[i] = U[:nu]
        except ValueError:
            failed += 1
    t_qp = time.time() - t0
    with tempfile.TemporaryDirectory() as td:
        sp = f"{td}/states.csv"
        np.savetxt(sp, xs, delimiter=",", header=",".join(f"x{k + 1}" for k in range(nx)),
                   comments="", fmt="%.17g")
        subprocess.run([a.trainer, "eval", "--model", f"{a.refined}/model.bin", "--states", sp,
                        "--out", f"{td}/out.csv"], check=True)
        out = np.loadtxt(f"{td}/out.csv", delimiter=",", skiprows=1, ndmin=2)
    net = np.clip(out[:, nx:nx + nu], cert["clamp_lo"], cert["clamp_hi"])
    ok = ~np.isnan(kap).any(axis=1)
    err = np.linalg.norm(kap[ok] - net[ok], axis=1)
    res = {
        "config": a.config,
        "states": int(a.n),
        "qp_infeasible": int(failed),
        "eps": eps,
        "guarantee": cert.get("guarantee"),
        "max_error": float(err.max()),
        "ratio_eps_over_max": float(eps / err.max()) if err.max() > 0 else None,
        "exceedances": int((err > eps).sum()),
        "qp_seconds": round(t_qp, 2),
    }
    print(json.dumps(res, indent=2))
    if a.json:
        json.dump(res, open(a.json, "w"), indent=2)
    sys.exit(1 if res["exceedances"] > 0 or failed > 0 else 0)


if __name__ == "__main__":
    main()
