"""Controller.eval against `trainer eval`: the same states through both, the same bits."""

from __future__ import annotations

import numpy as np

import ampc
from conftest import read_csv, run_cli, write_states


def _states(problem: ampc.Problem, n: int) -> np.ndarray:
    lo, hi = problem.domain
    rng = np.random.default_rng(3)
    # Inside X, beyond it (flag 1, projected), and near the band's edges (clamped).
    x = lo + (hi - lo) * rng.uniform(-0.5, 1.5, size=(n, problem.nx))
    x[:5] = rng.normal(size=(5, problem.nx)) * 1e-30  # tiny values: f32 rounding to subnormal/zero
    return x


def test_eval_bit_identical_to_cli(certified, tmp_path, trainer_bin):
    d, problem = certified["dir"], certified["problem"]
    x = _states(problem, 500)
    write_states(tmp_path / "states.csv", x)
    for cert_args, ctrl in [
        ([], ampc.Controller(d / "model.bin")),
        (["--certificate", str(d / "certificate.json")],
         ampc.Controller(str(d / "model.bin"), str(d / "certificate.json"))),
    ]:
        u, flags = ctrl.eval(x)
        assert u.dtype == np.float32 and flags.dtype == np.uint8
        out = tmp_path / f"eval{len(cert_args)}.csv"
        run_cli(trainer_bin, "eval", "--model", str(d / "model.bin"), "--states",
                str(tmp_path / "states.csv"), "--out", str(out), *cert_args)
        head, rows = read_csv(out)
        nx, nu = problem.nx, problem.nu
        cli_u = np.array([[float(v) for v in r[nx:nx + nu]] for r in rows])
        cli_flags = np.array([int(r[-1]) for r in rows])
        # The CLI prints the f32 as the f64 it widens to ({:?}, exact): compare the bits.
        assert (cli_u.astype(np.float32).view(np.uint32) == u.view(np.uint32)).all()
        assert (cli_u == u.astype(np.float64)).all()
        np.testing.assert_array_equal(cli_flags, flags)
        assert (flags & 1).any() and (flags == 0).any()


def test_eval_non_finite_is_flagged(certified):
    ctrl = ampc.Controller(certified["dir"] / "model.bin")
    u, flags = ctrl.eval(np.array([[np.nan, 0.0], [0.0, np.inf]]))
    assert (flags == 2).all()
    assert np.isfinite(u).all()
