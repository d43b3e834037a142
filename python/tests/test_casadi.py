"""from_casadi: do-mpc's CSTR written in CasADi, converted only by from_casadi, solves with
ampc and agrees with IPOPT on the same OCP; an unsupported operation is named."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

import ampc
from cstr import cstr

# The OCP (same in both): track C_b = 0.6 as do-mpc's CSTR example does, quadratic in the
# inputs' distance from a mid-range u_ref, do-mpc's state and input bounds, its step
# t_step = 0.005 h, RK4 with one step per sample, N = 20.
TS, N = 0.005, 20
Q = np.array([0.0, 1.0, 0.0, 0.0])
R = np.array([1e-3, 1e-9])
X_REF = np.array([0.8, 0.6, 134.0, 130.0])
U_REF = np.array([50.0, -4250.0])
X_LO, X_HI = [0.1, 0.1, 50.0, 50.0], [2.0, 2.0, 140.0, 140.0]
U_LO, U_HI = [5.0, -8500.0], [100.0, 0.0]
P_ALPHA_BETA = {"alpha": 1.0, "beta": 1.0}


def _problem_text(system: str) -> str:
    fl = lambda v: "[" + ", ".join(repr(float(a)) for a in v) + "]"
    return f"""name = "cstr"
{system}
[ocp]
ts = {TS}
horizon = {N}
q = {fl(Q)}
r = {fl(R)}
p = {fl(Q)}
x_ref = {fl(X_REF)}
u_ref = {fl(U_REF)}
setpoint_tol = 1e300  # do-mpc's tracking cost: its reference is no equilibrium (check waived)
x_lo = {fl(X_LO)}
x_hi = {fl(X_HI)}
u_lo = {fl(U_LO)}
u_hi = {fl(U_HI)}
[domain]
lo = [0.5, 0.3, 125.0, 120.0]
hi = [1.2, 0.8, 138.0, 135.0]
[sampling]
sampler = "halton"
n = 20
[solver]
tol = 1e-10
"""


def _ipopt(f: ca.Function, x0: np.ndarray) -> tuple[np.ndarray, float]:
    """The same OCP in CasADi: multiple shooting, RK4 (one step per sample), x_0 fixed,
    state bounds on x_1..x_N, cost Σ_{k<N} ℓ(x_k, u_k) + V_f(x_N) (the k = 0 state term
    included, as ampc reports its cost)."""
    p = ca.DM(list(P_ALPHA_BETA.values()))
    xs = [ca.SX.sym(f"x{k}", 4) for k in range(N + 1)]
    us = [ca.SX.sym(f"u{k}", 2) for k in range(N)]
    Qm, Rm = ca.diag(Q), ca.diag(R)

    def rk4(x, u):
        k1 = f(x, u, p)
        k2 = f(x + TS / 2 * k1, u, p)
        k3 = f(x + TS / 2 * k2, u, p)
        k4 = f(x + TS * k3, u, p)
        return x + TS / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    cost, g = 0, [xs[0] - x0]
    for k in range(N):
        dx, du = xs[k] - X_REF, us[k] - U_REF
        cost += ca.mtimes([dx.T, Qm, dx]) + ca.mtimes([du.T, Rm, du])
        g.append(rk4(xs[k], us[k]) - xs[k + 1])
    dx = xs[N] - X_REF
    cost += ca.mtimes([dx.T, Qm, dx])
    z = ca.vertcat(*[v for k in range(N) for v in (xs[k], us[k])], xs[N])
    lbz, ubz, z0 = [], [], []
    for k in range(N):
        lbz += ([-np.inf] * 4 if k == 0 else X_LO) + U_LO
        ubz += ([np.inf] * 4 if k == 0 else X_HI) + U_HI
        z0 += list(x0) + list(U_REF)
    lbz += X_LO
    ubz += X_HI
    z0 += list(x0)
    solver = ca.nlpsol("ocp", "ipopt", {"x": z, "f": cost, "g": ca.vertcat(*g)},
                       {"ipopt.tol": 1e-12, "ipopt.print_level": 0, "print_time": False,
                        "ipopt.max_iter": 3000, "ipopt.bound_relax_factor": 0.0})
    sol = solver(x0=z0, lbx=lbz, ubx=ubz, lbg=0, ubg=0)
    assert solver.stats()["success"], solver.stats()["return_status"]
    zs = np.array(sol["x"]).ravel()
    return zs[4:6], float(sol["f"])


def test_cstr_from_casadi_agrees_with_ipopt():
    f, x, u, _ = cstr()
    system = ampc.from_casadi(f, x, u, P_ALPHA_BETA)
    assert 'states = ["C_a", "C_b", "T_R", "T_K"]' in system
    problem = ampc.Problem.from_toml(_problem_text(system))
    # do-mpc's initial state of the example, and two more inside X.
    x0s = np.array([[0.8, 0.5, 134.14, 130.0], [1.0, 0.4, 130.0, 128.0], [0.6, 0.7, 136.0, 125.0]])
    u, _, status = problem.solve(x0s)
    assert status == ["converged"] * 3, status
    for i, x0 in enumerate(x0s):
        u_ip, cost_ip = _ipopt(f, x0)
        # Both solve the same NLP to a tight KKT tolerance (ampc `solver.tol = 1e-10` on
        # its scaled residual; IPOPT 1e-12 with bound_relax_factor = 0, so that IPOPT does
        # not relax the active bounds by 1e-8 and find a slightly lower cost). Measured:
        # u₀ agrees to ≤ 2e-11 of each input's range, the cost to ≤ 4e-13 relative. The
        # bounds leave ~500× room for rounding; a different model, constant or
        # discretisation moves u₀ by percents of the range.
        span = np.array(U_HI) - np.array(U_LO)
        assert np.all(np.abs(u[i] - u_ip) <= 1e-8 * span), (x0, u[i], u_ip)
        cost = _ampc_cost(problem, x0)
        assert abs(cost - cost_ip) <= 1e-10 * max(1.0, abs(cost_ip)), (cost, cost_ip)


def _ampc_cost(problem: ampc.Problem, x0: np.ndarray) -> float:
    # `trainer solve`'s cost column: the label's cost.
    return float(problem.solve(x0[None, :], with_cost=True)[3][0])


def test_unsupported_operation_named():
    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    f = ca.Function("f", [x, u], [ca.vertcat(x[1], ca.floor(u) - x[0])])
    with pytest.raises(ampc.AmpcError, match="OP_FLOOR"):
        ampc.from_casadi(f, x, u)


def test_conversion_keeps_values():
    """The converted [system] evaluates to CasADi's own numbers (one RK4 step through
    Problem.step against RK4 of f in CasADi)."""
    f, x, u, _ = cstr()
    problem = ampc.Problem.from_toml(_problem_text(ampc.from_casadi(f, x, u, P_ALPHA_BETA)))
    p = ca.DM([1.0, 1.0])
    x0, u0 = np.array([0.8, 0.5, 134.14, 130.0]), np.array([20.0, -3000.0])
    k1 = f(x0, u0, p)
    k2 = f(x0 + TS / 2 * k1, u0, p)
    k3 = f(x0 + TS / 2 * k2, u0, p)
    k4 = f(x0 + TS * k3, u0, p)
    ref = np.array(x0 + TS / 6 * (k1 + 2 * k2 + 2 * k3 + k4)).ravel()
    np.testing.assert_allclose(problem.step(x0, u0), ref, rtol=1e-13)


def test_do_mpc_struct_symbols():
    """do-mpc keeps a model's variables in casadi.tools structures (`model.x`, `model.u`):
    their entries' names are the states' and inputs' names."""
    from casadi.tools import entry, struct_symSX

    x = struct_symSX([entry("pos"), entry("vel")])
    u = struct_symSX([entry("force")])
    rhs = ca.vertcat(x["vel"], u["force"] - 2.0 * ca.sin(x["pos"]))
    f = ca.Function("f", [x, u], [rhs])
    system = ampc.from_casadi(f, x, u)
    assert 'states = ["pos", "vel"]' in system and 'inputs = ["force"]' in system
    assert '"force - (2*sin(pos))"' in system, system  # CasADi's 2·v is OP_TWICE
