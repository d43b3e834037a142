"""The stage functions' typed results: the certificate has certificate.json's keys (the
CLI's `trainer certify --json` of the same model and data gives the same record), export
writes controller-core's files, run returns its directory and certificate."""

from __future__ import annotations

import json

import numpy as np

import ampc
from conftest import REPO, run_cli


def test_dataset_arrays(certified):
    data = certified["data"]
    assert len(data) == 45
    assert data.x.shape == (45, 2) and data.u.shape == (45, 1) and data.du_dx.shape == (45, 1, 2)
    assert set(data.status) <= {"converged", "soft", "infeasible", "max_iterations", "numerical_failure"}
    u, du, status = certified["problem"].solve(data.x)
    labelled = np.array([s == "converged" for s in status])
    np.testing.assert_allclose(u[labelled], data.u[labelled], atol=1e-9)


def test_certificate_matches_cli(certified, tmp_path, trainer_bin):
    d = certified["dir"]
    cert = certified["cert"]
    certified["model"].save(tmp_path / "bare.bin")
    p = run_cli(trainer_bin, "certify", "--model", str(tmp_path / "bare.bin"), "--data",
                str(d / "dataset.bin"), "--json")
    cli = json.loads(p.stdout)
    assert set(cert) == set(cli)
    assert cert == cli
    assert cert.eps == cli["eps"] and cert.guarantee in ("sound", "statistical", "estimated")
    assert cert["hash"] == certified["model"].hash


def test_export_writes_files(certified, tmp_path):
    r = ampc.export(certified["problem"], certified["model"], certified["cert"],
                    tmp_path / "weights.rs", tmp_path / "weights.bin")
    assert isinstance(r, ampc.ExportResult)
    assert r.f32_allowance_libm > 0 and r.samples > 0
    assert "pub const NX: usize = 2;" in (tmp_path / "weights.rs").read_text()
    assert (tmp_path / "weights.bin").stat().st_size > 0


def test_run_returns_typed_result(tmp_path):
    text = (REPO / "python" / "tests" / "conftest.py").read_text()
    di = text.split('DI_TEXT = """', 1)[1].split('"""', 1)[0]
    di += "[closed_loop]\nsteps = 20\nrandom_initial_states = 1\nnoise_runs = 1\nseeds = 0\n[plots]\nerror_map_grid = [8, 6]\n"
    di += "[refine]\nenabled = \"off\"\n[certify]\nstatistical = 300\nclosed_loop = 300\n"
    problem = ampc.Problem.from_toml(di)
    r = ampc.run(problem, tmp_path)
    assert r.dir == tmp_path / "di_py"
    assert [s.stage for s in r.stages][:7] == [
        "sample", "validate", "train", "certify", "refine", "statistical", "export"]
    assert r.certificate == json.loads((r.dir / "certificate.json").read_text())
    u, flags = r.controller().eval(np.array([[0.5, 0.0]]))
    assert u.shape == (1, 1) and flags[0] == 0
    again = ampc.run(problem, tmp_path)
    assert all(s.skipped for s in again.stages)
