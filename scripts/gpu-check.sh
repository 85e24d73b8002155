#!/usr/bin/env bash
# A GPU machine's check (benchmarks/gpu_check.py): SAC, the forward model and MPC, and the SAR hand
# study at 1/50, on the device and on the CPU; <= 10 min on one GPU; nonzero on any error.
#   scripts/gpu-check.sh                       # on the GPU machine (device tool: run scripts/gpu-check.sh)
#   scripts/gpu-check.sh --device cpu --quick  # a rehearsal on any machine (CI runs it)
set -euo pipefail
cd "$(dirname "$0")/.."
[ -x .venv/bin/python ] || make setup
exec .venv/bin/python benchmarks/gpu_check.py "$@"
