"""Problem.solve against `trainer solve` on the same states: equal labels and statuses."""

from __future__ import annotations

import numpy as np

import ampc
from conftest import REPO, read_csv, run_cli, write_states


def test_solve_equals_cli(tmp_path, trainer_bin):
    cfg = REPO / "configs" / "pendulum.toml"
    problem = ampc.Problem.from_file(cfg)
    lo, hi = problem.domain
    rng = np.random.default_rng(7)
    # Inside X and beyond it (more than X: states the solver may label soft or not at all).
    x = lo + (hi - lo) * rng.uniform(-0.3, 1.3, size=(40, problem.nx))
    u, du, status = problem.solve(x)
    assert u.shape == (40, problem.nu) and du.shape == (40, problem.nu, problem.nx)
    assert len(status) == 40

    write_states(tmp_path / "states.csv", x)
    run_cli(trainer_bin, "solve", "--config", str(cfg), "--states", str(tmp_path / "states.csv"),
            "--out", str(tmp_path / "out.csv"))
    head, rows = read_csv(tmp_path / "out.csv")
    nx, nu = problem.nx, problem.nu
    cli = np.array([[float(v) for v in r[: nx + nu + nu * nx]] for r in rows])
    np.testing.assert_array_equal(cli[:, :nx], x)
    # Bit for bit (NaN where unlabelled on both sides).
    np.testing.assert_array_equal(cli[:, nx:nx + nu], u)
    np.testing.assert_array_equal(cli[:, nx + nu:].reshape(-1, nu, nx), du)
    assert [r[head.index("status")] for r in rows] == status
    assert "converged" in status


def test_solve_accepts_non_contiguous(tmp_path):
    problem = ampc.Problem.from_file(REPO / "configs" / "double_integrator.toml")
    x = np.asfortranarray(np.array([[0.5, 0.1], [-1.0, 0.2], [2.0, -0.5]]))
    u, du, _ = problem.solve(x)
    u2, du2, _ = problem.solve(np.ascontiguousarray(x))
    np.testing.assert_array_equal(u, u2)
    np.testing.assert_array_equal(du, du2)
