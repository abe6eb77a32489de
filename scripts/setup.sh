#!/usr/bin/env bash
# Installs the Debian 12 packages Rime builds against (idempotent: installs only what is missing),
# then configures and builds the given CMake build preset.
#   scripts/setup.sh [PRESET]      (default: tools)
# "tools" (the bake's programs) and "test" (everything) share one tree, build/rime, so the two
# README commands compile each file once between them.
set -euo pipefail
cd "$(dirname "$0")/.."

PACKAGES=(
  g++ cmake ninja-build pkg-config
  libeigen3-dev libtbb-dev libfmt-dev libxxhash-dev
  libhdf5-dev hdf5-tools libtomlplusplus-dev libcli11-dev libgtest-dev nlohmann-json3-dev
  libassimp-dev libopenvdb-dev libopenvdb-tools libboost-iostreams-dev libcgal-dev
  slurm-wlm  # the farm test starts a single-node Slurm cluster on localhost (tests/farm)
)

PRESET="${1:-tools}"
CONFIGURE_PRESET="$PRESET"
[ "$PRESET" = tools ] && CONFIGURE_PRESET=test
# The fuzz preset builds with clang and links libFuzzer and the sanitizer runtimes; clang-format (the
# style test, docs/design.md "Tests") shares clang's LLVM libraries, so it costs little there.
[ "$PRESET" = fuzz ] && PACKAGES+=(clang libclang-rt-14-dev clang-format)

missing=()
for p in "${PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  echo "setup: installing ${#missing[@]} Debian packages: ${missing[*]}"
  SUDO=""
  [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
fi

cmake --preset "$CONFIGURE_PRESET" >/dev/null
cmake --build --preset "$PRESET"
