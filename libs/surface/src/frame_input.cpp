// Selecting one phase of a particle frame (see rime/surface/frame_input.h).
#include "rime/surface/frame_input.h"

#include <fmt/format.h>

#include <cmath>

#include "rime/core/error.h"

namespace rime::surface {
namespace {

std::string Where(const io::ParticleFrame& frame, const std::string& field) {
  return frame.source.empty() ? field : frame.source + ":" + field;
}

// A float32 or float64 dataset as doubles (rime-sim may write either precision).
std::vector<double> ReadReal(const io::ParticleFrame& frame, const std::string& name) {
  const auto it = frame.attributes.find(name);
  if (it == frame.attributes.end()) throw InputError("missing dataset", Where(frame, name));
  if (const auto* f = std::get_if<std::vector<float>>(&it->second)) return {f->begin(), f->end()};
  if (const auto* d = std::get_if<std::vector<double>>(&it->second)) return *d;
  throw InputError("dataset must be float32 or float64", Where(frame, name));
}

}  // namespace

ParticleSet SelectPhase(const io::ParticleFrame& frame, io::Phase phase, const SelectOptions& options, std::vector<std::string>& warnings) {
  frame.Validate();
  if (!(frame.spacing > 0) || !std::isfinite(frame.spacing))
    throw InputError(fmt::format("root attribute 'spacing' must be a positive length in m (found {})", frame.spacing),
                     Where(frame, "spacing"));
  ParticleSet set;
  set.spacing = frame.spacing;
  set.smoothing_length = frame.spacing;
  if (auto it = frame.numbers.find("smoothing_length"); it != frame.numbers.end()) {
    if (!(it->second > 0) || !std::isfinite(it->second))
      throw InputError(fmt::format("root attribute 'smoothing_length' must be positive (found {})", it->second),
                       Where(frame, "smoothing_length"));
    set.smoothing_length = it->second;
  }
  const std::size_t n = frame.size();
  if (n == 0) return set;
  if (!frame.Has("phase")) throw InputError("missing dataset 'phase' (uint8: 0 water, 1 boundary, 2 ice)", Where(frame, "phase"));
  const auto& phases = frame.Get<std::uint8_t>("phase");
  const auto positions = frame.GetPositions<double>();

  std::vector<std::size_t> chosen;
  for (std::size_t i = 0; i < n; ++i)
    if (phases[i] == static_cast<std::uint8_t>(phase)) chosen.push_back(i);
  set.positions.reserve(chosen.size());
  for (std::size_t i : chosen) {
    if (!IsFinite(positions[i])) throw InputError(fmt::format("particle {} has a non-finite position", i), Where(frame, "x/y/z"));
    set.positions.push_back(positions[i]);
  }
  if (frame.Has("vx") && frame.Has("vy") && frame.Has("vz")) {
    const auto vx = ReadReal(frame, "vx"), vy = ReadReal(frame, "vy"), vz = ReadReal(frame, "vz");
    set.velocities.reserve(chosen.size());
    for (std::size_t i : chosen) set.velocities.push_back(Vec3f(float(vx[i]), float(vy[i]), float(vz[i])));
  }
  if (phase == io::Phase::kIce && !chosen.empty()) {
    bool complete = true;
    for (int c = 0; c < 6; ++c) complete = complete && frame.Has(fmt::format("anisotropy_{}", c));
    if (complete) {
      std::vector<double> comp[6];
      for (int c = 0; c < 6; ++c) comp[c] = ReadReal(frame, fmt::format("anisotropy_{}", c));
      set.stored_anisotropy.resize(chosen.size());
      for (std::size_t k = 0; k < chosen.size(); ++k) {
        for (int c = 0; c < 6; ++c) {
          const double v = comp[c][chosen[k]];
          if (!std::isfinite(v))
            throw InputError(fmt::format("ice particle {} has a non-finite anisotropy", chosen[k]),
                             Where(frame, fmt::format("anisotropy_{}", c)));
          set.stored_anisotropy[k][c] = float(v);
        }
      }
    } else if (options.strict) {
      throw InputError("ice particles carry no anisotropy (datasets anisotropy_0..5); refusing under --strict",
                       Where(frame, "anisotropy_0"));
    } else {
      warnings.push_back(fmt::format("{}: ice particles carry no anisotropy_0..5; using isotropic ellipsoids",
                                     frame.source.empty() ? "frame" : frame.source));
    }
  }
  return set;
}

}  // namespace rime::surface
