// Shared by the GPU check program and its GTest twin: scenes and CPU/GPU comparisons.
#pragma once

#include <cmath>
#include <memory>
#include <unordered_map>
#include <string>
#include <vector>

#include "rime/exec/device.h"
#include "rime/sph/simulation.h"
#include "rime/test/dam_break.h"

namespace rime::gpu_check {

/// Dam break with `n` particles per block edge (the benchmark's scene).
inline io::Scene DamBreak(int n, bool freezing) {
  return test::DamBreakScene(
      n, freezing ? std::set<std::string>{"gravity", "viscosity", "surface_tension", "freezing"} : std::set<std::string>{"gravity"});
}

inline std::unique_ptr<sph::Simulation<float>> Make(const io::Scene& scene, const exec::Device& device, double box_scale) {
  return test::MakeDamBreak(scene, device, box_scale);
}

struct Difference {
  double rms_position = 0, max_position = 0;  // in spacings, matched by particle id
  double max_density = 0;                     // relative
  std::int64_t ice_cpu = 0, ice_gpu = 0, unmatched = 0;
};

inline Difference Compare(const sph::Simulation<float>& cpu, const sph::Simulation<float>& gpu, double spacing) {
  Difference d;
  const auto xa = cpu.Positions(), xb = gpu.Positions();
  const auto ia = cpu.Ids(), ib = gpu.Ids();
  const auto ra = cpu.Densities(), rb = gpu.Densities();
  std::unordered_map<std::int64_t, std::size_t> where;
  for (std::size_t k = 0; k < ib.size(); ++k) where[ib[k]] = k;
  double sum = 0;
  std::size_t matched = 0;
  for (std::size_t k = 0; k < ia.size(); ++k) {
    const auto it = where.find(ia[k]);
    if (it == where.end()) {
      ++d.unmatched;
      continue;
    }
    const double e = Norm(Vec3d(xa[k]) - Vec3d(xb[it->second])) / spacing;
    sum += e * e;
    d.max_position = std::max(d.max_position, e);
    if (k < ra.size() && it->second < rb.size())
      d.max_density = std::max(d.max_density, std::fabs(double(ra[k]) - rb[it->second]) / 1000.0);
    ++matched;
  }
  d.rms_position = matched ? std::sqrt(sum / matched) : 0;
  d.ice_cpu = cpu.ice_count();
  d.ice_gpu = gpu.ice_count();
  d.unmatched += std::int64_t(ib.size()) - std::int64_t(matched);
  return d;
}

}  // namespace rime::gpu_check
