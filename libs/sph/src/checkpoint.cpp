/// @file checkpoint.cpp
/// @brief A frame is the solver's complete state: water rows first, then (with freezing on) every
/// boundary particle, solids in the boundary files' order and ice in the order it froze. Every
/// checkpointed attribute of every existing group is a dataset; rows of a group without it carry
/// the attribute's fill value. Restore reads the same declarations back, so a resumed run continues
/// bit-identically.

#include <fmt/format.h>

#include <cmath>

#include "rime/core/error.h"
#include "state.h"

namespace rime::sph {

template <class T>
io::ParticleFrame Simulation<T>::Snapshot(std::int64_t frame_number) const {
  const State& s = *state_;
  io::ParticleFrame f;
  f.kind = "particles";
  f.time = time_;
  f.frame = frame_number;
  f.spacing = scene_.fluid.spacing;
  f.particle_radius = scene_.fluid.spacing / 2;
  f.rest_density = scene_.fluid.rest_density;
  f.scene_hash = scene_.hash;
  f.numbers["smoothing_length"] = scene_.fluid.smoothing_length();
  f.numbers["step_count"] = double(step_count_);
  f.numbers["next_id"] = double(next_id_);
  f.numbers["removed_total"] = double(removed_total_);
  f.numbers["precision_bits"] = double(sizeof(T) * 8);
  f.numbers["water_particles"] = double(s.n());
  f.numbers["film_diffusion_pending"] = diffusion_pending_;
  for (std::size_t e = 0; e < emitter_travel_.size(); ++e) f.numbers[fmt::format("emitter_travel_{}", e)] = emitter_travel_[e];
  f.texts["modules"] = fmt::format("{}", fmt::join(modules_.enabled(), ","));
  if (s.freezing) {
    f.numbers["ice_particles"] = double(s.ice_count);
    f.numbers["film_max"] = scene_.freezing.film_max_ratio * scene_.fluid.particle_mass();
  }

  // With freezing on the boundary follows the water (solids carry the film state, ice its
  // anisotropy), so that the surface stage finds the ice and a frame resumes the film.
  const std::size_t nf = std::size_t(s.n()), rows = nf + (s.freezing ? std::size_t(s.nb()) : 0);
  const double rho0 = scene_.fluid.rest_density;
  // The phase tells readers which rows are water; boundary rows overwrite it with their own.
  f.Set("phase", std::vector<std::uint8_t>(rows, static_cast<std::uint8_t>(io::Phase::kFluid)));
  s.ForEachFluidGroup([&](const auto& group) { WriteRows(group, f, 0, rows, rho0); });
  if (s.freezing) s.ForEachBoundaryGroup([&](const auto& group) { WriteRows(group, f, nf, rows, rho0); });
  return f;
}

template <class T>
void Simulation<T>::Restore(const io::ParticleFrame& f) {
  if (!initialized_) Initialize();
  State& s = *state_;
  const auto bits = f.numbers.find("precision_bits");
  if (bits == f.numbers.end() || bits->second != double(sizeof(T) * 8))
    throw InputError(
        fmt::format("checkpoint precision does not match the scene's water.precision = \"{}\"", io::EnumName(scene_.fluid.precision)),
        f.source);
  if (std::fabs(f.spacing - scene_.fluid.spacing) > 1e-12 * scene_.fluid.spacing)
    throw InputError("checkpoint was written with a different water.spacing", f.source);
  auto number = [&](const std::string& key) {
    const auto it = f.numbers.find(key);
    if (it == f.numbers.end()) throw InputError("checkpoint lacks the attribute '" + key + "'", f.source);
    return it->second;
  };
  time_ = f.time;
  step_count_ = std::int64_t(number("step_count"));
  next_id_ = std::int64_t(number("next_id"));
  removed_total_ = std::int64_t(number("removed_total"));
  diffusion_pending_ = number("film_diffusion_pending");
  for (std::size_t e = 0; e < emitter_travel_.size(); ++e) emitter_travel_[e] = number(fmt::format("emitter_travel_{}", e));

  // Rows by group: water; solids, then ice (the order the run appended them in).
  const auto& phase = f.Get<std::uint8_t>("phase");
  std::vector<std::size_t> water, solids, ice;
  for (std::size_t i = 0; i < phase.size(); ++i) {
    if (phase[i] == static_cast<std::uint8_t>(io::Phase::kFluid)) water.push_back(i);
    if (phase[i] == static_cast<std::uint8_t>(io::Phase::kBoundary)) solids.push_back(i);
    if (phase[i] == static_cast<std::uint8_t>(io::Phase::kIce)) ice.push_back(i);
  }
  s.ForEachFluidGroup([&](auto& group) { ReadRows(group, f, water); });
  if (s.freezing) {
    if (solids.size() != std::size_t(s.nb()))
      throw InputError(fmt::format("checkpoint holds {} solid particles, the boundary files {}", solids.size(), s.nb()), f.source);
    std::vector<std::size_t> boundary = solids;
    boundary.insert(boundary.end(), ice.begin(), ice.end());
    s.ForEachBoundaryGroup([&](auto& group) { ReadRows(group, f, boundary); });
    // Ψ is not stored: it follows from the volumes as the run had them (updated only near new ice,
    // so recomputing them all would not resume bit-identically).
    s.boundary.psi.resize(s.nb());
    s.ice_count = Index(ice.size());
    // Binned anew from the rows as read, so the grid cannot point at other particles than the
    // start-up one did (the same grid when the rows come in start-up order and hold no ice).
    s.boundary_grid.Build(s.boundary.x.data(), s.nb(), T(2 * scene_.fluid.smoothing_length()), lattice_origin_);
    FinishBoundaryVolumes();
    s.freezing_work->diffusion_cache_valid = false;
  }
  UpdateBoundaryMotion(time_);
}

template io::ParticleFrame Simulation<float>::Snapshot(std::int64_t) const;
template io::ParticleFrame Simulation<double>::Snapshot(std::int64_t) const;
template void Simulation<float>::Restore(const io::ParticleFrame&);
template void Simulation<double>::Restore(const io::ParticleFrame&);

}  // namespace rime::sph
