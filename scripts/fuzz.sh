#!/usr/bin/env bash
# Fuzzes Rime's readers with libFuzzer (docs/reliability.md "Fuzzing and sanitizers"): builds the
# "fuzz" preset (clang, ASan + UBSan), then runs each target for SECONDS, one after the other.
#   scripts/fuzz.sh [SECONDS] [TARGET...]     (default 60 s each; targets: scene particle_frame
#                                              boundary_file mesh_import clean_mesh bake_state)
# Inputs found are kept in build/fuzz/corpus/<target>/ (the committed seeds in tests/fuzz/corpus/
# are only read); every failing input (crash, leak, UB report, hang, huge allocation) is written to
# build/fuzz/findings/<target>/ and replayed by scripts/fuzz-triage.py: the script exits 1 when one
# fails in Rime's code. Figures per target go to build/fuzz/summary.tsv.
set -euo pipefail
cd "$(dirname "$0")/.."

SECONDS_EACH="${1:-60}"
shift || true
TARGETS=("$@")
((${#TARGETS[@]})) || TARGETS=(scene particle_frame boundary_file mesh_import clean_mesh bake_state)

nice -n 10 scripts/setup.sh fuzz

summary=build/fuzz/summary.tsv
printf 'target\tseconds\texecutions\tresult\n' > "$summary"
failed=0
for t in "${TARGETS[@]}"; do
  work=build/fuzz/corpus/$t findings=build/fuzz/findings/$t
  mkdir -p "$work" "$findings"
  dict=()
  [ -f "tests/fuzz/$t.dict" ] && dict=(-dict="tests/fuzz/$t.dict")
  inputs=("$work" "tests/fuzz/corpus/$t")
  [ -d "tests/fuzz/regressions/$t" ] && inputs+=("tests/fuzz/regressions/$t")
  log=build/fuzz/$t.log
  before=$(ls "$findings" | wc -l)
  start=$(date +%s)
  # Fork mode with -ignore_*: a crash inside a library (HDF5, assimp) does not end the run; every
  # failing input is kept and replayed by scripts/fuzz-triage.py, which fails only on Rime's code.
  # -timeout: one input taking 10 s is a hang; -malloc_limit_mb: one asking for a gigabyte is a
  # finding too (a reader must check sizes against the file before allocating).
  set +e
  ASAN_OPTIONS=detect_leaks=1 UBSAN_OPTIONS=print_stacktrace=1 \
    nice -n 10 "build/fuzz/bin/fuzz_$t" -fork=1 -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 \
      -max_total_time="$SECONDS_EACH" -timeout=10 -rss_limit_mb=2048 -malloc_limit_mb=1024 \
      -artifact_prefix="$findings/" "${dict[@]}" "${inputs[@]}" > "$log" 2>&1
  set -e
  took=$(($(date +%s) - start))
  execs=$(sed -n 's/^#\([0-9]*\):.*/\1/p' "$log" | tail -1)
  mapfile -t new < <(ls -t "$findings" | head -n $(($(ls "$findings" | wc -l) - before)) | sed "s|^|$findings/|")
  result="no failing input"
  if ((${#new[@]})); then
    triage=build/fuzz/$t.triage.tsv
    if scripts/fuzz-triage.py "build/fuzz/bin/fuzz_$t" "${new[@]}" > "$triage"; then
      result="${#new[@]} failing inputs, none in Rime's code ($(cut -f1 "$triage" | sort | uniq -c | xargs); see $triage)"
    else
      result="FINDING in Rime's code: $(grep -c '^RIME' "$triage") of ${#new[@]} failing inputs (see $triage)"
      failed=1
    fi
  fi
  printf '%s\t%s\t%s\t%s\n' "$t" "$took" "${execs:-?}" "$result" | tee -a "$summary"
done
exit "$failed"
