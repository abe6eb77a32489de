/// @file iisph.cpp
/// @brief One IISPH step of the water (docs/physics.md): neighbor search and Z-order reordering,
/// kernel-sum density, the non-pressure accelerations of the enabled modules (gravity, viscosity,
/// surface tension, air pressure) with the implicit wall viscosity, the relaxed-Jacobi pressure
/// solve with its ω fallback, and the pressure integration of velocities and positions.

#include <cmath>

#include "rime/core/kernel.h"
#include "rime/exec/parallel.h"
#include "state.h"

namespace rime::sph {

template <class T>
void Simulation<T>::NeighborSearch() {
  State& s = *state_;
  const Index n = s.n();
  const T support = T(2 * scene_.fluid.smoothing_length());
  {
    PhaseTimer t(device_, timing_enabled_, timings_.grid_build);
    s.fluid_grid.Build(s.fluid.x.data(), n, support, lattice_origin_);
    // Reorder the persistent water state along the grid's Z curve for cache locality.
    s.order.resize(n);
    exec::CopyOnDevice(device_, s.order.data(), s.fluid_grid.order(), n * sizeof(std::uint32_t));
    s.GatherFluid(device_, n);
    s.fluid_grid.AdoptOrder(s.fluid.x.data());
  }

  const CubicSpline<T> kernel(T(scene_.fluid.smoothing_length()));
  Neighborhoods<T>& p = s.pairs;
  // w and ∇W of every pair, from the water (ff) and from the boundary (fb), found with the lists.
  {
    PhaseTimer t(device_, timing_enabled_, timings_.fluid_lists);
    s.fluid_grid.QueryGrid(s.fluid_grid, support, true, p.ff, {.kernel = kernel, .w = p.ff_w, .grad = p.ff_grad});
  }
  PhaseTimer t(device_, timing_enabled_, timings_.boundary_lists);
  s.boundary_grid.QueryGrid(s.fluid_grid, support, false, p.fb, {.kernel = kernel, .w = p.fb_w, .grad = p.fb_grad});
}

template <class T>
double Simulation<T>::ComputeDensity() {
  State& s = *state_;
  const Index n = s.n();
  s.fluid.density.resize(n);
  s.step.density_error.resize(n);
  const CubicSpline<T> kernel(T(scene_.fluid.smoothing_length()));
  exec::ParallelFor(device_, n,
                    kernels::Density<T>{.ff = s.FF(),
                                        .fb = s.FB(),
                                        .boundary_psi = s.boundary.psi.data(),
                                        .mass = T(scene_.fluid.particle_mass()),
                                        .w0 = kernel.W0(),
                                        .rest_density = T(scene_.fluid.rest_density),
                                        .density = s.fluid.density.data(),
                                        .density_error = s.step.density_error.data()});
  s.step.scratch.resize(n);
  exec::ParallelFor(device_, n,
                    kernels::Compression<T>{.density_error = s.step.density_error.data(), .compression = s.step.scratch.data()});
  return exec::Sum(device_, s.step.scratch.data(), n) / double(n) / scene_.fluid.rest_density;
}

template <class T>
void Simulation<T>::NonPressureAccelerations(double dt) {
  State& s = *state_;
  FluidStep<T>& st = s.step;
  const Index n = s.n();
  const T mass = T(scene_.fluid.particle_mass());
  const T h = T(scene_.fluid.smoothing_length());
  st.accel.resize(n);
  const Vec3<T> gravity = modules_.Enabled("gravity") ? ToT<T>(scene_.solver.gravity) : Vec3<T>{};
  exec::ParallelFor(device_, n, kernels::InitAcceleration<T>{.gravity = gravity, .accel = st.accel.data()});
  if (modules_.Enabled("viscosity")) {
    const io::ViscositySettings& vs = scene_.viscosity;
    exec::ParallelFor(device_, n,
                      kernels::ViscosityAcceleration<T>{.ff = s.FF(),
                                                        .x = s.fluid.x.data(),
                                                        .v = s.fluid.v.data(),
                                                        .density = s.fluid.density.data(),
                                                        .mass = mass,
                                                        .mu = T(vs.mu),
                                                        .beta0_beta1 = T(vs.beta0 * vs.beta1),
                                                        .h = h,
                                                        .epsilon = T(vs.epsilon),
                                                        .limiter = vs.limiter,
                                                        .accel = st.accel.data()});
    modules_.CountLaunch("viscosity");
  }
  if (s.normals) {
    const io::SurfaceTensionSettings& tension = scene_.surface_tension;
    const T support = T(2) * h;
    s.normals->normal.resize(n);
    exec::ParallelFor(
        device_, n,
        kernels::AkinciNormal<T>{
            .ff = s.FF(), .density = s.fluid.density.data(), .mass = mass, .support = support, .normal = s.normals->normal.data()});
    exec::ParallelFor(device_, n,
                      kernels::AkinciSurfaceTensionAcceleration<T>{.ff = s.FF(),
                                                                   .fb = s.FB(),
                                                                   .x = s.fluid.x.data(),
                                                                   .boundary_x = s.boundary.x.data(),
                                                                   .density = s.fluid.density.data(),
                                                                   .normal = s.normals->normal.data(),
                                                                   .boundary_psi = s.boundary.psi.data(),
                                                                   .mass = mass,
                                                                   .gamma = T(tension.gamma),
                                                                   .beta = T(tension.beta),
                                                                   .rest_density = T(scene_.fluid.rest_density),
                                                                   .support = support,
                                                                   .accel = st.accel.data()});
    modules_.CountLaunch("surface_tension");
  } else if (s.color_field) {
    const CubicSpline<T> kernel(h);
    SurfaceColorField<T>& c = *s.color_field;
    c.color.resize(n);
    c.energy.resize(n);
    exec::ParallelFor(device_, n,
                      kernels::SurfaceColor<T>{.ff = s.FF(),
                                               .fb = s.FB(),
                                               .density = s.fluid.density.data(),
                                               .boundary_volume = s.boundary.volume.data(),
                                               .mass = mass,
                                               .w0 = kernel.W0(),
                                               .color = c.color.data()});
    exec::ParallelFor(
        device_, n,
        kernels::SurfaceEnergy<T>{
            .ff = s.FF(), .density = s.fluid.density.data(), .color = c.color.data(), .mass = mass, .energy = c.energy.data()});
    exec::ParallelFor(device_, n,
                      kernels::SurfaceTensionAcceleration<T>{.ff = s.FF(),
                                                             .fb = s.FB(),
                                                             .density = s.fluid.density.data(),
                                                             .energy = c.energy.data(),
                                                             .boundary_volume = s.boundary.volume.data(),
                                                             .mass = mass,
                                                             .kappa = T(scene_.surface_tension.kappa),
                                                             .kappa_boundary = T(scene_.surface_tension.kappa_boundary),
                                                             .accel = st.accel.data()});
    modules_.CountLaunch("surface_tension");
  }
  if (modules_.Enabled("air_pressure")) {
    exec::ParallelFor(device_, n,
                      kernels::AirPressureAcceleration<T>{.ff = s.FF(),
                                                          .fb = s.FB(),
                                                          .density = s.fluid.density.data(),
                                                          .boundary_volume = s.boundary.volume.data(),
                                                          .mass = mass,
                                                          .p_atm = T(scene_.air_pressure.p_atm),
                                                          .accel = st.accel.data()});
    modules_.CountLaunch("air_pressure");
  }
  st.v_adv.resize(n);
  const bool wall_viscosity = modules_.Enabled("viscosity");
  const T wall_coefficient = wall_viscosity ? T(scene_.viscosity.wall_beta0 * scene_.viscosity.beta1) : T(0);
  exec::ParallelFor(device_, n,
                    kernels::AdvectVelocity<T>{.v = s.fluid.v.data(),
                                               .accel = st.accel.data(),
                                               .dt = T(dt),
                                               .fb = s.FB(),
                                               .x = s.fluid.x.data(),
                                               .boundary_x = s.boundary.x.data(),
                                               .boundary_v = s.boundary.v.data(),
                                               .boundary_psi = s.boundary.psi.data(),
                                               .density = s.fluid.density.data(),
                                               .wall_coefficient = wall_coefficient,
                                               .h = h,
                                               .epsilon = T(scene_.viscosity.epsilon),
                                               .rest_density = T(scene_.fluid.rest_density),
                                               .limiter = scene_.viscosity.limiter,
                                               .kernel = CubicSpline<T>(h),
                                               .ff = s.FF(),
                                               .pressure_previous = s.fluid.pressure.data(),
                                               .mass = mass,
                                               .v_adv = st.v_adv.data()});
}

template <class T>
StepStats Simulation<T>::SolvePressure(double dt, double omega) {
  State& s = *state_;
  FluidStep<T>& st = s.step;
  const Index n = s.n();
  const io::SolverSettings& solver = scene_.solver;
  const T mass = T(scene_.fluid.particle_mass());
  const T h = T(scene_.fluid.smoothing_length());
  const double rho0 = scene_.fluid.rest_density;
  for (auto* a : {&st.advected_error, &st.a_ii, &st.pressure, &st.pressure_next, &st.compression}) a->resize(n);
  st.d_ii.resize(n);
  st.s.resize(n);
  const T chi = solver.aii_boundary == io::AiiBoundary::kSplishSplash ? T(1) : T(0);
  exec::ParallelFor(device_, n,
                    kernels::PredictAdvection<T>{.ff = s.FF(),
                                                 .fb = s.FB(),
                                                 .v_adv = st.v_adv.data(),
                                                 .boundary_v = s.boundary.v.data(),
                                                 .boundary_psi = s.boundary.psi.data(),
                                                 .density = s.fluid.density.data(),
                                                 .density_error = st.density_error.data(),
                                                 .pressure_previous = s.fluid.pressure.data(),
                                                 .mass = mass,
                                                 .dt = T(dt),
                                                 .chi = chi,
                                                 .warm_start = T(solver.warm_start),
                                                 .d_ii = st.d_ii.data(),
                                                 .advected_error = st.advected_error.data(),
                                                 .a_ii = st.a_ii.data(),
                                                 .pressure = st.pressure.data()});
  // ε_a = 1e-6 Δt²/h² (spec §6): below it a particle is (nearly) isolated and gets p = 0.
  const T min_aii = T(1e-6 * dt * dt / (double(h) * double(h)));
  StepStats stats;
  stats.dt = dt;
  double previous_error = INFINITY;
  int growth_streak = 0;
  for (int l = 0; l < solver.max_iterations; ++l) {
    exec::ParallelFor(
        device_, n,
        kernels::DisplacementSum<T>{
            .ff = s.FF(), .pressure = st.pressure.data(), .density = s.fluid.density.data(), .mass = mass, .dt = T(dt), .s = st.s.data()});
    exec::ParallelFor(device_, n,
                      kernels::PressureUpdate<T>{.ff = s.FF(),
                                                 .fb = s.FB(),
                                                 .s = st.s.data(),
                                                 .d_ii = st.d_ii.data(),
                                                 .a_ii = st.a_ii.data(),
                                                 .pressure = st.pressure.data(),
                                                 .density = s.fluid.density.data(),
                                                 .advected_error = st.advected_error.data(),
                                                 .boundary_psi = s.boundary.psi.data(),
                                                 .mass = mass,
                                                 .dt = T(dt),
                                                 .omega = T(omega),
                                                 .min_aii = min_aii,
                                                 .pressure_next = st.pressure_next.data(),
                                                 .compression = st.compression.data()});
    st.pressure.swap(st.pressure_next);
    const double error = exec::Sum(device_, st.compression.data(), n) / double(n) / rho0;
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
                    kernels::IntegratePressure<T>{.ff = s.FF(),
                                                  .fb = s.FB(),
                                                  .pressure = s.step.pressure.data(),
                                                  .density = s.fluid.density.data(),
                                                  .boundary_psi = s.boundary.psi.data(),
                                                  .v_adv = s.step.v_adv.data(),
                                                  .mass = T(scene_.fluid.particle_mass()),
                                                  .dt = T(dt),
                                                  .v = s.fluid.v.data(),
                                                  .x = s.fluid.x.data(),
                                                  .pressure_previous = s.fluid.pressure.data()});
}

#define RIME_SPH_IISPH_MEMBERS(T)                                  \
  template void Simulation<T>::NeighborSearch();                   \
  template double Simulation<T>::ComputeDensity();                 \
  template void Simulation<T>::NonPressureAccelerations(double);   \
  template StepStats Simulation<T>::SolvePressure(double, double); \
  template void Simulation<T>::Integrate(double);
RIME_SPH_IISPH_MEMBERS(float)
RIME_SPH_IISPH_MEMBERS(double)

}  // namespace rime::sph
