"""python/Cargo.lock pins every crate it shares with the workspace's Cargo.lock to the same
version: the extension runs the very code `trainer` runs (the bit-for-bit comparisons with
the CLI rest on it). Crates only the extension uses (PyO3, numpy, ndarray 0.17) are free."""

from __future__ import annotations

import re

from conftest import REPO

ONLY_PYTHON = {"ndarray"}  # numpy's ndarray 0.17; the workspace has 0.16 for other crates


def _versions(path) -> dict[str, set[str]]:
    out: dict[str, set[str]] = {}
    for name, version in re.findall(r'\[\[package\]\]\nname = "([^"]+)"\nversion = "([^"]+)"',
                                    path.read_text()):
        out.setdefault(name, set()).add(version)
    return out


def test_shared_crates_same_versions():
    root, py = _versions(REPO / "Cargo.lock"), _versions(REPO / "python" / "Cargo.lock")
    assert "trainer" in py and "clarabel" in py
    differ = {n: (sorted(v), sorted(root[n])) for n, v in py.items()
              if n in root and n not in ONLY_PYTHON and not v <= root[n]}
    assert not differ, f"python/Cargo.lock differs from Cargo.lock (cargo update -p NAME --precise V): {differ}"
