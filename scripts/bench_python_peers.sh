#!/usr/bin/env bash
# The robocal Python package beside the Python peers, in one run on this machine: batched FK of
# 100,000 poses (Robotics Toolbox's C++ ETS.eval, pinocchio, numpy) and identification (numpy +
# scipy). A venv of its own under target/peersenv with the peers' pinned versions and the release
# wheel of crates/robocal-py; the peers' scripts are imported from a scratch copy under /tmp (as
# bench_identify_peers.sh does), nothing of theirs is copied into the repository. BLAS is pinned to
# one thread (../shared/peers/README.md). Figures: BENCHMARKS.md.
#
#   scripts/bench_python_peers.sh [--repeats 5]
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
venv=target/peersenv
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
fi
"$venv/bin/python" -m pip install -q --disable-pip-version-check "maturin>=1.9.4,<2" \
    roboticstoolbox-python==1.5.0 spatialmath-python==1.1.18 pin==4.1.0 scipy numpy
rm -f target/wheels/robocal-*.whl
"$venv/bin/maturin" build --release --locked -q -m crates/robocal-py/Cargo.toml -i "$venv/bin/python" -o target/wheels
"$venv/bin/python" -m pip install -q --disable-pip-version-check --force-reinstall --no-deps target/wheels/robocal-*.whl
run=$(mktemp -d /tmp/pypeers-run.XXXX)
cp "$root"/../shared/peers/*.py "$run"/
ln -s "$(cd "$root"/../shared/datasets/irb120-sim-peers && pwd)" "$run"/data
cd "$run"
OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 "$root/$venv/bin/python" "$root/scripts/bench_python_peers.py" \
    --peers "$run" --out "$run/bench_python_peers.json" "$@"
echo "raw figures: $run/bench_python_peers.json"
