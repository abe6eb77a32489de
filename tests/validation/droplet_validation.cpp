// Oscillating droplet with surface tension (He et al. 2014 module `surface_tension`, no gravity)
// against Rayleigh's theory: a free drop of radius R, density ρ and surface tension σ oscillates
// in mode l with ω² = l(l−1)(l+2) σ / (ρ R³) (Lord Rayleigh 1879; Lamb, Hydrodynamics §275), so
// for l = 2 the period is 2π sqrt(ρ R³ / (8σ)) ∝ R^1.5 at fixed σ.
//
// Each drop is first relaxed from its lattice sphere (velocities zeroed after every step); the
// interior pressure then gives a static σ from Laplace's Δp = 2σ/R. The drop is given the l = 2
// potential-flow velocity v = A (−x, −y, 2z) about its centre; the signal s = <z² − (x² + y²)/2>
// is zero for the relaxed drop (cubic symmetry) and should oscillate at ω: the period comes from
// its zero crossings, corrected for the measured viscous decay. He 2014's κ is an energy
// coefficient, not σ: the σ implied by each period is printed beside Laplace's and κ/(2h), the
// spec's estimate (spec §5.3).
//
// Status (see README.md): with the current solver the kicked drop does not oscillate: it deforms
// and stays deformed (no zero crossing within three Laplace periods), so this program fails and
// its CTest entry is disabled until the surface-tension model restores shape.
//
// Usage: rime_validation_droplet [--full]   (RIME_VALIDATION_FULL=1 = --full)
#include <cmath>
#include <cstdio>
#include <vector>

#include "rime/exec/device.h"
#include "rime/sph/simulation.h"
#include "validation_common.h"

namespace rime::validation {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDp = 0.01;  // m, h = d_p
constexpr double kRho = 1000;

// Damping: without any viscosity the relaxed drop does not stay still (see README: the lattice
// sphere's cubic-symmetric deformation grows and particles leave it), so the viscosity module runs
// with β0 = 0.01 instead of the spec's 0.1: ν_eff = β0 β1 h / 10 = 1e-4 m²/s, which damps the l = 2
// mode at γ = 5ν/R² (Lamb §355), 0.06–0.2 1/s here, i.e. under 10 % of ω.
constexpr double kBeta0 = 0.01;

struct Result {
  double radius = 0, period = 0, sigma = 0, sigma_laplace = 0, damping = 0;
  double largest = 0, last = 0;  // largest |s| after the kick and s at the end, in R²
  std::int64_t particles = 0, steps = 0;
  int crossings = 0;
  double seconds = 0;
};

/// s = mean of z² − (x² + y²)/2 about the centroid: zero for a cubic-symmetric drop, linear in an
/// l = 2 (axisymmetric about z) deformation.
template <class T>
double Deformation(const std::vector<Vec3<T>>& x) {
  Vec3d c{};
  for (const auto& p : x) c += Vec3d(p);
  c /= double(x.size());
  double s = 0;
  for (const auto& p : x) {
    const Vec3d d = Vec3d(p) - c;
    s += d.z * d.z - 0.5 * (d.x * d.x + d.y * d.y);
  }
  return s / double(x.size());
}

Result Oscillate(int radius_in_dp, double kappa) {
  io::Scene scene;
  scene.fluid.spacing = kDp;
  scene.modules = {"surface_tension", "viscosity"};
  scene.viscosity.beta0 = kBeta0;
  scene.surface_tension.kappa = kappa;
  io::FluidBlock drop;
  drop.shape = "sphere";
  drop.center = {0, 0, 0};
  drop.radius = radius_in_dp * kDp;
  scene.fluid_blocks.push_back(drop);

  sph::Simulation<double> sim(scene, exec::Device::Cpu());  // spec §7 time step: CFL 0.4, Δt ≤ 6 ms
  sim.Initialize();
  Result r;
  r.particles = sim.fluid_count();
  r.radius = std::cbrt(3.0 * double(r.particles) / (4 * kPi)) * kDp;  // from the water's volume
  Stopwatch watch;

  // Relax the lattice sphere (velocities removed after every step), then read the Laplace
  // pressure Δp = 2σ/R from the particles deeper than 2h: a static estimate of σ.
  const std::vector<Vec3d> zero(r.particles);
  const int relax_steps = 200, pressure_steps = 50;
  double pressure = 0;
  std::int64_t pressure_count = 0;
  for (int step = 0; step < relax_steps; ++step) {
    sim.Step(sim.NextTimeStep(1e30));
    const auto x = sim.Positions();
    sim.SetFluidState(x, zero);
    if (step < relax_steps - pressure_steps) continue;
    Vec3d c{};
    for (const auto& p : x) c += p;
    c /= double(x.size());
    const auto p = sim.Pressures();
    for (std::size_t i = 0; i < x.size(); ++i)
      if (Norm(x[i] - c) < r.radius - 2 * kDp) pressure += p[i], ++pressure_count;
  }
  r.sigma_laplace = pressure / double(pressure_count) * r.radius / 2;
  const double omega_laplace = std::sqrt(8 * r.sigma_laplace / (kRho * std::pow(r.radius, 3)));
  const double period_laplace = 2 * kPi / omega_laplace;

  // l = 2 kick, v = A (−x, −y, 2z): surface displacement amplitude 2AR/ω = 5 % of R at ω_Laplace.
  const double A = 0.05 * omega_laplace / 2;
  const auto x0 = sim.Positions();
  Vec3d c{};
  for (const auto& p : x0) c += p;
  c /= double(x0.size());
  std::vector<Vec3d> v(x0.size());
  for (std::size_t i = 0; i < x0.size(); ++i) {
    const Vec3d d = x0[i] - c;
    v[i] = {-A * d.x, -A * d.y, 2 * A * d.z};
  }
  sim.SetFluidState(x0, v);
  const double t0 = sim.time();

  // Zero crossings of s(t) (linear interpolation) and the extremes between them; four crossings
  // span two periods.
  std::vector<double> crossings, extremes;
  double previous = Deformation(x0), t_previous = t0, extreme = 0;
  while (crossings.size() < 4 && sim.time() < t0 + 3 * period_laplace) {
    sim.Step(sim.NextTimeStep(1e30));
    const double s = Deformation(sim.Positions());
    extreme = std::max(extreme, std::fabs(s));
    r.largest = std::max(r.largest, std::fabs(s) / (r.radius * r.radius));
    r.last = s / (r.radius * r.radius);
    if ((previous > 0) != (s > 0) && sim.time() - t0 > 0.1 * period_laplace) {
      crossings.push_back(t_previous + (sim.time() - t_previous) * previous / (previous - s));
      extremes.push_back(extreme);
      extreme = 0;
    }
    previous = s, t_previous = sim.time();
  }
  r.crossings = int(crossings.size());
  r.steps = sim.step_count();
  r.seconds = watch.seconds();
  if (crossings.size() < 4) return r;
  // Damped period: least-squares slope of crossing time against its index (half periods). The
  // decay rate γ comes from the extremes' ratio; the undamped ω0² = ω_d² + γ² is Rayleigh's ω.
  std::vector<double> k, t;
  for (std::size_t i = 0; i < crossings.size(); ++i) k.push_back(double(i)), t.push_back(crossings[i]);
  const double half = FitLine(k, t).slope;
  r.damping = std::log(extremes[1] / extremes[3]) / (2 * half);
  const double omega_d = kPi / half, omega = std::sqrt(omega_d * omega_d + r.damping * r.damping);
  r.period = 2 * kPi / omega;
  r.sigma = omega * omega * kRho * std::pow(r.radius, 3) / 8;
  return r;
}

int Run(const Options& o) {
  const double kappa = 0.02;  // N, the paper's and the scene's default (spec §12)
  const std::vector<int> radii = o.full ? std::vector<int>{6, 9, 13} : std::vector<int>{4, 6, 8};
  std::printf("d_p = h = %.3g m, kappa = %.3g N, rho0 = %.0f kg/m^3; modules: surface_tension, viscosity with beta0 = %.2g "
              "(nu_eff = %.2g m^2/s); no gravity; kappa/(2h) = %.3g N/m\n", kDp, kappa, kRho, kBeta0, kBeta0 * 10 * kDp / 10,
              kappa / (2 * kDp));
  std::printf("\n  R/h   R (m)    particles  period (s)  damping (1/s)  sigma_eff (N/m)  Laplace sigma (N/m)  sigma_eff/(kappa/2h)  steps  wall (s)\n");
  std::vector<double> log_r, log_p;
  bool measured = true;
  for (int n : radii) {
    const Result r = Oscillate(n, kappa);
    std::printf("  %4.2f  %.4f  %9lld  %10.4f  %13.3f  %15.4f  %19.4f  %20.3f  %5lld  %8.1f\n", r.radius / kDp, r.radius,
                (long long)r.particles, r.period, r.damping, r.sigma, r.sigma_laplace, r.sigma / (kappa / (2 * kDp)),
                (long long)r.steps, r.seconds);
    if (r.crossings < 4) {
      std::printf("        no oscillation: %d zero crossings in 3 Laplace periods; the deformation s/R^2 peaked at %.4f "
                  "and ended at %+.4f\n", r.crossings, r.largest, r.last);
      measured = false;
    }
    log_r.push_back(std::log(r.radius));
    log_p.push_back(std::log(r.period));
  }
  bool ok = Check(measured, "two periods measured for every radius");
  if (!measured) return 1;
  const double exponent = FitLine(log_r, log_p).slope;
  std::printf("\nfitted period ~ R^%.3f (Rayleigh: R^1.5)\n", exponent);
  // The interface is about 2h thick whatever R is, so the effective radius and curvature carry
  // an O(h/R) error that bends the fitted exponent at small R/h: 0.15 for R = 4..8 h (fast),
  // 0.1 for R = 6..13 h (full).
  const double tol = o.full ? 0.10 : 0.15;
  ok &= Check(std::fabs(exponent - 1.5) <= tol, fmt::format("|exponent - 1.5| = {:.3f} <= {:.2f}", std::fabs(exponent - 1.5), tol));
  return ok ? 0 : 1;
}

}  // namespace
}  // namespace rime::validation

int main(int argc, char** argv) {
  using namespace rime::validation;
  const Options o = ParseOptions(argc, argv, "usage: rime_validation_droplet [--full]");
  PrintRunInfo("oscillating droplet vs Rayleigh (l = 2)", o);
  return Run(o);
}
