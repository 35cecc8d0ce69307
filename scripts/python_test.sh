#!/usr/bin/env bash
# Build the `robocal` Python package (crates/robocal-py, maturin + PyO3 over robocal-core) as a
# release wheel, install it in a venv of its own under target/pyenv, and run its pytest suite.
# Installs what it needs itself (maturin, pytest, numpy from the package registry). Reuses the
# workspace's target directory, so a warm run rebuilds nothing. Exits non-zero on any failure,
# including a pytest run that collected no test.
#
#   scripts/python_test.sh [pytest args…]     PYTHON=python3.11 to choose the interpreter
#
# The pytest suite compares against the CLI binary target/debug/robocal when it exists (after
# `cargo test`), or ROBOCAL_BIN; without it those comparisons are skipped, and say so.
set -euo pipefail
cd "$(dirname "$0")/.."
start=$(date +%s)
elapsed() { echo "$(($(date +%s) - start)) s"; }

python=${PYTHON:-python3}
venv=target/pyenv
if [ ! -x "$venv/bin/python" ]; then
    "$python" -m venv "$venv"
fi
"$venv/bin/python" -m pip install -q --disable-pip-version-check "maturin>=1.9.4,<2" "pytest>=8" "numpy>=1.21"
echo "python_test: venv ready ($("$venv/bin/python" --version), $(elapsed))"

# A release wheel (what a user installs), then that wheel into the venv. --locked: the committed
# Cargo.lock must already hold pyo3 and numpy.
rm -f target/wheels/robocal-*.whl
"$venv/bin/maturin" build --release --locked -q -m crates/robocal-py/Cargo.toml -i "$venv/bin/python" -o target/wheels
wheel=$(ls target/wheels/robocal-*.whl)
"$venv/bin/python" -m pip install -q --disable-pip-version-check --force-reinstall --no-deps "$wheel"
echo "python_test: built and installed $(basename "$wheel") ($(elapsed))"

status=0
"$venv/bin/python" -m pytest crates/robocal-py/tests -q -p no:cacheprovider "$@" || status=$?
if [ "$status" -eq 5 ]; then
    echo "python_test: pytest collected no test" >&2
fi
echo "python_test: exit $status after $(elapsed)"
exit "$status"
