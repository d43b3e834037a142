"""The CSTR of do-mpc's examples (examples/CSTR/template_model.py), written in CasADi as
do-mpc writes it: states C_a, C_b [mol/l], T_R, T_K [°C]; inputs F [1/h], Q_dot [kW];
uncertain parameters alpha, beta (nominal 1). Time in hours."""

from __future__ import annotations

import casadi as ca

# do-mpc's constants, unchanged.
K0_ab = 1.287e12
K0_bc = 1.287e12
K0_ad = 9.043e9
R_gas = 8.3144621e-3
E_A_ab = 9758.3 * 1.00
E_A_bc = 9758.3 * 1.00
E_A_ad = 8560.0 * 1.0
H_R_ab = 4.2
H_R_bc = -11.0
H_R_ad = -41.85
Rou = 0.9342
Cp = 3.01
Cp_k = 2.0
A_R = 0.215
V_R = 10.01
m_k = 5.0
T_in = 130.0
K_w = 4032.0
C_A0 = (5.7 + 4.5) / 2.0 * 1.0


def cstr():
    """(f, x, u, p): f(x, u, p) = ẋ as a CasADi Function, the SX symbols of x and u, and
    the symbols of p (alpha, beta)."""
    C_a, C_b, T_R, T_K = (ca.SX.sym(n) for n in ("C_a", "C_b", "T_R", "T_K"))
    F, Q_dot = ca.SX.sym("F"), ca.SX.sym("Q_dot")
    alpha, beta = ca.SX.sym("alpha"), ca.SX.sym("beta")
    T_dif = T_R - T_K
    K_1 = beta * K0_ab * ca.exp((-E_A_ab) / ((T_R + 273.15)))
    K_2 = K0_bc * ca.exp((-E_A_bc) / ((T_R + 273.15)))
    K_3 = K0_ad * ca.exp((-alpha * E_A_ad) / ((T_R + 273.15)))
    rhs = ca.vertcat(
        F * (C_A0 - C_a) - K_1 * C_a - K_3 * (C_a**2),
        -F * C_b + K_1 * C_a - K_2 * C_b,
        ((K_1 * C_a * H_R_ab + K_2 * C_b * H_R_bc + K_3 * (C_a**2) * H_R_ad) / (-Rou * Cp))
        + F * (T_in - T_R)
        + (((K_w * A_R) * (-T_dif)) / (Rou * Cp * V_R)),
        (Q_dot + K_w * A_R * (T_dif)) / (m_k * Cp_k),
    )
    x = ca.vertcat(C_a, C_b, T_R, T_K)
    u = ca.vertcat(F, Q_dot)
    p = ca.vertcat(alpha, beta)
    return ca.Function("cstr", [x, u, p], [rhs]), x, u, p
