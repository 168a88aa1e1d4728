#!/usr/bin/env bash
# The device check of issue 34 on a machine with an NVIDIA GPU, in at most 8 minutes: the CUDA
# tests, CPU/CUDA agreement on the first simulated second of the main job, GPU throughput at
# 1e3, 1e4 and 1e5 rods; results in benchmarks/results/device_check.json and .md.  Without a
# GPU it prints one line and writes nothing.  The logic and the options are in
# scripts/device_check.py (--help); this wrapper only picks the Python.
#
#     bash scripts/device_check.sh [--budget 480] [--out PATH]
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
python="${PYTHON:-}"
if [[ -z "$python" ]]; then
    if [[ -x "$root/.venv/bin/python" ]]; then python="$root/.venv/bin/python"; else python="python3"; fi
fi
export DEVICE_CHECK_WRAPPER="scripts/device_check.sh"
exec "$python" "$root/scripts/device_check.py" "$@"
