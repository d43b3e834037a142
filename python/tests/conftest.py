"""Shared fixtures: the repository, the `trainer` binary the Python results are compared
with, and a small certified double-integrator model (built once per session)."""

from __future__ import annotations

import csv
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import ampc

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def trainer_bin() -> Path:
    """`AMPC_TRAINER`, else the repository's target/{debug,release}/trainer. A missing
    binary fails the tests (no silent skip): build it with `cargo build -p trainer`."""
    env = os.environ.get("AMPC_TRAINER")
    candidates = [Path(env)] if env else [
        REPO / "target" / "debug" / "trainer",
        REPO / "target" / "release" / "trainer",
    ]
    for c in candidates:
        if c.is_file() and os.access(c, os.X_OK):
            return c
    pytest.fail(f"no trainer binary at {[str(c) for c in candidates]}: run `cargo build -p trainer` or set AMPC_TRAINER")


def run_cli(trainer: Path, *args: str) -> subprocess.CompletedProcess:
    p = subprocess.run([str(trainer), *args], capture_output=True, text=True)
    assert p.returncode == 0, f"trainer {' '.join(args)} failed:\n{p.stderr}"
    return p


def write_states(path: Path, x: np.ndarray) -> None:
    with open(path, "w") as f:
        f.write(",".join(f"x{i + 1}" for i in range(x.shape[1])) + "\n")
        for row in x:
            f.write(",".join(repr(float(v)) for v in row) + "\n")


def read_csv(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path) as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


DI_TEXT = """
name = "di_py"
[system]
kind = "double_integrator"
[ocp]
ts = 0.1
horizon = 10
q = [1.0, 0.1]
r = [0.1]
p = [1.0, 0.1]
x_lo = [-5.0, -1.0]
x_hi = [5.0, 1.0]
u_lo = [-1.0]
u_hi = [1.0]
[domain]
lo = [-2.0, -1.0]
hi = [2.0, 1.0]
[sampling]
sampler = "grid"
counts = [9, 5]
[training]
hidden = [8]
epochs = 60
validation_n = 20
"""


@pytest.fixture(scope="session")
def certified(tmp_path_factory):
    """A trained and certified double integrator through the stage functions: the model
    file (certificate stored), the certificate file and the objects."""
    d = tmp_path_factory.mktemp("di")
    problem = ampc.Problem.from_toml(DI_TEXT)
    data = ampc.sample(problem, d / "dataset.bin")
    model = ampc.train(problem, data)
    cert = ampc.certify(problem, model, data)
    model.save(d / "model.bin", cert.text)
    cert.save(d / "certificate.json")
    return {"dir": d, "problem": problem, "data": data, "model": model, "cert": cert}
