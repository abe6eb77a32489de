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
  s.fluid_grid.Build(s.fluid.x.data(), n, support, lattice_origin_);
  // Reorder the persistent water state along the grid's Z curve for cache locality.
  s.order.resize(n);
  exec::CopyOnDevice(device_, s.order.data(), s.fluid_grid.order(), n * sizeof(std::uint32_t));
  s.GatherFluid(device_, n);
  s.fluid_grid.AdoptOrder(s.fluid.x.data());

  const CubicSpline<T> kernel(T(scene_.fluid.smoothing_length()));
  Neighborhoods<T>& p = s.pairs;
  s.fluid_grid.QueryGrid(s.fluid_grid, support, true, p.ff);
  p.ff_w.resize(p.ff.pairs());
  p.ff_grad.resize(p.ff.pairs());
  exec::ParallelFor(device_, n,
                    kernels::PairValues<T>{.xi = s.fluid.x.data(), .xj = s.fluid.x.data(), .offsets = p.ff.offsets.data(),
                                           .index = p.ff.indices.data(), .kernel = kernel, .w = p.ff_w.data(), .grad = p.ff_grad.data()});
  s.boundary_grid.QueryGrid(s.fluid_grid, support, false, p.fb);
  p.fb_w.resize(p.fb.pairs());
  p.fb_grad.resize(p.fb.pairs());
  exec::ParallelFor(device_, n,
                    kernels::PairValues<T>{.xi = s.fluid.x.data(), .xj = s.boundary.x.data(), .offsets = p.fb.offsets.data(),
                                           .index = p.fb.indices.data(), .kernel = kernel, .w = p.fb_w.data(), .grad = p.fb_grad.data()});
}

template <class T>
double Simulation<T>::ComputeDensity() {
  State& s = *state_;
  const Index n = s.n();
  s.fluid.density.resize(n);
  s.step.density_error.resize(n);
  const CubicSpline<T> kernel(T(scene_.fluid.smoothing_length()));
  exec::ParallelFor(device_, n,
                    kernels::Density<T>{.ff = s.FF(), .fb = s.FB(), .boundary_psi = s.boundary.psi.data(), .mass = T(scene_.fluid.particle_mass()),
                                        .w0 = kernel.W0(), .rest_density = T(scene_.fluid.rest_density), .density = s.fluid.density.data(),
                                        .density_error = s.step.density_error.data()});
  s.step.scratch.resize(n);
  exec::ParallelFor(device_, n, kernels::Compression<T>{s.step.density_error.data(), s.step.scratch.data()});
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
  exec::ParallelFor(device_, n, kernels::InitAcceleration<T>{gravity, st.accel.data()});
  if (modules_.Enabled("viscosity")) {
    const io::ViscositySettings& vs = scene_.viscosity;
    exec::ParallelFor(device_, n, kernels::ViscosityAcceleration<T>{s.FF(), s.fluid.x.data(), s.fluid.v.data(), s.fluid.density.data(), mass, T(vs.mu),
                                                                     T(vs.beta0 * vs.beta1), h, T(vs.epsilon), vs.limiter, st.accel.data()});
    modules_.CountLaunch("viscosity");
  }
  if (s.normals) {
    const io::SurfaceTensionSettings& tension = scene_.surface_tension;
    const T support = T(2) * h;
    s.normals->normal.resize(n);
    exec::ParallelFor(device_, n, kernels::AkinciNormal<T>{s.FF(), s.fluid.density.data(), mass, support, s.normals->normal.data()});
    exec::ParallelFor(device_, n,
                      kernels::AkinciSurfaceTensionAcceleration<T>{s.FF(), s.FB(), s.fluid.x.data(), s.boundary.x.data(), s.fluid.density.data(),
                                                                   s.normals->normal.data(), s.boundary.psi.data(), mass, T(tension.gamma),
                                                                   T(tension.beta), T(scene_.fluid.rest_density), support, st.accel.data()});
    modules_.CountLaunch("surface_tension");
  } else if (s.color_field) {
    const CubicSpline<T> kernel(h);
    SurfaceColorField<T>& c = *s.color_field;
    c.color.resize(n);
    c.energy.resize(n);
    exec::ParallelFor(device_, n,
                      kernels::SurfaceColor<T>{s.FF(), s.FB(), s.fluid.density.data(), s.boundary.volume.data(), mass, kernel.W0(), c.color.data()});
    exec::ParallelFor(device_, n, kernels::SurfaceEnergy<T>{s.FF(), s.fluid.density.data(), c.color.data(), mass, c.energy.data()});
    exec::ParallelFor(device_, n,
                      kernels::SurfaceTensionAcceleration<T>{s.FF(), s.FB(), s.fluid.density.data(), c.energy.data(), s.boundary.volume.data(), mass,
                                                             T(scene_.surface_tension.kappa), T(scene_.surface_tension.kappa_boundary),
                                                             st.accel.data()});
    modules_.CountLaunch("surface_tension");
  }
  if (modules_.Enabled("air_pressure")) {
    exec::ParallelFor(device_, n, kernels::AirPressureAcceleration<T>{s.FF(), s.FB(), s.fluid.density.data(), s.boundary.volume.data(), mass,
                                                                       T(scene_.air_pressure.p_atm), st.accel.data()});
    modules_.CountLaunch("air_pressure");
  }
  st.v_adv.resize(n);
  const bool wall_viscosity = modules_.Enabled("viscosity");
  const T wall_coefficient = wall_viscosity ? T(scene_.viscosity.wall_beta0 * scene_.viscosity.beta1) : T(0);
  exec::ParallelFor(device_, n,
                    kernels::AdvectVelocity<T>{s.fluid.v.data(), st.accel.data(), T(dt), s.FB(), s.fluid.x.data(), s.boundary.x.data(),
                                               s.boundary.v.data(), s.boundary.psi.data(), s.fluid.density.data(), wall_coefficient, h,
                                               T(scene_.viscosity.epsilon), T(scene_.fluid.rest_density), scene_.viscosity.limiter,
                                               CubicSpline<T>(h), s.FF(), s.fluid.pressure.data(), mass, st.v_adv.data()});
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
  const T chi = solver.aii_boundary == "splishsplash" ? T(1) : T(0);
  exec::ParallelFor(device_, n,
                    kernels::PredictAdvection<T>{s.FF(), s.FB(), st.v_adv.data(), s.boundary.v.data(), s.boundary.psi.data(), s.fluid.density.data(),
                                                 st.density_error.data(), s.fluid.pressure.data(), mass, T(dt), chi, T(solver.warm_start),
                                                 st.d_ii.data(), st.advected_error.data(), st.a_ii.data(), st.pressure.data()});
  // ε_a = 1e-6 Δt²/h² (spec §6): below it a particle is (nearly) isolated and gets p = 0.
  const T min_aii = T(1e-6 * dt * dt / (double(h) * double(h)));
  StepStats stats;
  stats.dt = dt;
  double previous_error = INFINITY;
  int growth_streak = 0;
  for (int l = 0; l < solver.max_iterations; ++l) {
    exec::ParallelFor(device_, n, kernels::DisplacementSum<T>{s.FF(), st.pressure.data(), s.fluid.density.data(), mass, T(dt), st.s.data()});
    exec::ParallelFor(device_, n,
                      kernels::PressureUpdate<T>{s.FF(), s.FB(), st.s.data(), st.d_ii.data(), st.a_ii.data(), st.pressure.data(),
                                                 s.fluid.density.data(), st.advected_error.data(), s.boundary.psi.data(), mass, T(dt), T(omega),
                                                 min_aii, st.pressure_next.data(), st.compression.data()});
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
                    kernels::IntegratePressure<T>{s.FF(), s.FB(), s.step.pressure.data(), s.fluid.density.data(), s.boundary.psi.data(),
                                                  s.step.v_adv.data(), T(scene_.fluid.particle_mass()), T(dt), s.fluid.v.data(), s.fluid.x.data(),
                                                  s.fluid.pressure.data()});
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
