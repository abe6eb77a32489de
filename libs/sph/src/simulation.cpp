#include "rime/sph/simulation.h"

#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <cmath>

#include "rime/core/error.h"
#include "rime/core/kernel.h"
#include "rime/core/log.h"
#include "rime/exec/memory.h"
#include "rime/exec/parallel.h"
#include "rime/neighbors/grid.h"
#include "rime/sph/kernels.h"
#include "rime/sph/motion.h"

RIME_SPH_KERNELS(RIME_INSTANTIATE_CPU_KERNEL)

namespace rime::sph {

using exec::DeviceArray;

template <class T>
struct Simulation<T>::State {
  explicit State(const exec::Device& d)
      : x(d), v(d), v_adv(d), accel(d), d_ii(d), s(d), density(d), density_error(d), pressure(d), pressure_next(d),
        pressure_previous(d), advected_error(d), a_ii(d), compression(d), scratch(d), id(d), color(d), energy(d),
        tmp_vec(d), tmp_scalar(d), tmp_id(d), bx(d), bv(d), blocal(d), bpsi(d), bvol(d), bobject(d), bphase(d), bid(d),
        fluid_grid(d), boundary_grid(d), ff(d), fb(d), ff_w(d), fb_w(d), ff_grad(d), fb_grad(d), motions(d), keep(d),
        slot(d), order(d) {}

  // Fluid state (persistent across steps, reordered with the particles).
  DeviceArray<Vec3<T>> x, v;
  // Per-step fluid quantities.
  DeviceArray<Vec3<T>> v_adv, accel, d_ii, s;
  DeviceArray<T> density, density_error, pressure, pressure_next, pressure_previous, advected_error, a_ii, compression, scratch;
  DeviceArray<std::int64_t> id;
  // Surface tension module.
  DeviceArray<T> color, energy;
  // Reordering buffers.
  DeviceArray<Vec3<T>> tmp_vec;
  DeviceArray<T> tmp_scalar;
  DeviceArray<std::int64_t> tmp_id;
  // Boundary particles (solids, later ice).
  DeviceArray<Vec3<T>> bx, bv, blocal;
  DeviceArray<T> bpsi, bvol;  // Ψ_b = ρ0 V_b and V_b
  DeviceArray<std::uint32_t> bobject;
  DeviceArray<std::uint8_t> bphase;
  DeviceArray<std::int64_t> bid;
  // Neighborhoods.
  neighbors::UniformGrid<T> fluid_grid, boundary_grid;
  neighbors::NeighborList ff, fb;
  DeviceArray<T> ff_w, fb_w;
  DeviceArray<Vec3<T>> ff_grad, fb_grad;
  // Objects.
  std::vector<ObjectMotion> object_motions;  // index = object id
  DeviceArray<RigidMotion<T>> motions;
  bool any_animated = false;
  // Compaction.
  DeviceArray<std::uint32_t> keep, slot, order;

  Index n() const { return static_cast<Index>(x.size()); }
  Index nb() const { return static_cast<Index>(bx.size()); }
  Pairs<T> FF() const { return {ff.offsets.data(), ff.indices.data(), ff_w.data(), ff_grad.data()}; }
  Pairs<T> FB() const { return {fb.offsets.data(), fb.indices.data(), fb_w.data(), fb_grad.data()}; }
};

namespace {

class PhaseTimer {
 public:
  PhaseTimer(const exec::Device& device, bool enabled, double& slot) : device_(device), enabled_(enabled), slot_(slot) {
    if (enabled_) start_ = std::chrono::steady_clock::now();
  }
  ~PhaseTimer() {
    if (!enabled_) return;
    exec::Synchronize(device_);
    slot_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }

 private:
  const exec::Device& device_;
  bool enabled_;
  double& slot_;
  std::chrono::steady_clock::time_point start_;
};

template <class V>
void Reorder(const exec::Device& device, DeviceArray<V>& array, DeviceArray<V>& scratch, const std::uint32_t* order, Index n) {
  scratch.resize(n);
  exec::ParallelFor(device, n, kernels::Gather<V>{array.data(), order, scratch.data()});
  array.swap(scratch);
}

template <class T>
Vec3<T> ToT(const Vec3d& v) {
  return {T(v.x), T(v.y), T(v.z)};
}

}  // namespace

template <class T>
Simulation<T>::Simulation(const io::Scene& scene, const exec::Device& device)
    : scene_(scene), device_(device), state_(std::make_unique<State>(device)) {
  for (const std::string& m : scene.modules) modules_.Enable(m);
  modules_.RecordAttribute("core", "position");
  modules_.RecordAttribute("core", "velocity");
  modules_.RecordAttribute("core", "density");
  modules_.RecordAttribute("core", "pressure");
  if (modules_.Enabled("surface_tension")) {
    modules_.RecordAttribute("surface_tension", "color");
    modules_.RecordAttribute("surface_tension", "color_energy");
  }
  emitter_travel_.assign(scene.emitters.size(), 0.0);
}

template <class T>
Simulation<T>::~Simulation() = default;

template <class T>
std::int64_t Simulation<T>::fluid_count() const {
  return state_->n();
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

  std::vector<Vec3<T>> bx = s.bx.ToHost();
  std::vector<std::uint32_t> bobject = s.bobject.ToHost();
  std::vector<std::uint8_t> bphase = s.bphase.ToHost();
  std::vector<std::int64_t> bid = s.bid.ToHost();
  for (const Vec3<T>& p : positions) {
    if (!IsFinite(p)) throw InputError("boundary particle position is NaN or infinite", boundary.source);
    bx.push_back(p);
    bobject.push_back(object);
    bphase.push_back(static_cast<std::uint8_t>(io::Phase::kBoundary));
    bid.push_back(-static_cast<std::int64_t>(bid.size()) - 1);
  }
  s.bx.assign(bx);
  s.blocal.assign(bx);
  s.bobject.assign(bobject);
  s.bphase.assign(bphase);
  s.bid.assign(bid);
  s.bv.resize(bx.size());
  s.bv.SetZero();
}

template <class T>
void Simulation<T>::RecomputeBoundaryVolumes() {
  State& s = *state_;
  const CubicSpline<T> kernel(T(scene_.fluid.smoothing_length()));
  s.bvol.resize(s.nb());
  s.bpsi.resize(s.nb());
  exec::ParallelFor(device_, s.nb(), kernels::BoundaryVolume<T>{s.boundary_grid.view(), kernel, T(scene_.fluid.rest_density),
                                                                s.bvol.data(), s.bpsi.data()});
}

template <class T>
void Simulation<T>::UpdateBoundaryMotion(double t) {
  State& s = *state_;
  if (!s.any_animated || s.nb() == 0) return;
  std::vector<RigidMotion<T>> motions;
  for (const ObjectMotion& m : s.object_motions) motions.push_back(m.At<T>(t));
  s.motions.assign(motions);
  exec::ParallelFor(device_, s.nb(), kernels::MoveBoundary<T>{s.blocal.data(), s.bobject.data(), s.motions.data(), s.bx.data(), s.bv.data()});
  s.boundary_grid.Build(s.bx.data(), s.nb(), T(2 * scene_.fluid.smoothing_length()));
}

template <class T>
void Simulation<T>::Initialize() {
  State& s = *state_;
  const double dp = scene_.fluid.spacing;
  const T support = T(2 * scene_.fluid.smoothing_length());
  UpdateBoundaryMotion(0.0);
  if (s.nb() > 0) {
    // Order boundary particles along the Z curve once (cache locality), then compute Akinci volumes.
    s.boundary_grid.Build(s.bx.data(), s.nb(), support);
    DeviceArray<std::uint32_t> d_order(device_);
    d_order.resize(s.nb());
    exec::CopyOnDevice(device_, d_order.data(), s.boundary_grid.order(), s.nb() * sizeof(std::uint32_t));
    DeviceArray<Vec3<T>> tv(device_);
    DeviceArray<std::uint32_t> tu(device_);
    DeviceArray<std::uint8_t> t8(device_);
    DeviceArray<std::int64_t> ti(device_);
    Reorder(device_, s.bx, tv, d_order.data(), s.nb());
    Reorder(device_, s.blocal, tv, d_order.data(), s.nb());
    Reorder(device_, s.bv, tv, d_order.data(), s.nb());
    Reorder(device_, s.bobject, tu, d_order.data(), s.nb());
    Reorder(device_, s.bphase, t8, d_order.data(), s.nb());
    Reorder(device_, s.bid, ti, d_order.data(), s.nb());
    s.boundary_grid.AdoptOrder(s.bx.data());
    RecomputeBoundaryVolumes();
  } else {
    s.boundary_grid.Build(s.bx.data(), 0, support);
  }

  // Fluid blocks on a lattice of spacing d_p, anchored at the block's min corner (box) or centre
  // (sphere). Particles closer than 1.05 d_p to a boundary particle are dropped: fluid must start
  // about 1.1 d_p from walls (spec §3), and nothing may start inside a solid.
  std::vector<Vec3<T>> x;
  std::vector<Vec3<T>> v;
  for (const io::FluidBlock& block : scene_.fluid_blocks) {
    if (block.shape == "box") {
      const Vec3d ext = block.max - block.min;
      const std::int64_t nx = std::int64_t(std::floor(ext.x / dp + 1e-6)) + 1, ny = std::int64_t(std::floor(ext.y / dp + 1e-6)) + 1,
                         nz = std::int64_t(std::floor(ext.z / dp + 1e-6)) + 1;
      if (nx * ny * nz > 200'000'000) throw InputError("water block would create more than 200 million particles", scene_.file.string() + ": water_block");
      for (std::int64_t k = 0; k < nz; ++k)
        for (std::int64_t j = 0; j < ny; ++j)
          for (std::int64_t i = 0; i < nx; ++i) {
            x.push_back(ToT<T>(block.min + Vec3d(i * dp, j * dp, k * dp)));
            v.push_back(ToT<T>(block.velocity));
          }
    } else {
      const std::int64_t r = std::int64_t(std::floor(block.radius / dp + 1e-6));
      for (std::int64_t k = -r; k <= r; ++k)
        for (std::int64_t j = -r; j <= r; ++j)
          for (std::int64_t i = -r; i <= r; ++i) {
            const Vec3d offset(i * dp, j * dp, k * dp);
            if (Norm(offset) > block.radius + 1e-9) continue;
            x.push_back(ToT<T>(block.center + offset));
            v.push_back(ToT<T>(block.velocity));
          }
    }
  }
  std::size_t dropped = 0;
  if (!x.empty() && s.nb() > 0) {
    DeviceArray<Vec3<T>> candidates(device_, x);
    neighbors::NeighborList near(device_);
    s.boundary_grid.Query(candidates.data(), Index(x.size()), T(1.05 * dp), false, near);
    const auto offsets = near.offsets.ToHost();
    std::vector<Vec3<T>> kept_x, kept_v;
    for (std::size_t i = 0; i < x.size(); ++i)
      if (offsets[i + 1] == offsets[i]) {
        kept_x.push_back(x[i]);
        kept_v.push_back(v[i]);
      }
    dropped = x.size() - kept_x.size();
    x.swap(kept_x);
    v.swap(kept_v);
  }
  if (dropped) log::Info("dropped {} water particles closer than 1.05 spacings to a solid", dropped);
  if (!scene_.fluid_blocks.empty() && x.empty() && scene_.emitters.empty())
    throw InputError("every water particle lies inside or against a solid: nothing to simulate", scene_.file.string() + ": water_block");
  std::vector<std::int64_t> ids(x.size());
  for (auto& id : ids) id = next_id_++;
  s.x.assign(x);
  s.v.assign(v);
  s.id.assign(ids);
  s.pressure_previous.resize(x.size());
  s.pressure_previous.SetZero();
  ComputeDomain(x);
  initialized_ = true;
}

template <class T>
void Simulation<T>::ComputeDomain(const std::vector<Vec3<T>>& fluid) {
  if (scene_.domain.set) {
    domain_min_ = ToT<T>(scene_.domain.min);
    domain_max_ = ToT<T>(scene_.domain.max);
    return;
  }
  // Default: the bounding box of solids, water and emitters, enlarged by max(1 m, half its size).
  Vec3d lo = Vec3d::Splat(1e300), hi = Vec3d::Splat(-1e300);
  auto grow = [&](const Vec3d& p) { lo = Min(lo, p), hi = Max(hi, p); };
  for (const Vec3<T>& p : BoundaryPositions()) grow(Vec3d(p));
  for (const Vec3<T>& p : fluid) grow(Vec3d(p));
  for (const io::Emitter& e : scene_.emitters) grow(e.center);
  if (lo.x > hi.x) lo = hi = Vec3d{};
  const Vec3d margin = Max(Vec3d::Splat(1.0), (hi - lo) * 0.5);
  domain_min_ = ToT<T>(lo - margin);
  domain_max_ = ToT<T>(hi + margin);
}

template <class T>
double Simulation<T>::NextTimeStep(double next_stop) const {
  const io::SolverSettings& solver = scene_.solver;
  double dt = solver.dt;
  if (solver.time_step == "cfl") {
    const State& s = *state_;
    double max_speed = 0;
    if (s.n() > 0) {
      DeviceArray<T> speed2(device_, s.n());
      exec::ParallelFor(device_, s.n(), kernels::SquaredSpeed<T>{s.v.data(), speed2.data()});
      max_speed = std::sqrt(double(exec::Max(device_, speed2.data(), s.n())));
    }
    for (const io::Emitter& e : scene_.emitters) max_speed = std::max(max_speed, e.speed);
    dt = max_speed > 0 ? solver.cfl * scene_.fluid.spacing / max_speed : solver.dt_max;
    // Explicit stability of the fluid–fluid sticky viscosity: Δt ν_eff / h² ≤ 0.1 (spec §5.2).
    if (modules_.Enabled("viscosity")) {
      const double h = scene_.fluid.smoothing_length();
      const double nu = scene_.viscosity.beta0 * scene_.viscosity.beta1 * h / 10;
      if (nu > 0) dt = std::min(dt, 0.1 * h * h / nu);
    }
    dt = std::clamp(dt, solver.dt_min, solver.dt_max);
  }
  const double remaining = next_stop - time_;
  if (remaining <= dt * (1 + 1e-9)) return std::max(remaining, 1e-12);
  // Avoid a tiny last step before the stop: split the remainder evenly.
  if (remaining < 2 * dt) return remaining / 2;
  return dt;
}

template <class T>
void Simulation<T>::NeighborSearch() {
  State& s = *state_;
  const Index n = s.n();
  const T support = T(2 * scene_.fluid.smoothing_length());
  s.fluid_grid.Build(s.x.data(), n, support);
  // Reorder the persistent fluid state along the grid's Z curve for cache locality.
  s.order.resize(n);
  exec::CopyOnDevice(device_, s.order.data(), s.fluid_grid.order(), n * sizeof(std::uint32_t));
  Reorder(device_, s.x, s.tmp_vec, s.order.data(), n);
  Reorder(device_, s.v, s.tmp_vec, s.order.data(), n);
  Reorder(device_, s.pressure_previous, s.tmp_scalar, s.order.data(), n);
  Reorder(device_, s.id, s.tmp_id, s.order.data(), n);
  s.fluid_grid.AdoptOrder(s.x.data());

  const CubicSpline<T> kernel(T(scene_.fluid.smoothing_length()));
  s.fluid_grid.Query(s.x.data(), n, support, true, s.ff);
  s.ff_w.resize(s.ff.pairs());
  s.ff_grad.resize(s.ff.pairs());
  exec::ParallelFor(device_, n, kernels::PairValues<T>{s.x.data(), s.x.data(), s.ff.offsets.data(), s.ff.indices.data(), kernel, s.ff_w.data(), s.ff_grad.data()});
  s.boundary_grid.Query(s.x.data(), n, support, false, s.fb);
  s.fb_w.resize(s.fb.pairs());
  s.fb_grad.resize(s.fb.pairs());
  exec::ParallelFor(device_, n, kernels::PairValues<T>{s.x.data(), s.bx.data(), s.fb.offsets.data(), s.fb.indices.data(), kernel, s.fb_w.data(), s.fb_grad.data()});
}

template <class T>
void Simulation<T>::ComputeDensity() {
  State& s = *state_;
  const Index n = s.n();
  s.density.resize(n);
  s.density_error.resize(n);
  const CubicSpline<T> kernel(T(scene_.fluid.smoothing_length()));
  exec::ParallelFor(device_, n, kernels::Density<T>{s.FF(), s.FB(), s.bpsi.data(), T(scene_.fluid.particle_mass()), kernel.W0(),
                                                     T(scene_.fluid.rest_density), s.density.data(), s.density_error.data()});
}

template <class T>
void Simulation<T>::NonPressureAccelerations(double dt) {
  State& s = *state_;
  const Index n = s.n();
  const T mass = T(scene_.fluid.particle_mass());
  const T h = T(scene_.fluid.smoothing_length());
  s.accel.resize(n);
  const Vec3<T> gravity = modules_.Enabled("gravity") ? ToT<T>(scene_.solver.gravity) : Vec3<T>{};
  exec::ParallelFor(device_, n, kernels::InitAcceleration<T>{gravity, s.accel.data()});
  if (modules_.Enabled("viscosity")) {
    const io::ViscositySettings& vs = scene_.viscosity;
    exec::ParallelFor(device_, n, kernels::ViscosityAcceleration<T>{s.FF(), s.x.data(), s.v.data(), s.density.data(), mass, T(vs.mu),
                                                                     T(vs.beta0 * vs.beta1), h, T(vs.epsilon), vs.limiter, s.accel.data()});
    modules_.CountLaunch("viscosity");
  }
  if (modules_.Enabled("surface_tension")) {
    const CubicSpline<T> kernel(h);
    s.color.resize(n);
    s.energy.resize(n);
    exec::ParallelFor(device_, n, kernels::SurfaceColor<T>{s.FF(), s.FB(), s.density.data(), s.bvol.data(), mass, kernel.W0(), s.color.data()});
    exec::ParallelFor(device_, n, kernels::SurfaceEnergy<T>{s.FF(), s.density.data(), s.color.data(), mass, s.energy.data()});
    exec::ParallelFor(device_, n,
                      kernels::SurfaceTensionAcceleration<T>{s.FF(), s.FB(), s.density.data(), s.energy.data(), s.bvol.data(), mass,
                                                             T(scene_.surface_tension.kappa), T(scene_.surface_tension.kappa_boundary),
                                                             s.accel.data()});
    modules_.CountLaunch("surface_tension");
  }
  if (modules_.Enabled("air_pressure")) {
    exec::ParallelFor(device_, n, kernels::AirPressureAcceleration<T>{s.FF(), s.FB(), s.density.data(), s.bvol.data(), mass,
                                                                       T(scene_.air_pressure.p_atm), s.accel.data()});
    modules_.CountLaunch("air_pressure");
  }
  s.v_adv.resize(n);
  const bool wall_viscosity = modules_.Enabled("viscosity");
  const T wall_coefficient = wall_viscosity ? T(scene_.viscosity.wall_beta0 * scene_.viscosity.beta1) : T(0);
  exec::ParallelFor(device_, n,
                    kernels::AdvectVelocity<T>{s.v.data(), s.accel.data(), T(dt), s.FB(), s.x.data(), s.bx.data(), s.bv.data(),
                                               s.bpsi.data(), s.density.data(), wall_coefficient, h, T(scene_.viscosity.epsilon),
                                               T(scene_.fluid.rest_density), scene_.viscosity.limiter, CubicSpline<T>(h), s.v_adv.data()});
}

template <class T>
StepStats Simulation<T>::SolvePressure(double dt, double omega) {
  State& s = *state_;
  const Index n = s.n();
  const io::SolverSettings& solver = scene_.solver;
  const T mass = T(scene_.fluid.particle_mass());
  const T h = T(scene_.fluid.smoothing_length());
  const double rho0 = scene_.fluid.rest_density;
  for (auto* a : {&s.advected_error, &s.a_ii, &s.pressure, &s.pressure_next, &s.compression}) a->resize(n);
  s.d_ii.resize(n);
  s.s.resize(n);
  const T chi = solver.aii_boundary == "splishsplash" ? T(1) : T(0);
  exec::ParallelFor(device_, n,
                    kernels::PredictAdvection<T>{s.FF(), s.FB(), s.v_adv.data(), s.bv.data(), s.bpsi.data(), s.density.data(),
                                                 s.density_error.data(), s.pressure_previous.data(), mass, T(dt), chi, T(solver.warm_start),
                                                 s.d_ii.data(), s.advected_error.data(), s.a_ii.data(), s.pressure.data()});
  // ε_a = 1e-6 Δt²/h² (spec §6): below it a particle is (nearly) isolated and gets p = 0.
  const T min_aii = T(1e-6 * dt * dt / (double(h) * double(h)));
  StepStats stats;
  stats.dt = dt;
  double previous_error = INFINITY;
  int growth_streak = 0;
  for (int l = 0; l < solver.max_iterations; ++l) {
    exec::ParallelFor(device_, n, kernels::DisplacementSum<T>{s.FF(), s.pressure.data(), s.density.data(), mass, T(dt), s.s.data()});
    exec::ParallelFor(device_, n,
                      kernels::PressureUpdate<T>{s.FF(), s.FB(), s.s.data(), s.d_ii.data(), s.a_ii.data(), s.pressure.data(),
                                                 s.density.data(), s.advected_error.data(), s.bpsi.data(), mass, T(dt), T(omega),
                                                 min_aii, s.pressure_next.data(), s.compression.data()});
    s.pressure.swap(s.pressure_next);
    const double error = exec::Sum(device_, s.compression.data(), n) / double(n) / rho0;
    stats.pressure_iterations = l + 1;
    stats.average_density_error = error;
    if (!std::isfinite(error)) break;
    if (error <= solver.eta && l + 1 >= solver.min_iterations) {
      stats.converged = true;
      return stats;
    }
    growth_streak = error > previous_error ? growth_streak + 1 : 0;
    previous_error = error;
    if (growth_streak >= 3 && omega > 0.5 && solver.omega_fallback) {
      // Weighted Jacobi with ω = 0.8 can diverge (spec §6): restart this step's solve with 0.5.
      StepStats retry = SolvePressure(dt, 0.5);
      retry.omega_fallback = true;
      retry.pressure_iterations += stats.pressure_iterations;
      return retry;
    }
  }
  stats.converged = false;
  return stats;
}

template <class T>
void Simulation<T>::Integrate(double dt) {
  State& s = *state_;
  exec::ParallelFor(device_, s.n(),
                    kernels::IntegratePressure<T>{s.FF(), s.FB(), s.pressure.data(), s.density.data(), s.bpsi.data(), s.v_adv.data(),
                                                  T(scene_.fluid.particle_mass()), T(dt), s.v.data(), s.x.data(),
                                                  s.pressure_previous.data()});
}

template <class T>
void Simulation<T>::RemoveOutsideDomain(StepStats& stats) {
  State& s = *state_;
  const Index n = s.n();
  if (n == 0) return;
  s.keep.resize(n);
  s.slot.resize(n);
  exec::ParallelFor(device_, n, kernels::InsideDomain<T>{s.x.data(), domain_min_, domain_max_, s.keep.data()});
  const Index kept = static_cast<Index>(exec::ExclusiveScan(device_, s.keep.data(), s.slot.data(), n));
  if (kept == n) return;
  s.order.resize(kept);
  exec::ParallelFor(device_, n, kernels::CompactionOrder{s.keep.data(), s.slot.data(), s.order.data()});
  Reorder(device_, s.x, s.tmp_vec, s.order.data(), kept);
  Reorder(device_, s.v, s.tmp_vec, s.order.data(), kept);
  Reorder(device_, s.pressure_previous, s.tmp_scalar, s.order.data(), kept);
  Reorder(device_, s.id, s.tmp_id, s.order.data(), kept);
  stats.removed_particles = n - kept;
  removed_total_ += n - kept;
}

template <class T>
void Simulation<T>::Emit(double dt, StepStats& stats) {
  State& s = *state_;
  const double dp = scene_.fluid.spacing;
  std::vector<Vec3<T>> new_x, new_v;
  for (std::size_t e = 0; e < scene_.emitters.size(); ++e) {
    const io::Emitter& em = scene_.emitters[e];
    // Active part of [time, time + dt) within [start, stop).
    const double t0 = std::max(time_, em.start), t1 = std::min(time_ + dt, em.stop);
    if (t1 <= t0) continue;
    emitter_travel_[e] += em.speed * (t1 - t0);
    const Vec3d dir = em.direction / Norm(em.direction);
    const Vec3d helper = std::fabs(dir.z) < 0.9 ? Vec3d(0, 0, 1) : Vec3d(1, 0, 0);
    const Vec3d u = Cross(dir, helper) / Norm(Cross(dir, helper));
    const Vec3d w = Cross(dir, u);
    const double half_u = em.shape == "disc" ? em.radius : em.width / 2;
    const double half_w = em.shape == "disc" ? em.radius : em.height / 2;
    const std::int64_t nu = std::int64_t(std::floor(half_u / dp + 1e-9)), nw = std::int64_t(std::floor(half_w / dp + 1e-9));
    while (emitter_travel_[e] >= dp) {
      emitter_travel_[e] -= dp;
      // The layer emitted `travel` ago has moved that far already.
      const Vec3d base = em.center + dir * emitter_travel_[e];
      for (std::int64_t a = -nu; a <= nu; ++a)
        for (std::int64_t b = -nw; b <= nw; ++b) {
          if (em.shape == "disc" && std::hypot(a * dp, b * dp) > em.radius + 1e-9) continue;
          new_x.push_back(ToT<T>(base + u * (a * dp) + w * (b * dp)));
          new_v.push_back(ToT<T>(dir * em.speed));
        }
    }
  }
  if (new_x.empty()) return;
  const Index n = s.n(), m = Index(new_x.size());
  std::vector<std::int64_t> ids(m);
  for (auto& id : ids) id = next_id_++;
  s.x.resize(n + m);
  s.v.resize(n + m);
  s.id.resize(n + m);
  s.pressure_previous.resize(n + m);  // new particles start with p = 0
  exec::CopyToDevice(device_, s.x.data() + n, new_x.data(), m * sizeof(Vec3<T>));
  exec::CopyToDevice(device_, s.v.data() + n, new_v.data(), m * sizeof(Vec3<T>));
  exec::CopyToDevice(device_, s.id.data() + n, ids.data(), m * sizeof(std::int64_t));
  stats.emitted_particles = m;
}

template <class T>
void Simulation<T>::CheckDivergence(const StepStats& stats) const {
  const double limit = scene_.solver.divergence_density_error;
  const bool bad_error = !std::isfinite(stats.average_density_error) || stats.average_density_error > limit;
  const bool bad_speed = !std::isfinite(stats.max_speed);
  if (!bad_error && !bad_speed) return;
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
  const std::string reason = bad_speed ? "a particle velocity became NaN or infinite"
                                       : fmt::format("average density error {:.3g}% exceeds the limit {:.3g}% (simulation.divergence_density_error)",
                                                     100 * stats.average_density_error, 100 * limit);
  throw Error(ExitCode::kDiverged, fmt::format("simulation diverged at step {} (t = {:.6g} s, dt = {:.3g} s): {}; {}. Reduce "
                                               "simulation.dt_max or cfl, or check the scene",
                                               step_count_, time_, stats.dt, reason, particle));
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
  {
    PhaseTimer t(device_, timing_enabled_, timings_.non_pressure);
    ComputeDensity();
    NonPressureAccelerations(dt);
  }
  StepStats solve;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.pressure_solve);
    solve = SolvePressure(dt, scene_.solver.omega);
  }
  solve.emitted_particles = stats.emitted_particles;
  stats = solve;
  {
    PhaseTimer t(device_, timing_enabled_, timings_.integration);
    Integrate(dt);
    stats.max_density_error = s.n() ? exec::Max(device_, s.compression.data(), s.n()) / scene_.fluid.rest_density : 0;
    s.scratch.resize(s.n());
    exec::ParallelFor(device_, s.n(), kernels::SquaredSpeed<T>{s.v.data(), s.scratch.data()});
    stats.max_speed = std::sqrt(double(exec::Max(device_, s.scratch.data(), s.n())));
  }
  time_ += dt;
  ++step_count_;
  CheckDivergence(stats);
  RemoveOutsideDomain(stats);
  stats.fluid_particles = s.n();
  return stats;
}

template <class T>
std::size_t Simulation<T>::MemoryBytes() const {
  const State& s = *state_;
  std::size_t bytes = 0;
  for (const auto* a : {&s.x, &s.v, &s.v_adv, &s.accel, &s.d_ii, &s.s, &s.bx, &s.bv, &s.blocal, &s.ff_grad, &s.fb_grad, &s.tmp_vec}) bytes += a->bytes();
  for (const auto* a : {&s.density, &s.density_error, &s.pressure, &s.pressure_next, &s.pressure_previous, &s.advected_error, &s.a_ii,
                        &s.compression, &s.scratch, &s.color, &s.energy, &s.bpsi, &s.bvol, &s.ff_w, &s.fb_w, &s.tmp_scalar})
    bytes += a->bytes();
  bytes += s.ff.offsets.bytes() + s.ff.indices.bytes() + s.fb.offsets.bytes() + s.fb.indices.bytes();
  return bytes;
}

template <class T> std::vector<Vec3<T>> Simulation<T>::Positions() const { return state_->x.ToHost(); }
template <class T> std::vector<Vec3<T>> Simulation<T>::Velocities() const { return state_->v.ToHost(); }
template <class T> std::vector<T> Simulation<T>::Densities() const { return state_->density.ToHost(); }
template <class T> std::vector<T> Simulation<T>::Pressures() const { return state_->pressure_previous.ToHost(); }
template <class T> std::vector<std::int64_t> Simulation<T>::Ids() const { return state_->id.ToHost(); }
template <class T> std::vector<Vec3<T>> Simulation<T>::BoundaryPositions() const { return state_->bx.ToHost(); }
template <class T> std::vector<T> Simulation<T>::BoundaryVolumes() const { return state_->bvol.ToHost(); }
template <class T> std::vector<Vec3<T>> Simulation<T>::NonPressureAccelerations() const { return state_->accel.ToHost(); }

template <class T>
void Simulation<T>::SetFluidState(const std::vector<Vec3<T>>& x, const std::vector<Vec3<T>>& v) {
  State& s = *state_;
  if (x.size() != v.size()) throw Error(ExitCode::kFailure, "SetFluidState: size mismatch");
  const bool resized = Index(x.size()) != s.n();
  s.x.assign(x);
  s.v.assign(v);
  if (resized) {
    std::vector<std::int64_t> ids(x.size());
    for (auto& id : ids) id = next_id_++;
    s.id.assign(ids);
    s.pressure_previous.resize(x.size());
    s.pressure_previous.SetZero();
  }
  initialized_ = true;
}

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
  for (std::size_t e = 0; e < emitter_travel_.size(); ++e) f.numbers[fmt::format("emitter_travel_{}", e)] = emitter_travel_[e];
  f.texts["modules"] = fmt::format("{}", fmt::join(modules_.enabled(), ","));
  const auto x = s.x.ToHost();
  f.SetPositions(x);
  const auto v = s.v.ToHost();
  std::vector<T> vx(v.size()), vy(v.size()), vz(v.size());
  for (std::size_t i = 0; i < v.size(); ++i) vx[i] = v[i].x, vy[i] = v[i].y, vz[i] = v[i].z;
  f.Set("vx", std::move(vx));
  f.Set("vy", std::move(vy));
  f.Set("vz", std::move(vz));
  f.Set("id", s.id.ToHost());
  f.Set("phase", std::vector<std::uint8_t>(x.size(), static_cast<std::uint8_t>(io::Phase::kFluid)));
  f.Set("pressure", s.pressure_previous.ToHost());
  std::vector<T> density = s.density.size() == x.size() ? s.density.ToHost() : std::vector<T>(x.size(), T(scene_.fluid.rest_density));
  f.Set("density", std::move(density));
  return f;
}

template <class T>
void Simulation<T>::Restore(const io::ParticleFrame& f) {
  if (!initialized_) Initialize();
  State& s = *state_;
  const auto bits = f.numbers.find("precision_bits");
  if (bits == f.numbers.end() || bits->second != double(sizeof(T) * 8))
    throw InputError(fmt::format("checkpoint precision does not match the scene's water.precision = \"{}\"", scene_.fluid.precision), f.source);
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
  for (std::size_t e = 0; e < emitter_travel_.size(); ++e) emitter_travel_[e] = number(fmt::format("emitter_travel_{}", e));
  const auto x = f.GetPositions<T>();
  const auto& vx = f.Get<T>("vx");
  const auto& vy = f.Get<T>("vy");
  const auto& vz = f.Get<T>("vz");
  std::vector<Vec3<T>> v(x.size());
  for (std::size_t i = 0; i < v.size(); ++i) v[i] = {vx[i], vy[i], vz[i]};
  s.x.assign(x);
  s.v.assign(v);
  s.id.assign(f.Get<std::int64_t>("id"));
  s.pressure_previous.assign(f.Get<T>("pressure"));
  s.density.assign(f.Get<T>("density"));
  UpdateBoundaryMotion(time_);
}

template class Simulation<float>;
template class Simulation<double>;

}  // namespace rime::sph
