"""Errors are ampc.AmpcError (an Exception) carrying the trainer's message."""

from __future__ import annotations

import numpy as np
import pytest

import ampc
from conftest import DI_TEXT


def test_error_is_exception_subclass():
    assert issubclass(ampc.AmpcError, Exception)


def test_bad_key_names_the_key():
    with pytest.raises(ampc.AmpcError, match=r"ocp\.horizon"):
        ampc.Problem.from_toml(DI_TEXT.replace("horizon = 10", "horizon = 0"))


def test_unknown_key_named():
    with pytest.raises(ampc.AmpcError, match="horizn"):
        ampc.Problem.from_toml(DI_TEXT.replace("horizon = 10", "horizon = 10\nhorizn = 3"))


def test_missing_file_named(tmp_path):
    p = tmp_path / "nope.toml"
    with pytest.raises(ampc.AmpcError, match="nope.toml"):
        ampc.Problem.from_file(p)
    with pytest.raises(ampc.AmpcError, match="nope.bin"):
        ampc.Controller(tmp_path / "nope.bin")


def test_expression_error_names_key_and_name():
    text = DI_TEXT.replace(
        'kind = "double_integrator"',
        'kind = "ode"\nstates = ["p", "v"]\ninputs = ["f"]\nrhs = ["v", "f - sprng"]',
    )
    with pytest.raises(ampc.AmpcError, match=r"system\.rhs\[1\].*sprng"):
        ampc.Problem.from_toml(text)


def test_wrong_shape_named():
    problem = ampc.Problem.from_toml(DI_TEXT)
    with pytest.raises(ampc.AmpcError, match=r"shape \(2, 3\)"):
        problem.solve(np.zeros((2, 3)))


def test_tampered_certificate_refused(certified, tmp_path):
    text = certified["cert"].text.replace('"eps": ', '"eps": 1', 1)
    (tmp_path / "c.json").write_text(text)
    with pytest.raises(ampc.AmpcError, match="c.json"):
        ampc.Controller(certified["dir"] / "model.bin", tmp_path / "c.json")
