#!/usr/bin/env bash
# The main job (README.md): installs what is missing, builds the release preset and bakes the
# built-in example scene end to end into out/default/.
set -euo pipefail
cd "$(dirname "$0")/.."
scripts/setup.sh release
SCENE="${1:-examples/default.toml}"
BIN=build/release/bin
if [ -x "$BIN/rime-bake" ]; then
  exec "$BIN/rime-bake" "$SCENE" --output out/default
fi
echo "bake-example: rime-bake is not built yet; nothing to bake" >&2
exit 1
