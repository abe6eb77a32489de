#!/usr/bin/env bash
# The test command (README.md; .ci/run calls exactly this): installs what is missing, builds the
# "test" preset (CUDA backend compiled for one architecture when nvcc exists) and runs every test.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh test
ctest --preset test "$@"
