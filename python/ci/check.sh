#!/usr/bin/env bash
# The Python package's check (tests/run-all calls it): a fresh virtual environment, the
# wheel built from ./python by pip (maturin from PyPI, the `ci` cargo profile), the test
# dependencies, then pytest (python/tests) and the quickstart notebook executed.
# Fails loudly when anything is missing: no test is skipped for a missing package.
#
# The wheel is built with the `ci` profile (release optimisation, no debug info, 16 codegen
# units; python/Cargo.toml) — `pip install ./python` without settings builds `release`.
set -euo pipefail
cd "$(dirname "$0")/../.."
fail() { echo "FATAL: $*" >&2; exit 1; }
start=$(date +%s)

command -v python3 >/dev/null || fail "python3 not found: install Python ≥ 3.9"
python3 --version
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
python3 -m venv "$work/venv" ||
  fail "python3 -m venv failed: install the venv module (Debian: apt-get install python3-venv)"
py="$work/venv/bin/python"
"$py" -m pip --version || fail "pip is missing in the new virtual environment"

echo "== python: test dependencies (PyPI)"
"$py" -m pip install --quiet pytest numpy casadi matplotlib nbclient nbformat nbconvert ipykernel ||
  fail "cannot install the Python test dependencies from PyPI"

echo "== python: pip install ./python (maturin, cargo profile ci)"
build_start=$(date +%s)
MATURIN_PEP517_ARGS="--profile ci" "$py" -m pip install ./python ||
  fail "pip install ./python failed"
echo "wheel built and installed in $(($(date +%s) - build_start)) s"
# Imported from the installed wheel, not from the source folder.
(cd "$work" && "$py" -c "import ampc, sys; print('ampc from', ampc.__file__)")

# The trainer binary the tests compare with: AMPC_TRAINER, else the workspace's debug build
# (which `cargo test --workspace` has just built; a no-op then).
if [ -n "${AMPC_TRAINER:-}" ]; then
  trainer=$AMPC_TRAINER
else
  cargo build -p trainer --quiet
  trainer="${CARGO_TARGET_DIR:-$PWD/target}/debug/trainer"
fi
[ -x "$trainer" ] || fail "no trainer binary at $trainer"

echo "== python: pytest"
AMPC_TRAINER="$trainer" "$py" -m pytest python/tests -q -p no:cacheprovider --rootdir python/tests

echo "== python: the quickstart notebook"
nb_start=$(date +%s)
(cd "$work" && cp -r "$OLDPWD/python/examples" nb &&
  "$py" -m jupyter nbconvert --to notebook --execute --ExecutePreprocessor.timeout=300 \
    --output executed.ipynb nb/quickstart.ipynb) ||
  fail "the quickstart notebook failed"
echo "notebook executed in $(($(date +%s) - nb_start)) s"
echo "python check: $(($(date +%s) - start)) s"
