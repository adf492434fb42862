#!/usr/bin/env bash
# Issue 69: the Monte-Carlo workloads on a GPU and on the same machine's CPU, in one
# sitting: writes results/gpu.csv and results/gpu.md (benchmarks/gpu.py says what runs;
# about 6 minutes on one H200 and its 16 cores). Where JAX finds no GPU it says so and
# runs nothing (exit 0), as run_all.sh's `gpu` step does.
#   bash benchmarks/gpu.sh                     # from the repository root or anywhere
#   bash benchmarks/gpu.sh --log gpu_run.log   # options go to benchmarks/gpu.py
set -euo pipefail
cd "$(dirname "$0")/.."
export PYTHONUNBUFFERED=1
PYTHON=${PYTHON:-$(command -v python || command -v python3)}
if ! "$PYTHON" benchmarks/gpu.py --probe; then
    echo "gpu.sh: skipped: no GPU found"
    exit 0
fi
"$PYTHON" benchmarks/gpu.py --out results/gpu "$@"
