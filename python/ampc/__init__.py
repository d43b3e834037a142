"""ampc from Python: certified approximate MPC, stage by stage, with NumPy arrays.

The computations are the Rust trainer's (the extension module ``ampc._ampc``, built with
PyO3 and maturin); this package adds the typed results:

- :class:`Problem` — a problem file; ``solve(X)`` → ``(U, dU_dX, status)`` as ``trainer solve``;
- :func:`sample`, :func:`train`, :func:`certify`, :func:`export`, :func:`run` — the
  subcommands' computations; :func:`certify` returns a :class:`Certificate` (a dict with
  the keys of ``certificate.json``);
- :class:`Controller` — the exported controller; ``eval(X)`` → ``(U, flags)``, bit for bit
  what ``trainer eval`` writes;
- :func:`from_casadi` — a CasADi SX function as the problem file's ``[system]`` text.

Every error of the trainer is raised as :class:`AmpcError` with its message.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union

from . import _ampc
from ._ampc import AmpcError, Controller, Dataset, Model, Problem
from .casadi import from_casadi

__all__ = [
    "AmpcError",
    "Certificate",
    "Controller",
    "Dataset",
    "ExportResult",
    "Model",
    "Problem",
    "RunResult",
    "certify",
    "export",
    "from_casadi",
    "run",
    "sample",
    "train",
]

PathLike = Union[str, "os.PathLike[str]"]


class Certificate(dict):
    """A certificate: a dict with exactly the keys of ``certificate.json`` (``eps``,
    ``guarantee``, ``hash``, ``problem_hash``, …); :attr:`text` is the sealed file text
    (what :meth:`save` writes and what :func:`export` re-reads and re-checks)."""

    def __init__(self, text: str) -> None:
        super().__init__(json.loads(text))
        self.text: str = text

    @classmethod
    def load(cls, path: PathLike) -> "Certificate":
        """Reads a ``certificate.json``."""
        with open(path, encoding="utf-8") as f:
            return cls(f.read())

    def save(self, path: PathLike) -> None:
        """Writes the sealed ``certificate.json`` text."""
        with open(path, "w", encoding="utf-8") as f:
            f.write(self.text)

    @property
    def eps(self) -> float:
        """ε: the bound on ‖κ − κ_NN‖ over X (with the f32 allowance)."""
        return float(self["eps"])

    @property
    def guarantee(self) -> str:
        """The certificate's tier: ``sound``, ``statistical`` or ``estimated``."""
        return str(self["guarantee"])


@dataclass(frozen=True)
class ExportResult:
    """What :func:`export` wrote and its f32 analysis (``trainer export``'s report)."""

    rust: Path
    postcard: Path
    f32_allowance_libm: float
    f32_allowance_fast: float
    f32_observed_libm: float
    f32_observed_fast: float
    samples: int
    boxes: int


@dataclass(frozen=True)
class StageResult:
    """One stage of :func:`run`: ``trainer run``'s stage line."""

    stage: str
    skipped: bool
    seconds: float
    summary: str
    outputs: List[str]


@dataclass(frozen=True)
class RunResult:
    """A pipeline run: its directory, each stage, the regularized net's certificate and the
    files a program uses next."""

    dir: Path
    stages: List[StageResult]
    certificate: Certificate
    model: Path
    weights_rs: Path
    weights_bin: Path
    extra: Dict[str, Any] = field(default_factory=dict)

    def controller(self) -> Controller:
        """The exported controller of the run (its model under ``certificate.json``)."""
        return Controller(str(self.model), str(self.dir / "certificate.json"))


def sample(problem: Problem, path: PathLike) -> Dataset:
    """``trainer sample``: labels the problem's sampling plan with the MPC (κ, ∂κ/∂x and
    each solve's status) and saves the dataset at ``path``."""
    return _ampc.sample(problem, os.fspath(path))


def train(
    problem: Problem,
    data: Dataset,
    validation: Optional[Dataset] = None,
    nominal: bool = False,
) -> Model:
    """``trainer train``: the sensitivity-regularized net (``nominal=True``: λ₂ = λ₃ = 0)
    from the problem's ``[training]``; ``validation`` (default ``data``) for its statistics."""
    return _ampc.train(problem, data, validation, nominal)


def certify(
    problem: Problem,
    model: Model,
    data: Dataset,
    validation: Optional[Dataset] = None,
) -> Certificate:
    """``trainer certify``: Theorem 1's certificate, ε = ε_D + (L_MPC + L_NN)·r plus the
    deployed controller's f32 allowance, with the keys of ``certificate.json``."""
    return Certificate(_ampc.certify(problem, model, data, validation))


def export(
    problem: Problem,
    model: Model,
    certificate: Certificate,
    rust: PathLike,
    postcard: PathLike,
) -> ExportResult:
    """``trainer export --rust … --postcard …``: controller-core's ``weights.rs`` and blob of
    the net under the certificate (re-read and re-checked from its sealed text)."""
    r = _ampc.export(problem, model, certificate.text, os.fspath(rust), os.fspath(postcard))
    return ExportResult(rust=Path(rust), postcard=Path(postcard), **r)


def run(problem: Problem, out: PathLike = "runs", force: Sequence[str] = ()) -> RunResult:
    """``trainer run``: the whole (nominal) pipeline into ``out/<name>/``, each stage skipped
    when its inputs are unchanged (``force`` names stages to redo). The robust design loop
    (``[robust]``) stays with ``trainer run``."""
    stages, d = _ampc.run(problem, os.fspath(out), list(force))
    d = Path(d)
    return RunResult(
        dir=d,
        stages=[StageResult(**s) for s in stages],
        certificate=Certificate.load(d / "certificate.json"),
        model=d / "model_regularized.bin",
        weights_rs=d / "weights.rs",
        weights_bin=d / "weights.bin",
    )
