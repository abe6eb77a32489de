/// @file fake_tools.h
/// @brief Tiny shell-script stand-ins for the stage tools, following their command-line contracts
/// (README.md), so rime-bake's decisions can be tested without the real stages. Each appends its
/// command line to $FAKE_LOG; outputs are copies of the inputs plus the scene section the real tool
/// would read, written atomically (temporary name + mv).
#pragma once

#include <sys/stat.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace rime::test {

/// A scene for the fake tools: frames 0..kFakeLastFrame (fps 2 x end_time 1.5 s). The fake
/// simulation ignores omega, which tests edit to change the [sim] section.
constexpr int kFakeLastFrame = 3;
constexpr const char* kFakeScene = R"([scene]
fps = 2
end_time = 1.5

[water]
spacing = 0.05

[sim]
modules = ["gravity"]
omega = 0.5

[[solid]]
name = "ground"
shape = "plane"
size = [1.0, 1.0, 1.0]

[[water_block]]
min = [0.0, 0.0, 0.1]
max = [0.2, 0.2, 0.3]
)";

// FAKE_FAIL=<stage>:<frame> makes that stage fail on that frame (FAKE_FAIL_CODE: the surface's exit
// code, default 3; 5 says it could not write, 10 that it is over its memory budget); FAKE_SIM_SLEEP slows each frame.
constexpr const char* kPreamble = R"SH(#!/bin/bash
set -e
echo "$(basename "$0") $*" >> "$FAKE_LOG"
section() { sed -n "/^\[$1\]/,/^\[/p" "$2" | grep -v '^\[' || true; }
fail_here() { [ "${FAKE_FAIL:-}" = "$1:$2" ]; }
)SH";

constexpr const char* kBoundary = R"SH(
scene=$1; out=$3
mkdir -p "$out"
for name in $(grep -E '^name *= *"' "$scene" | sed -E 's/.*"(.*)"/\1/'); do
  { echo "boundary $name"; section water "$scene"; } > "$out/$name.h5part.tmp"; mv "$out/$name.h5part.tmp" "$out/$name.h5part"
done
)SH";

constexpr const char* kSim = R"SH(
scene=$1; boundary=$3; out=$5; first=0
mkdir -p "$out"
if [[ " $* " == *" --resume "* ]]; then
  while [ -f "$out/particles.$(printf %04d $first).h5part" ]; do first=$((first + 1)); done
fi
for f in $(seq $first "$FAKE_FRAMES"); do
  if fail_here sim $f; then echo "rime-sim: error: simulation diverged at frame $f (fake)" >&2; exit 4; fi
  sleep "${FAKE_SIM_SLEEP:-0}"
  name="$out/particles.$(printf %04d $f).h5part"
  { echo "frame $f"; cat "$boundary"/*.h5part; } > "$name.tmp"; mv "$name.tmp" "$name"
done
echo index > "$out/particles.h5part.tmp"; mv "$out/particles.h5part.tmp" "$out/particles.h5part"
echo '{}' > "$out/stats.jsonl.tmp"; mv "$out/stats.jsonl.tmp" "$out/stats.jsonl"
)SH";

constexpr const char* kSurface = R"SH(
input=$1; out=$3; scene=$5
frame=$(basename "$input" | sed -E 's/particles\.([0-9]+)\.h5part/\1/')
if fail_here surface $((10#$frame)); then
  if [ "${FAKE_FAIL_CODE:-3}" = 5 ]; then echo "rime-surface: error: cannot write VDB file: No space left on device ($out/ice.$frame.vdb)" >&2; exit 5; fi
  if [ "${FAKE_FAIL_CODE:-3}" = 10 ]; then echo "rime-surface: error: needs about 2 GiB for 100 M voxels (frame $input, voxel 1 mm), budget 1 GiB (--memory-budget)" >&2; exit 10; fi
  echo "rime-surface: error: no particles in frame (fake) ($input)" >&2; exit 3
fi
mkdir -p "$out"
phases="ice water"  # [surface] phase defaults to "both"
if section surface "$scene" | grep -q 'phase *= *"ice"'; then phases=ice; fi
if section surface "$scene" | grep -q 'phase *= *"water"'; then phases=water; fi
for phase in $phases; do
  for ext in vdb obj ply; do
    if [ "${FAKE_EMPTY_FRAME:-}" = "$((10#$frame))" ]; then echo "# no triangles" > "$out/$phase.$frame.$ext.tmp"; else
    { echo "$phase"; cat "$input"; section surface "$scene"; echo "$ext"; echo "f 1 2 3"; } > "$out/$phase.$frame.$ext.tmp"; fi
    mv "$out/$phase.$frame.$ext.tmp" "$out/$phase.$frame.$ext"
  done
done
)SH";

constexpr const char* kClean = R"SH(
input=$1; out=$3; scene=$5
frame=$(basename "$input" | sed -E 's/ice\.([0-9]+)\.obj/\1/')
if fail_here cleanup $((10#$frame)); then echo "rime-clean: error: mesh has no faces (fake) ($input)" >&2; exit 3; fi
mkdir -p "$out"
for ext in obj ply json; do
  { cat "$input"; section cleanup "$scene"; echo "$ext"; } > "$out/ice_clean.$frame.$ext.tmp"; mv "$out/ice_clean.$frame.$ext.tmp" "$out/ice_clean.$frame.$ext"
done
)SH";

// Preview tools: `blender ... -- --setup J --ice OBJ --water OBJ --output PNG` and `ffmpeg ... OUT`.
constexpr const char* kBlender = R"SH(
while [ $# -gt 0 ]; do case "$1" in --ice) ice=$2; shift ;; --output) png=$2; shift ;; esac; shift; done
mkdir -p "$(dirname "$png")"
{ echo png; cat "$ice"; } > "$png.tmp"; mv "$png.tmp" "$png"
)SH";

constexpr const char* kFfmpeg = R"SH(
for last; do :; done
echo "assembled" > "${last#file:}"
)SH";

/// Writes fake `blender` and `ffmpeg` into `folder` (put it on PATH to enable the preview stage).
inline void WriteFakePreviewTools(const std::filesystem::path& folder) {
  std::filesystem::create_directories(folder);
  for (const auto& [name, body] : {std::pair{"blender", kBlender}, std::pair{"ffmpeg", kFfmpeg}}) {
    const auto path = folder / name;
    std::ofstream(path) << kPreamble << body;
    chmod(path.c_str(), 0755);
  }
}

inline void WriteFakeTools(const std::filesystem::path& folder) {
  std::filesystem::create_directories(folder);
  const std::pair<const char*, const char*> tools[] = {
      {"rime-boundary", kBoundary}, {"rime-sim", kSim}, {"rime-surface", kSurface}, {"rime-clean", kClean}};
  for (const auto& [name, body] : tools) {
    const auto path = folder / name;
    std::ofstream(path) << kPreamble << body;
    chmod(path.c_str(), 0755);
  }
}

}  // namespace rime::test
