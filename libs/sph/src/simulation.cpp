#include "rime/sph/simulation.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "rime/boundary/volumes.h"
#include "rime/core/error.h"
#include "rime/core/kernel.h"
#include "rime/core/log.h"
#include "rime/exec/memory.h"
#include "rime/exec/parallel.h"
#include "rime/sph/enclosure.h"
#include "rime/sph/kernels.h"
#include "state.h"

RIME_SPH_KERNELS(RIME_INSTANTIATE_CPU_KERNEL)

namespace rime::sph {

namespace {

// The largest step the explicit non-pressure forces allow, and the scene parameter that sets it
// (empty when nothing limits). The pressure solve is implicit and the wall viscosity is solved
// per particle, so only these bind:
//   Monaghan viscosity Δt ν/h² ≤ 0.1 with ν = β0 β1 h/10 (spec §5.2); Morris Δt μ/(ρ0 h²) ≤ 0.1;
//   surface tension Δt ≤ 0.25 √(h/a) with a ≈ κ/(ρ0 h³) (He 2014) or a ≈ γ ρ0 (Akinci 2013);
//   air pressure the same with a ≈ p_atm/(ρ0 h), its push on a free-surface particle.
std::pair<double, std::string> ExplicitStepLimit(const io::Scene& scene, const ModuleRegistry& modules) {
  double limit = 1e30;
  std::string parameter;
  auto bound = [&](double dt, const char* name) {
    if (dt < limit) limit = dt, parameter = name;
  };
  const double h = scene.fluid.smoothing_length(), rho0 = scene.fluid.rest_density;
  if (modules.Enabled("viscosity")) {
    const double nu = scene.viscosity.beta0 * scene.viscosity.beta1 * h / 10;
    if (nu > 0) bound(0.1 * h * h / nu, "viscosity.beta0");
    if (scene.viscosity.mu > 0) bound(0.1 * h * h * rho0 / scene.viscosity.mu, "viscosity.mu");
  }
  if (modules.Enabled("surface_tension")) {
    const io::SurfaceTensionSettings& st = scene.surface_tension;
    if (st.model == io::SurfaceTensionModel::kAkinci2013) {
      const double g = std::max(st.gamma, st.beta);
      if (g > 0) bound(0.25 * std::sqrt(h / (g * rho0)), st.gamma >= st.beta ? "surface_tension.gamma" : "surface_tension.beta");
    } else {
      const double kappa = std::max(st.kappa, st.kappa_boundary);
      if (kappa > 0)
        bound(0.25 * std::sqrt(rho0 * h * h * h * h / kappa),
              st.kappa >= st.kappa_boundary ? "surface_tension.kappa" : "surface_tension.kappa_boundary");
    }
  }
  if (modules.Enabled("air_pressure") && scene.air_pressure.p_atm > 0)
    bound(0.25 * h * std::sqrt(rho0 / scene.air_pressure.p_atm), "air_pressure.p_atm");
  return {limit, parameter};
}

}  // namespace

template <class T>
Simulation<T>::Simulation(const io::Scene& scene, const exec::Device& device) : scene_(scene), device_(device) {
  for (const std::string& m : scene.modules) modules_.Enable(m);
  state_ = std::make_unique<State>(device, scene, modules_);
  emitter_travel_.assign(scene.emitters.size(), 0.0);
}

template <class T>
Simulation<T>::~Simulation() = default;

template <class T>
std::int64_t Simulation<T>::fluid_count() const {
  return state_->n();
}
template <class T>
std::int64_t Simulation<T>::ice_count() const {
  return state_->ice_count;
}
template <class T>
std::int64_t Simulation<T>::boundary_count() const {
  return state_->nb();
}

template <class T>
void Simulation<T>::AddBoundaryObject(const io::ParticleFrame& boundary, const std::string& object_name) {
  if (initialized_) throw Error(ExitCode::kFailure, "AddBoundaryObject after Initialize");
  State& s = *state_;
  const auto positions = boundary.GetPositions<T>();
  const std::uint32_t object = static_cast<std::uint32_t>(object_names_.size());
  object_names_.push_back(object_name);
  // The object's motion comes from the scene solid of the same name (static when none).
  ObjectMotion motion;
  for (const io::SolidObject& solid : scene_.solids)
    if (solid.name == object_name) motion = ObjectMotion(solid);
  s.any_animated = s.any_animated || motion.animated();
  s.object_motions.push_back(motion);

  // Normals tell sealed tanks (inward-facing) from solids when water is placed (Initialize).
  std::vector<Vec3d> normals(positions.size());
  if (boundary.HasVec3("normal")) {
    const bool single = std::holds_alternative<std::vector<float>>(boundary.attributes.at("normal_0"));
    if (single) {
      const auto n = boundary.GetVec3<float>("normal");
      for (std::size_t i = 0; i < n.size(); ++i) normals[i] = {n[i].x, n[i].y, n[i].z};
    } else {
      normals = boundary.GetVec3<double>("normal");
    }
  }
  s.initial_normals.insert(s.initial_normals.end(), normals.begin(), normals.end());
  for (const Vec3<T>& p : positions)
    if (!IsFinite(p)) throw InputError("boundary particle position is NaN or infinite", boundary.source);
  const std::size_t first = s.boundary.x.size(), m = positions.size();
  std::vector<std::int64_t> ids(m);
  for (std::size_t i = 0; i < m; ++i) ids[i] = -static_cast<std::int64_t>(first + i) - 1;
  s.ForEachBoundaryGroup([&](auto& group) { exec::GrowGroup(device_, group, m, scene_.fluid.rest_density); });
  exec::CopyTail(device_, s.boundary.x, first, positions);
  exec::CopyTail(device_, s.boundary.local, first, positions);
  exec::CopyTail(device_, s.boundary.object, first, std::vector<std::uint32_t>(m, object));
  exec::CopyTail(device_, s.boundary.phase, first, std::vector<std::uint8_t>(m, static_cast<std::uint8_t>(io::Phase::kBoundary)));
  exec::CopyTail(device_, s.boundary.id, first, ids);
}

template <class T>
void Simulation<T>::RecomputeBoundaryVolumes() {
  State& s = *state_;
  s.boundary.volume.resize(s.nb());
  s.boundary.psi.resize(s.nb());
  boundary::ComputeBoundaryVolumes<T>(device_, s.boundary.x.data(), s.nb(), T(scene_.fluid.smoothing_length()), s.boundary.volume.data());
  FinishBoundaryVolumes();
}

template <class T>
void Simulation<T>::FinishBoundaryVolumes() {
  State& s = *state_;
  const double dp = scene_.fluid.spacing;
  if (s.ice_count > 0)
    exec::ParallelFor(
        device_, s.nb(),
        kernels::CapIceVolume<T>{.phase = s.boundary.phase.data(), .cap = T(dp * dp * dp), .volume = s.boundary.volume.data()});
  exec::ParallelFor(
      device_, s.nb(),
      kernels::Scale<T>{.in = s.boundary.volume.data(), .factor = T(scene_.fluid.rest_density), .out = s.boundary.psi.data()});
}

template <class T>
void Simulation<T>::UpdateBoundaryMotion(double t) {
  State& s = *state_;
  if (!s.any_animated || s.nb() == 0) return;
  std::vector<RigidMotion<T>> motions;
  for (const ObjectMotion& m : s.object_motions) motions.push_back(m.At<T>(t));
  s.motions.assign(motions);
  exec::ParallelFor(device_, s.nb(),
                    kernels::MoveBoundary<T>{.local = s.boundary.local.data(),
                                             .object = s.boundary.object.data(),
                                             .motions = s.motions.data(),
                                             .x = s.boundary.x.data(),
                                             .v = s.boundary.v.data()});
  s.boundary_grid.Build(s.boundary.x.data(), s.nb(), T(2 * scene_.fluid.smoothing_length()), lattice_origin_);
}

template <class T>
void Simulation<T>::Initialize() {
  State& s = *state_;
  const double dp = scene_.fluid.spacing;
  const T support = T(2 * scene_.fluid.smoothing_length());
  {
    const auto [limit, parameter] = ExplicitStepLimit(scene_, modules_);
    if (scene_.solver.time_step == io::TimeStep::kCfl && limit < scene_.solver.dt_min)
      throw InputError(fmt::format("{} needs time steps below {:.3g} s for stability, but sim.dt_min is {:.3g} s: lower {} or dt_min",
                                   parameter, limit, scene_.solver.dt_min, parameter),
                       SceneField(scene_, parameter));
    if (scene_.solver.time_step == io::TimeStep::kFixed && scene_.solver.dt > limit)
      log::Warn("sim.dt = {:.3g} s exceeds the stability limit {:.3g} s set by {}: expect the run to diverge", scene_.solver.dt, limit,
                parameter);
  }
  UpdateBoundaryMotion(0.0);
  // Cells enclosed by closed solids, from the boundary particles at t = 0 (before they are reordered).
  std::vector<Vec3d> boundary_at_start;
  for (const Vec3<T>& p : s.boundary.x.ToHost()) boundary_at_start.push_back({double(p.x), double(p.y), double(p.z)});
  const Enclosure enclosure(boundary_at_start, s.initial_normals, dp);
  boundary_at_start = {};
  s.initial_normals = {};
  for (std::size_t e = 0; e < scene_.emitters.size(); ++e)
    if (enclosure.Inside(scene_.emitters[e].center))
      throw InputError(
          fmt::format("emitter {}'s nozzle centre ({}, {}, {}) lies inside a closed solid: its water would be simulated inside the object",
                      e + 1, scene_.emitters[e].center.x, scene_.emitters[e].center.y, scene_.emitters[e].center.z),
          SceneField(scene_, "emitter.center"));
  if (s.nb() > 0) {
    // Order boundary particles along the Z curve once (cache locality), then compute Akinci volumes.
    s.boundary_grid.Build(s.boundary.x.data(), s.nb(), support);
    DeviceArray<std::uint32_t> d_order(device_);
    d_order.resize(s.nb());
    exec::CopyOnDevice(device_, d_order.data(), s.boundary_grid.order(), s.nb() * sizeof(std::uint32_t));
    exec::ScratchPool once(device_);  // freed here: the boundary is reordered only now
    s.ForEachBoundaryGroup([&](auto& group) { exec::GatherGroup(device_, group, d_order.data(), s.nb(), once); });
    s.boundary_grid.AdoptOrder(s.boundary.x.data());
    RecomputeBoundaryVolumes();
  } else {
    s.boundary_grid.Build(s.boundary.x.data(), 0, support);
  }

  SeedWater(enclosure);
  ComputeDomain(Positions());
  // One cell lattice for the water and boundary grids, so that neighbor searches run cell by cell.
  {
    Vec3<T> lo = domain_min_;
    for (const Vec3<T>& p : BoundaryPositions()) lo = Min(lo, p);
    lattice_origin_ = {std::floor(lo.x / support) * support - support, std::floor(lo.y / support) * support - support,
                       std::floor(lo.z / support) * support - support};
    if (s.nb() > 0) s.boundary_grid.Build(s.boundary.x.data(), s.nb(), support, lattice_origin_);
  }
  initialized_ = true;
}

template <class T>
double Simulation<T>::NextTimeStep(double next_stop) const {
  const io::SolverSettings& solver = scene_.solver;
  double dt = solver.dt;
  if (solver.time_step == io::TimeStep::kCfl) {
    const State& s = *state_;
    double max_speed = 0;
    if (s.n() > 0) {
      DeviceArray<T> speed2(device_, s.n());
      exec::ParallelFor(device_, s.n(), kernels::SquaredSpeed<T>{.v = s.fluid.v.data(), .out = speed2.data()});
      max_speed = std::sqrt(double(exec::Max(device_, speed2.data(), s.n())));
    }
    // Head speed √(2 g H), H = the fluid's extent along gravity: the speed its own weight can give
    // it. Without it, deep water at rest steps at dt_max, and the pressure displacements Δt² p/(ρ d_p)
    // of the bottom layers reach a spacing (a 0.5 m column at d_p = 12.5 mm diverged at 6 ms).
    const double g = Norm(scene_.solver.gravity);
    if (s.n() > 0 && g > 0 && modules_.Enabled("gravity")) {
      DeviceArray<T> heights(device_, 2 * s.n());
      exec::ParallelFor(
          device_, s.n(),
          kernels::Heights<T>{.x = s.fluid.x.data(), .up = ToT<T>(scene_.solver.gravity / -g), .n = s.n(), .out = heights.data()});
      const double top = double(exec::Max(device_, heights.data(), s.n()));
      const double bottom = -double(exec::Max(device_, heights.data() + s.n(), s.n()));
      max_speed = std::max(max_speed, std::sqrt(2 * g * (top - bottom)));
    }
    for (const io::Emitter& e : scene_.emitters) max_speed = std::max(max_speed, e.speed);
    dt = max_speed > 0 ? solver.cfl * scene_.fluid.spacing / max_speed : solver.dt_max;
    // Initialize refused a scene whose explicit limit lies below dt_min, so clamping keeps it.
    dt = std::clamp(std::min(dt, ExplicitStepLimit(scene_, modules_).first), solver.dt_min, solver.dt_max);
  }
  // Equal steps up to the stop, none longer than dt: the step then stays the same from frame to
  // frame for water at rest. A shortened step at every stop (the remainder, or half of it) jolted
  // resting water at each output frame (Iisph.OutputFramesDoNotJoltWaterAtRest). Likely why: with
  // spec §6's default a_ii, water next to walls stays compressed, and the pressure the solve keeps
  // on it scales with 1/Δt², so a sudden change of Δt unbalances it.
  const double remaining = next_stop - time_;
  const double steps = std::ceil(remaining / dt * (1 - 1e-9));
  return steps > 1 ? remaining / steps : std::max(remaining, 1e-12);
}

// Largest displacement per step, in particle spacings, before a step is reported as diverged.
constexpr double kMaxSpacingsPerStep = 0.8;

template <class T>
void Simulation<T>::CheckDivergence(const StepStats& stats) const {
  const double limit = scene_.solver.divergence_density_error;
  const bool bad_error = !std::isfinite(stats.average_density_error) || stats.average_density_error > limit;
  const bool bad_speed = !std::isfinite(stats.max_speed);
  // A particle crossing more than 0.8 spacings in one step can tunnel through single-layer walls
  // (measured: 0.7 holds, 0.8 leaks); spec §7 steps at 0.4, and scene files allow cfl ≤ 0.7.
  const double courant = stats.max_speed * stats.dt / scene_.fluid.spacing;
  const bool bad_courant = courant > kMaxSpacingsPerStep;
  if (!bad_error && !bad_speed && !bad_courant) return;
  // Name the worst particle: a non-finite one, else the fastest.
  const auto x = Positions();
  const auto v = Velocities();
  const auto ids = Ids();
  std::size_t worst = 0;
  double worst_speed = -1;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double sp = double(Norm(v[i]));
    if (!IsFinite(x[i]) || !std::isfinite(sp)) {
      worst = i;
      break;
    }
    if (sp > worst_speed) worst_speed = sp, worst = i;
  }
  std::string particle = x.empty() ? "no particles"
                                   : fmt::format("worst particle id {} at ({:.4g}, {:.4g}, {:.4g}) m, speed {:.4g} m/s", ids[worst],
                                                 double(x[worst].x), double(x[worst].y), double(x[worst].z), double(Norm(v[worst])));
  const std::string reason =
      bad_speed ? "a particle velocity became NaN or infinite"
      : bad_courant
          ? fmt::format("particles move {:.3g} spacings per step (above {}, where they tunnel through walls): the time step is too large",
                        courant, kMaxSpacingsPerStep)
          : fmt::format("average density error {:.3g}% exceeds the limit {:.3g}% (sim.divergence_density_error)",
                        100 * stats.average_density_error, 100 * limit);
  const char* advice = scene_.solver.time_step == io::TimeStep::kFixed ? "Reduce sim.dt" : "Reduce sim.cfl or dt_max";
  throw Error(ExitCode::kDiverged,
              fmt::format("simulation diverged at step {} (t = {:.6g} s, dt = {:.3g} s): {}; {}. {}, or check the scene", step_count_,
                          time_, stats.dt, reason, particle, advice));
}

template <class T>
StepStats Simulation<T>::Step(double dt) {
  if (!initialized_) throw Error(ExitCode::kFailure, "Step before Initialize");
  State& s = *state_;
  StepStats stats;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.other);
    Emit(dt, stats);
    UpdateBoundaryMotion(time_);
  }
  if (s.n() == 0) {
    time_ += dt;
    ++step_count_;
    stats.dt = dt;
    return stats;
  }
  {
    PhaseTimer t(device_, timing_enabled_, timings_.neighbor_search);
    NeighborSearch();
  }
  double measured_error = 0;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.non_pressure);
    measured_error = ComputeDensity();
    NonPressureAccelerations(dt);
  }
  StepStats solve;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.pressure_solve);
    solve = SolvePressure(dt, scene_.solver.omega);
  }
  solve.emitted_particles = stats.emitted_particles;
  stats = solve;
  stats.measured_density_error = measured_error;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.integration);
    Integrate(dt);
    stats.max_density_error = s.n() ? exec::Max(device_, s.step.compression.data(), s.n()) / scene_.fluid.rest_density : 0;
    s.step.scratch.resize(s.n());
    exec::ParallelFor(device_, s.n(), kernels::SquaredSpeed<T>{.v = s.fluid.v.data(), .out = s.step.scratch.data()});
    stats.max_speed = std::sqrt(double(exec::Max(device_, s.step.scratch.data(), s.n())));
  }
  CheckDivergence(stats);
  if (modules_.Enabled("freezing")) {
    PhaseTimer t(device_, timing_enabled_, timings_.freezing);
    const std::int64_t before = state_->ice_count;
    Freeze(dt);
    stats.frozen_particles = state_->ice_count - before;
  }
  time_ += dt;
  ++step_count_;
  RemoveOutsideDomain(stats);
  stats.fluid_particles = s.n();
  return stats;
}

template <class T>
std::size_t Simulation<T>::MemoryBytes(const std::string& module) const {
  const State& s = *state_;
  std::size_t bytes = 0;
  s.ForEachGroup([&](const std::string& owner, const auto& group) {
    if (module.empty() || owner == module) bytes += exec::GroupBytes(group);
  });
  if (module.empty() || module == "core") bytes += s.pool.bytes() + s.keep.bytes() + s.slot.bytes() + s.order.bytes();
  return bytes;
}

template <class T>
std::vector<Vec3<T>> Simulation<T>::Positions() const {
  return state_->fluid.x.ToHost();
}
template <class T>
std::vector<Vec3<T>> Simulation<T>::Velocities() const {
  return state_->fluid.v.ToHost();
}
template <class T>
std::vector<T> Simulation<T>::Densities() const {
  return state_->fluid.density.ToHost();
}
template <class T>
std::vector<T> Simulation<T>::Pressures() const {
  return state_->fluid.pressure.ToHost();
}
template <class T>
std::vector<std::int64_t> Simulation<T>::Ids() const {
  return state_->fluid.id.ToHost();
}
template <class T>
std::vector<Vec3<T>> Simulation<T>::BoundaryPositions() const {
  return state_->boundary.x.ToHost();
}
template <class T>
std::vector<T> Simulation<T>::BoundaryVolumes() const {
  return state_->boundary.volume.ToHost();
}
template <class T>
std::vector<Vec3<T>> Simulation<T>::NonPressureAccelerations() const {
  return state_->step.accel.ToHost();
}

template <class T>
void Simulation<T>::SetFluidState(const std::vector<Vec3<T>>& x, const std::vector<Vec3<T>>& v) {
  State& s = *state_;
  if (x.size() != v.size()) throw Error(ExitCode::kFailure, "SetFluidState: size mismatch");
  if (Index(x.size()) != s.n()) {
    SetWater(x, v);
  } else {
    s.fluid.x.assign(x);
    s.fluid.v.assign(v);
  }
  initialized_ = true;
}

template class Simulation<float>;
template class Simulation<double>;

}  // namespace rime::sph
