#!/usr/bin/env python3
"""Independent IPOPT + KKT reference for ampc problem files (not part of the build or CI).

Reads a problem file (TOML), builds the same multiple-shooting OCP in CasADi from the plant's
expressions (its own parser of the expression language, not the trainer's), solves it with
IPOPT (tol 1e-10) at seeded random states of the domain X, computes du0/dx0 by CasADi's
parametric sensitivities (implicit differentiation of the KKT conditions at IPOPT's solution,
the active set taken from IPOPT's multipliers), and compares with `trainer solve` on the same
states: the largest relative errors of kappa and dkappa/dx, how often the two solvers end in
different local optima (and whose cost is lower), and the median per-state time of
IPOPT (solve + sensitivity) against ours (`solve_timing` example: cold solve + sensitivity).

The OCP (trainer/src/mpc/ocp.rs, README "Problem files"; issue 12 for the optional keys):
    min  sum_{k<N} (x_k - x_ref)'Q(x_k - x_ref) + (u_k - u_ref)'R(u_k - u_ref)
         + (x_N - x_ref)'P(x_N - x_ref)                       (k = 0 term included, a constant)
    s.t. x_0 = x_s,  x_{k+1} = F(x_k, u_k)  (RK4 with ocp.rk4_substeps for kind = "ode";
                                              `next` for kind = "discrete")
         x_lo <= x_k <= x_hi, k = 1..N;  u_lo <= u_k <= u_hi, k = 0..N-1
         ocp.constraints: in states only on x_1..x_N, in inputs only on u_0..u_{N-1},
                          mixed on k = 1..N-1;  ocp.terminal_constraints on x_N.
Built-in kinds (pendulum, cart_pole, double_integrator) are written out from their documented
equations (trainer/src/problem/model/*.rs).

IPOPT options: tol 1e-10, bound_relax_factor 0 (the bounds exactly as stated; IPOPT's default
relaxes them by 1e-8, which moves u0 by ~2e-7 where a state bound is active), one thread.
Errors: max |a - b| / max(1, max |b|) over the entries of kappa (resp. dkappa/dx) of a state,
b = IPOPT's; the maxima over the states where both solvers converge to the same optimum
(costs equal to 1e-6 relative). Timing: CPU time (process time for IPOPT, thread time for
ours) and wall clock, median over `--reps` repetitions per state, then over the states; the
IPOPT figure is the IPOPT call alone (the sensitivity computed here in NumPy is not
counted), ours is the cold solve + the KKT sensitivity. On a loaded machine trust the CPU
times: the wall clock of the longer IPOPT calls suffers more from preemption.

Usage (from the repository root, after `cargo build --release -p trainer --bin trainer
--example solve_timing`):
    python3 tests/reference/ipopt_compare.py configs/planar_quadrotor.toml [--n 100] [--seed 7]
        [--reps 3] [--json OUT.json] [--markdown] [--ipopt KEY=VALUE ...]
Needs Python >= 3.11 and `pip install casadi` (CasADi ships IPOPT with MUMPS).
"""

import argparse
import csv
import json
import math
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
import tomllib

# One core for IPOPT as for ours (MUMPS/BLAS threads off), set before CasADi loads them.
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import casadi as ca  # noqa: E402
import numpy as np  # noqa: E402

ROOT = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))

# ---- the expression language (grammar of trainer/src/problem/model/expr/parse.rs) ---------

FUNCS1 = {
    "sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "asin": ca.asin, "acos": ca.acos,
    "atan": ca.atan, "exp": ca.exp, "log": ca.log, "sqrt": ca.sqrt, "sinh": ca.sinh,
    "cosh": ca.cosh, "tanh": ca.tanh, "abs": ca.fabs,
}
FUNCS2 = {"atan2": ca.atan2, "min": ca.fmin, "max": ca.fmax}
TOKEN = re.compile(
    r"\s*(?:(?P<num>(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?)|(?P<name>[A-Za-z_][A-Za-z0-9_]*)"
    r"|(?P<op>[-+*/^(),]))"
)


class Parser:
    """expr = term {(+|-) term}; term = unary {(*|/) unary}; unary = "-" unary | power;
    power = atom ["^" unary] (right-associative); atom = number | pi | name | call | (expr)."""

    def __init__(self, text, env, key):
        self.toks, pos, self.key, self.text, self.env = [], 0, key, text, env
        while pos < len(text):
            if text[pos:].strip() == "":
                break
            m = TOKEN.match(text, pos)
            if not m:
                raise ValueError(f"{key}: cannot read '{text[pos:]}' in '{text}'")
            self.toks.append((m.lastgroup, m.group(m.lastgroup)))
            pos = m.end()
        self.i = 0

    def peek(self):
        return self.toks[self.i] if self.i < len(self.toks) else (None, None)

    def take(self, want=None):
        t = self.peek()
        if want is not None and t[1] != want:
            raise ValueError(f"{self.key}: expected '{want}' in '{self.text}'")
        self.i += 1
        return t

    def parse(self):
        e = self.expr()
        if self.i != len(self.toks):
            raise ValueError(f"{self.key}: trailing input in '{self.text}'")
        return e

    def expr(self):
        e = self.term()
        while self.peek()[1] in ("+", "-"):
            op = self.take()[1]
            r = self.term()
            e = e + r if op == "+" else e - r
        return e

    def term(self):
        e = self.unary()
        while self.peek()[1] in ("*", "/"):
            op = self.take()[1]
            r = self.unary()
            e = e * r if op == "*" else e / r
        return e

    def unary(self):
        if self.peek()[1] == "-":
            self.take()
            return -self.unary()
        return self.power()

    def power(self):
        a = self.atom()
        if self.peek()[1] == "^":
            self.take()
            return a ** self.unary()
        return a

    def atom(self):
        kind, val = self.take()
        if kind == "num":
            return float(val)
        if kind == "name":
            if self.peek()[1] == "(" and (val in FUNCS1 or val in FUNCS2):
                self.take("(")
                args = [self.expr()]
                while self.peek()[1] == ",":
                    self.take()
                    args.append(self.expr())
                self.take(")")
                f, n = (FUNCS1[val], 1) if val in FUNCS1 else (FUNCS2[val], 2)
                if len(args) != n:
                    raise ValueError(f"{self.key}: {val} takes {n} arguments")
                return f(*args)
            if val == "pi":
                return math.pi
            if val not in self.env:
                raise ValueError(f"{self.key}: unknown name '{val}' in '{self.text}'")
            return self.env[val]
        if val == "(":
            e = self.expr()
            self.take(")")
            return e
        raise ValueError(f"{self.key}: unexpected '{val}' in '{self.text}'")


def ev(text, env, key):
    return Parser(text, env, key).parse()


# ---- the plant ---------------------------------------------------------------------------

BUILTIN = {
    # kind: (states, inputs, default parameters, definitions, rhs), from the trainer's docs.
    "pendulum": (["x1", "x2"], ["u"], {"m": 1.0, "l": 1.0, "g": 9.81}, [],
                 ["x2", "u/(m*l^2) - g/l*sin(x1 + pi)"]),
    "cart_pole": (["p", "th", "pd", "thd"], ["F"],
                  {"m_cart": 1.0, "m_pole": 0.1, "l": 0.5, "g": 9.81},
                  ["mt = m_cart + m_pole",
                   "temp = (F + m_pole*l*thd^2*sin(th))/mt",
                   "thdd = (g*sin(th) - cos(th)*temp)/(l*(4/3 - m_pole*cos(th)^2/mt))",
                   "pdd = temp - m_pole*l*thdd*cos(th)/mt"],
                  ["pd", "thd", "pdd", "thdd"]),
    "double_integrator": (["x1", "x2"], ["u"], {"mass": 1.0}, [], ["x2", "u/mass"]),
}


class Plant:
    """Symbols x, u; env maps every name (states, inputs, parameters, definitions) to SX."""

    def __init__(self, sysd, ocp):
        kind = sysd["kind"]
        if kind in BUILTIN:
            states, inputs, params, defs, rhs = BUILTIN[kind]
            params = {k: float(sysd.get(k, v)) for k, v in params.items()}
            self.kind, eqs = "ode", rhs
        else:
            states, inputs = sysd["states"], sysd["inputs"]
            params = {k: float(v) for k, v in sysd.get("parameters", {}).items()}
            defs = sysd.get("definitions", [])
            self.kind = kind
            eqs = sysd["rhs"] if kind == "ode" else sysd["next"]
        self.states, self.inputs = states, inputs
        self.nx, self.nu = len(states), len(inputs)
        self.x = ca.SX.sym("x", self.nx)
        self.u = ca.SX.sym("u", self.nu)
        env = dict(params)
        env.update({n: self.x[i] for i, n in enumerate(states)})
        env.update({n: self.u[i] for i, n in enumerate(inputs)})
        for i, d in enumerate(defs):
            name, text = d.split("=", 1)
            env[name.strip()] = ev(text, env, f"system.definitions[{i}]")
        self.env = env
        f = ca.vertcat(*[ev(t, env, f"system.eq[{i}]") for i, t in enumerate(eqs)])
        if self.kind == "ode":
            ts, m = float(ocp["ts"]), int(ocp.get("rk4_substeps", 1))
            fc = ca.Function("f", [self.x, self.u], [f])
            h, xk = ts / m, self.x
            for _ in range(m):
                k1 = fc(xk, self.u)
                k2 = fc(xk + h / 2 * k1, self.u)
                k3 = fc(xk + h / 2 * k2, self.u)
                k4 = fc(xk + h * k3, self.u)
                xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            f = xk
        self.F = ca.Function("F", [self.x, self.u], [f])

    def expr(self, text, key):
        return ev(text, self.env, key)


def weight(v, n, key):
    a = np.array(v, dtype=float)
    if a.ndim == 1:
        a = np.diag(a)
    if a.shape != (n, n):
        raise ValueError(f"ocp.{key}: shape {a.shape}, expected {n} x {n}")
    return a


def split_constraint(text, key):
    for op in ("<=", ">="):
        if op in text:
            lhs, rhs = text.split(op, 1)
            return lhs, rhs, op
    raise ValueError(f"{key}: '{text}' is not 'lhs <= rhs' or 'lhs >= rhs'")


class Ocp:
    def __init__(self, cfg, ipopt_options=None):
        ocp = cfg["ocp"]
        self.plant = pl = Plant(cfg["system"], ocp)
        nx, nu, N = pl.nx, pl.nu, int(ocp["horizon"])
        self.N, self.nx, self.nu = N, nx, nu
        if "stages" in ocp:
            print("warning: ocp.stages (a robust design) is ignored", file=sys.stderr)
        Q, R, P = (weight(ocp[k], n, k) for k, n in (("q", nx), ("r", nu), ("p", nx)))
        xr = np.array(ocp.get("x_ref", [0.0] * nx), dtype=float)
        ur = np.array(ocp.get("u_ref", [0.0] * nu), dtype=float)
        self.x_lo = np.array(ocp["x_lo"], float)
        self.x_hi = np.array(ocp["x_hi"], float)
        self.u_lo = np.array(ocp["u_lo"], float)
        self.u_hi = np.array(ocp["u_hi"], float)
        # General constraints c(x, u) <= 0, classified by the symbols they depend on.
        path, term = [], []
        for key, lst, out in (("constraints", ocp.get("constraints", []), path),
                              ("terminal_constraints", ocp.get("terminal_constraints", []), term)):
            for i, t in enumerate(lst):
                k = f"ocp.{key}[{i}]"
                lhs, rhs, op = split_constraint(t, k)
                c = pl.expr(lhs, k) - pl.expr(rhs, k)
                c = c if op == "<=" else -c
                c = ca.SX(c)
                out.append((ca.Function("c", [pl.x, pl.u], [c]),
                            ca.depends_on(c, pl.x), ca.depends_on(c, pl.u)))
        xs = ca.SX.sym("xs", nx)
        X = [xs] + [ca.SX.sym(f"x{k}", nx) for k in range(1, N + 1)]
        U = [ca.SX.sym(f"u{k}", nu) for k in range(N)]
        J = 0
        g, lbg, ubg = [], [], []
        for k in range(N):
            dx, du = X[k] - xr, U[k] - ur
            J += ca.mtimes([dx.T, Q, dx]) + ca.mtimes([du.T, R, du])
            g.append(pl.F(X[k], U[k]) - X[k + 1])
            lbg += [0.0] * nx
            ubg += [0.0] * nx
        dN = X[N] - xr
        J += ca.mtimes([dN.T, P, dN])
        for c, dep_x, dep_u in path:
            if dep_x and dep_u:
                ks = range(1, N)
            elif dep_x:
                ks = range(1, N + 1)
            else:
                ks = range(0, N)
            for k in ks:
                uk = U[k] if k < N else ca.DM.zeros(nu)
                g.append(c(X[k], uk))
                lbg.append(-ca.inf)
                ubg.append(0.0)
        for c, _, dep_u in term:
            if dep_u:
                raise ValueError("terminal constraints must be in states only")
            g.append(c(X[N], ca.DM.zeros(nu)))
            lbg.append(-ca.inf)
            ubg.append(0.0)
        # Variables by stage: u_0, x_1, u_1, ..., x_N.
        w, lbw, ubw = [], [], []
        for k in range(N):
            w += [U[k], X[k + 1]]
            lbw += list(self.u_lo) + list(self.x_lo)
            ubw += list(self.u_hi) + list(self.x_hi)
        self.w = ca.vertcat(*w)
        self.lbw, self.ubw = np.array(lbw), np.array(ubw)
        self.lbg, self.ubg = np.array(lbg), np.array(ubg)
        nlp = {"x": self.w, "p": xs, "f": J, "g": ca.vertcat(*g)}
        opts = {"ipopt.tol": 1e-10, "ipopt.print_level": 0, "print_time": False,
                "ipopt.max_iter": 3000, "ipopt.sb": "yes", "ipopt.bound_relax_factor": 0.0}
        opts.update({f"ipopt.{k}": v for k, v in (ipopt_options or {}).items()})
        self.solver = ca.nlpsol("S", "ipopt", nlp, opts)
        # The KKT system's parts at a solution (w, lam): Hessian of the Lagrangian
        # L = J + lam'g in w, its mixed derivative in x_s, and the constraint Jacobians.
        lam = ca.SX.sym("lam", len(lbg))
        gv = nlp["g"]
        lag = J + ca.dot(lam, gv)
        grad = ca.gradient(lag, self.w)
        self.kkt_parts = ca.Function(
            "kkt", [self.w, xs, lam],
            [ca.hessian(lag, self.w)[0], ca.jacobian(grad, xs), gv,
             ca.jacobian(gv, self.w), ca.jacobian(gv, xs)])

    def initial_guess(self, xs):
        """x_k = x_s (clipped to the state box), u_k = 0 (clipped to the input box)."""
        xk = np.clip(xs, self.x_lo, self.x_hi)
        uk = np.clip(np.zeros(self.nu), self.u_lo, self.u_hi)
        return np.concatenate([np.concatenate([uk, xk]) for _ in range(self.N)])

    def solve(self, xs):
        """IPOPT from the initial guess; returns (u0, cost, du0/dxs, (wall, CPU) seconds of
        the IPOPT call, success, weakly active constraints). The cost includes the k = 0
        state term."""
        w0 = self.initial_guess(xs)
        t0, c0 = time.perf_counter(), time.process_time()
        r = self.solver(x0=w0, p=xs, lbx=self.lbw, ubx=self.ubw, lbg=self.lbg, ubg=self.ubg)
        t = (time.perf_counter() - t0, time.process_time() - c0)
        ok = self.solver.stats()["success"]
        self.last_status = self.solver.stats()["return_status"]
        w = np.array(r["x"]).ravel()
        lam_g = np.array(r["lam_g"]).ravel()
        lam_x = np.array(r["lam_x"]).ravel()
        jac, weak = self.sensitivity(xs, w, lam_g, lam_x)
        return w[: self.nu], float(r["f"]), jac, t, ok, weak

    def solve_only(self, xs):
        """(wall, CPU) seconds of one IPOPT call from the initial guess (no sensitivity)."""
        w0 = self.initial_guess(xs)
        t0, c0 = time.perf_counter(), time.process_time()
        self.solver(x0=w0, p=xs, lbx=self.lbw, ubx=self.ubw, lbg=self.lbg, ubg=self.ubg)
        return time.perf_counter() - t0, time.process_time() - c0

    def sensitivity(self, xs, w, lam_g, lam_x, weak_tol=1e-6):
        """dw*/dxs from the KKT conditions on the active set: with A the Jacobian of the
        equalities and active inequalities and E the rows of the active bounds,
        [H A' E'; A 0 0; E 0 0] d(w, lam_A, nu_A)/dxs = -(H_wx, A_x, 0).
        An inequality is active when its multiplier exceeds its distance to the bound (at an
        interior-point solution their product is ~mu, so an active constraint has a
        multiplier far above its slack and an inactive one the reverse); one with both below
        `weak_tol` is weakly active: counted, and treated as inactive (the one-sided
        derivative the trainer returns for weakly active constraints)."""
        H, Hwp, g, Jg, Jgp = (np.array(v) for v in self.kkt_parts(w, xs, lam_g))
        g = g.ravel()
        weak = 0

        def classify(val, lo, hi, lam):
            nonlocal weak
            dist = min(val - lo, hi - val)
            if abs(lam) < weak_tol and dist < weak_tol:
                weak += 1
                return False
            return abs(lam) > dist

        rows = [i for i in range(len(g)) if self.lbg[i] == self.ubg[i]
                or classify(g[i], self.lbg[i], self.ubg[i], lam_g[i])]
        bounds = [i for i in range(len(w)) if classify(w[i], self.lbw[i], self.ubw[i], lam_x[i])]
        n, m, b = len(w), len(rows), len(bounds)
        A = Jg[rows, :]
        E = np.zeros((b, n))
        for k, i in enumerate(bounds):
            E[k, i] = 1.0
        K = np.zeros((n + m + b, n + m + b))
        K[:n, :n] = H
        K[:n, n:n + m] = A.T
        K[:n, n + m:] = E.T
        K[n:n + m, :n] = A
        K[n + m:, :n] = E
        rhs = np.zeros((n + m + b, self.nx))
        rhs[:n] = -Hwp
        rhs[n:n + m] = -Jgp[rows, :]
        d = np.linalg.solve(K, rhs)
        self.last_active = (sum(self.lbg[i] != self.ubg[i] for i in rows), len(bounds))
        return d[: self.nu, :], weak


# ---- comparison --------------------------------------------------------------------------

def rel(a, b):
    """max |a - b| / max(1, max |b|): relative, absolute where the reference is below 1."""
    return float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b)))))


def run_trainer(args, cfg_path, states_csv):
    out = os.path.join(os.path.dirname(states_csv), "ours.csv")
    subprocess.run([args.trainer, "solve", "--config", cfg_path, "--states", states_csv,
                    "--out", out], check=True, capture_output=True)
    with open(out) as f:
        rows = list(csv.DictReader(f))
    timing = subprocess.run([args.timing, cfg_path, states_csv, str(args.reps)], check=True,
                            capture_output=True, text=True).stdout
    times = [(float(r["median_seconds"]), float(r["median_cpu_seconds"]))
             for r in csv.DictReader(timing.splitlines())]
    return rows, times


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("config")
    ap.add_argument("--n", type=int, default=100, help="random states of X (default 100)")
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--reps", type=int, default=3, help="timing repetitions per state")
    ap.add_argument("--trainer", default=os.path.join(ROOT, "target/release/trainer"))
    ap.add_argument("--timing",
                    default=os.path.join(ROOT, "target/release/examples/solve_timing"))
    ap.add_argument("--states", help="CSV of states (header x1,..,xn) instead of random ones")
    ap.add_argument("--json", help="write the per-state results here")
    ap.add_argument("--markdown", action="store_true", help="also print a table row")
    ap.add_argument("--ipopt", action="append", default=[], metavar="KEY=VALUE",
                    help="extra IPOPT option (repeatable), e.g. bound_relax_factor=1e-8")
    args = ap.parse_args()
    with open(args.config, "rb") as f:
        cfg = tomllib.load(f)
    extra = {}
    for kv in args.ipopt:
        k, v = kv.split("=", 1)
        try:
            extra[k] = float(v) if any(c in v for c in ".e") else int(v)
        except ValueError:
            extra[k] = v
    ocp = Ocp(cfg, extra)
    nx, nu = ocp.nx, ocp.nu
    if args.states:
        with open(args.states) as f:
            xs_all = np.array([[float(v) for v in r] for r in list(csv.reader(f))[1:] if r])
    else:
        rng = np.random.default_rng(args.seed)
        lo, hi = np.array(cfg["domain"]["lo"], float), np.array(cfg["domain"]["hi"], float)
        xs_all = lo + (hi - lo) * rng.random((args.n, nx))
    tmp = tempfile.mkdtemp(prefix="ipopt_compare_")
    states_csv = os.path.join(tmp, "states.csv")
    with open(states_csv, "w") as f:
        f.write(",".join(f"x{i + 1}" for i in range(nx)) + "\n")
        for x in xs_all:
            f.write(",".join(repr(float(v)) for v in x) + "\n")
    ours, our_times = run_trainer(args, args.config, states_csv)
    res = []
    for i, xs in enumerate(xs_all):
        u, f, jac, t_first, ok, weak = ocp.solve(xs)
        ts = [t_first] + [ocp.solve_only(xs) for _ in range(args.reps - 1)]
        r = ours[i]
        u_o = np.array([float(r[f"u{j + 1}"]) for j in range(nu)])
        jac_o = np.array([[float(r[f"du{j + 1}_dx{k + 1}"]) for k in range(nx)]
                          for j in range(nu)])
        res.append({
            "x": xs.tolist(), "ipopt_ok": bool(ok), "ipopt_status": ocp.last_status,
            "status": r["status"], "weak": weak,
            "active_constraints": int(ocp.last_active[0]), "active_bounds": ocp.last_active[1],
            "u_ipopt": u.tolist(), "u_ours": u_o.tolist(),
            "cost_ipopt": f, "cost_ours": float(r["cost"]),
            "err_u": rel(u_o, u), "err_du": rel(jac_o, jac),
            "t_ipopt": statistics.median(t[0] for t in ts),
            "cpu_ipopt": statistics.median(t[1] for t in ts),
            "t_ours": our_times[i][0], "cpu_ours": our_times[i][1],
        })
    both = [r for r in res if r["ipopt_ok"] and r["status"] == "converged"]
    same, lower, higher = [], 0, 0
    for r in both:
        d = r["cost_ours"] - r["cost_ipopt"]
        if abs(d) <= 1e-6 * max(1.0, abs(r["cost_ipopt"])):
            same.append(r)
        elif d < 0:
            lower += 1
        else:
            higher += 1
    med = lambda v: statistics.median(v) if v else float("nan")
    summary = {
        "config": args.config, "name": cfg.get("name"), "nx": nx, "nu": nu, "N": ocp.N,
        "states": len(res), "ipopt_failed": sum(not r["ipopt_ok"] for r in res),
        "ours_not_converged": sum(r["status"] != "converged" for r in res),
        "both_infeasible": sum(not r["ipopt_ok"] and r["ipopt_status"] == "Infeasible_Problem_Detected"
                               and r["status"] in ("soft", "infeasible") for r in res),
        "ipopt_failed_ours_converged": sum(not r["ipopt_ok"] and r["status"] == "converged"
                                           for r in res),
        "ours_failed_ipopt_ok": sum(r["ipopt_ok"] and r["status"] != "converged" for r in res),
        "compared": len(both), "same_optimum": len(same),
        "different_optimum_ours_lower": lower, "different_optimum_ours_higher": higher,
        "max_rel_err_u": max((r["err_u"] for r in same), default=float("nan")),
        "max_rel_err_du": max((r["err_du"] for r in same), default=float("nan")),
        "median_rel_err_du": med([r["err_du"] for r in same]),
        "states_err_du_above_1e-4": sum(r["err_du"] > 1e-4 for r in same),
        "weakly_active_states": sum(r["weak"] > 0 for r in res),
        "states_with_active_constraints": sum(r["active_constraints"] > 0 for r in same),
        "states_with_active_bounds": sum(r["active_bounds"] > 0 for r in same),
        "median_t_ipopt_ms": 1e3 * med([r["t_ipopt"] for r in res]),
        "median_t_ours_ms": 1e3 * med([r["t_ours"] for r in res]),
        "median_cpu_ipopt_ms": 1e3 * med([r["cpu_ipopt"] for r in res]),
        "median_cpu_ours_ms": 1e3 * med([r["cpu_ours"] for r in res]),
    }
    summary["speedup_wall"] = summary["median_t_ipopt_ms"] / summary["median_t_ours_ms"]
    summary["speedup_cpu"] = summary["median_cpu_ipopt_ms"] / summary["median_cpu_ours_ms"]
    print(json.dumps(summary, indent=1))
    if args.markdown:
        sm = summary
        print(f"| {sm['name']} | {nx}, {nu}, {ocp.N} | {sm['states']} | {sm['compared']} | "
              f"{sm['different_optimum_ours_lower']} / {sm['different_optimum_ours_higher']} | "
              f"{sm['both_infeasible']} | {sm['max_rel_err_u']:.1e} | {sm['max_rel_err_du']:.1e} | "
              f"{sm['weakly_active_states']} | {sm['median_cpu_ipopt_ms']:.2f} | "
              f"{sm['median_cpu_ours_ms']:.2f} | {sm['speedup_cpu']:.1f}x | "
              f"{sm['median_t_ipopt_ms']:.2f} / {sm['median_t_ours_ms']:.2f} |")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"summary": summary, "states": res}, f, indent=1)


if __name__ == "__main__":
    main()
