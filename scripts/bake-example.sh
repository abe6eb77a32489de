#!/usr/bin/env bash
# The main job (README.md): installs what is missing, builds the bake's programs and bakes the
# built-in example scene end to end into out/default/ (rime-bake reruns only what is stale, so
# running it again is quick).
#   scripts/bake-example.sh [SCENE.toml [rime-bake flags...]]
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh tools
SCENE="${1:-examples/default.toml}"
shift || true
BIN=build/rime/bin
if [ ! -x "$BIN/rime-bake" ]; then
  echo "bake-example: $BIN/rime-bake was not built" >&2
  exit 1
fi
# Output folder: out/<scene name> (examples/default.toml -> out/default).
# Per-frame stages (surfaces, cleanup, preview renders) run one frame per core unless -j is given.
JOBS=(-j "$(nproc)")
for a in "$@"; do case "$a" in -j|-j*|--jobs|--jobs=*) JOBS=() ;; esac; done
exec "$BIN/rime-bake" "$SCENE" "${JOBS[@]}" "$@"
