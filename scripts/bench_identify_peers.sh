#!/usr/bin/env bash
# Identification speed, robocal beside the Python references, in one session on this machine.
# Needs the peers' venv (see ../shared/peers/README.md):
#   python3 -m venv /tmp/peersenv && /tmp/peersenv/bin/pip install roboticstoolbox-python==1.5.0 \
#       spatialmath-python==1.1.18 pybotics==1.1.0 pin==4.1.0
# ../shared/peers/data is a plain file naming ../datasets/irb120-sim-peers (a flattened symlink), so
# the reference runs from a scratch copy under /tmp with a real link; nothing is copied into the repo.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
cargo bench --bench identify_peers 2>&1 | grep -E "peers [0-9]+:|time:|^identify_peers/"
run=$(mktemp -d /tmp/peers-run.XXXX)
cp "$root"/../shared/peers/*.py "$run"/
ln -s "$(cd "$root"/../shared/datasets/irb120-sim-peers && pwd)" "$run"/data
cd "$run"
OPENBLAS_NUM_THREADS=1 /tmp/peersenv/bin/python numpy_calib.py --n-id 75 1000 5000 --repeats 5 --out "$run"/numpy_calib.json
