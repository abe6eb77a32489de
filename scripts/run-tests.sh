#!/usr/bin/env bash
# The test command (README.md; .ci/run calls exactly this): installs what is missing, builds the
# "test" preset (CUDA backend compiled for one architecture when nvcc exists) and runs every test.
# Then, where clang with libFuzzer is installed, fuzzes each reader for RIME_FUZZ_SECONDS (default
# 15 s each, 0 skips; docs/reliability.md "Fuzzing and sanitizers"); scripts/fuzz.sh runs longer.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh test
ctest --preset test "$@"

fuzz_seconds="${RIME_FUZZ_SECONDS:-15}"
probe="$(mktemp -d)"
trap 'rm -rf "$probe"' EXIT
echo 'extern "C" int LLVMFuzzerTestOneInput(const char*, unsigned long) { return 0; }' > "$probe/probe.cpp"
if [ "$fuzz_seconds" -gt 0 ] && clang++ -fsanitize=fuzzer,address,undefined "$probe/probe.cpp" -o "$probe/probe" 2>/dev/null; then
  scripts/fuzz.sh "$fuzz_seconds"
else
  echo "run-tests: fuzzing skipped (RIME_FUZZ_SECONDS=0, or no clang++ with libFuzzer; scripts/setup.sh fuzz installs it)"
fi
