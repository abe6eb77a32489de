#!/usr/bin/env bash
# GPU check for a machine with an NVIDIA GPU: builds the release preset (CUDA for sm_80/86/89/90),
# then runs CPU/GPU parity on the same scenes and the GPU benchmark (1M and 4M particle dam
# breaks, a freezing scene). Prints tables; writes gpu_check.json in the current folder.
#   tests/gpu/run_gpu_checks.sh [--quick]
set -euo pipefail
cd "$(dirname "$0")/../.."
command -v nvidia-smi >/dev/null && nvidia-smi -L || echo "run_gpu_checks: nvidia-smi not found; the check will say whether CUDA is usable"
scripts/setup.sh release
cmake --build --preset release --target rime-gpu-check
exec build/release/bin/rime-gpu-check "$@"
