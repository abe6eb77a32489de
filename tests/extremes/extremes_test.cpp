// Stability at the extremes: every case ends either in a stable result (finite state,
// bounded density error, no particle through a wall) or in a clear refusal (rime::Error of the
// documented kind, naming the cause). The empty scene, a single particle and coincident particles
// are covered in tests/validation/free_fall_test.cpp.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <optional>
#include <set>
#include <string>

#include "rime/boundary/object.h"
#include "rime/core/error.h"
#include "rime/exec/device.h"
#include "rime/sph/simulation.h"
#include "rime/test/sph_scenes.h"

namespace rime {
namespace {

constexpr double kG = 9.81;

// What a run went through, step by step.
struct RunSummary {
  int steps = 0, unconverged = 0;
  double max_average_error = 0;  // relative, worst step
  double max_error = 0;          // relative, worst particle of the worst step
  double max_speed = 0;
  std::optional<Error> error;  // the refusal or divergence that stopped the run
};

// Steps with the scene's Δt rule until t_end (or until the solver throws), calling observe(sim) after
// every step.
template <class T, class F>
RunSummary Advance(sph::Simulation<T>& sim, double t_end, F&& observe) {
  RunSummary s;
  try {
    while (sim.time() < t_end - 1e-12) {
      const sph::StepStats st = sim.Step(sim.NextTimeStep(t_end));
      ++s.steps;
      s.unconverged += !st.converged;
      s.max_average_error = std::max(s.max_average_error, st.average_density_error);
      s.max_error = std::max(s.max_error, st.max_density_error);
      s.max_speed = std::max(s.max_speed, st.max_speed);
      observe(sim);
    }
  } catch (const Error& e) {
    s.error = e;
  }
  return s;
}
template <class T>
RunSummary Advance(sph::Simulation<T>& sim, double t_end) {
  return Advance(sim, t_end, [](const sph::Simulation<T>&) {});
}

std::string Describe(const RunSummary& s) {
  char line[256];
  std::snprintf(line, sizeof line,
                "%d steps (%d unconverged), density error: worst step average %.3g%%, worst particle %.3g%%, max speed %.3g m/s", s.steps,
                s.unconverged, 100 * s.max_average_error, 100 * s.max_error, s.max_speed);
  return line;
}

template <class T>
bool AllFinite(const sph::Simulation<T>& sim) {
  for (const auto& p : sim.Positions())
    if (!IsFinite(p)) return false;
  for (const auto& v : sim.Velocities())
    if (!IsFinite(v)) return false;
  return true;
}

// Specific mechanical energy Σ (½‖v‖² + g z), J/kg summed over particles.
template <class T>
double Energy(const sph::Simulation<T>& sim) {
  const auto x = sim.Positions();
  const auto v = sim.Velocities();
  double e = 0;
  for (std::size_t i = 0; i < x.size(); ++i) e += 0.5 * double(Dot(v[i], v[i])) + kG * double(x[i].z);
  return e;
}

// Stable means: no error, finite state, average density error within 5 η = 0.5 % on every step
// and no particle more than 5 % compressed (a splash peak; divergence is 5 % on the average).
void ExpectStable(const RunSummary& s, bool finite) {
  EXPECT_FALSE(s.error.has_value()) << s.error->what();
  EXPECT_TRUE(finite) << "NaN or infinite position/velocity";
  EXPECT_LE(s.max_average_error, 0.005) << Describe(s);
  EXPECT_LE(s.max_error, 0.05) << Describe(s);
}

io::ParticleFrame Procedural(const io::SolidObject& solid, double dp) {
  boundary::BoundarySettings settings;
  settings.particle_spacing = dp;
  return boundary::ToParticleFrame(boundary::BuildBoundaryObject(solid, 0, {}, settings));
}

// ------------------------------------------------------------------------------------------------
// Impacts on a thin plate: a 10 cm block (6³ particles, d_p = 2 cm) thrown down onto a plate 1 m
// wide and half a spacing thick (two particle layers at d_b = d_p/2), centred at z = 0.

constexpr double kPlateDp = 0.02, kPlateHalf = 0.5, kPlateThickness = 0.01;

io::Scene PlateScene(double speed) {
  io::Scene scene;
  scene.fluid.spacing = kPlateDp;
  scene.modules = {"gravity", "viscosity"};
  io::SolidObject plate;
  plate.name = "plate";
  plate.size = {2 * kPlateHalf, 2 * kPlateHalf, kPlateThickness};
  scene.solids.push_back(plate);
  io::FluidBlock b;
  b.min = {-0.05, -0.05, 0.05};
  b.max = {0.05, 0.05, 0.15};
  b.velocity = {0, 0, -speed};
  scene.fluid_blocks.push_back(b);
  return scene;
}

struct PlateRun {
  RunSummary s;
  std::int64_t initial = 0;
  int through = 0;         // particle-steps found below the plate's top inside its footprint
  double min_z = 1e30;     // lowest particle over the footprint, m
  double mean_vz_end = 0;  // m/s
  double energy_start = 0, energy_end = 0;
  bool finite = true;
};

// Runs until the block has reached the plate and spread for 0.6/speed s.
PlateRun RunPlate(const io::Scene& scene, double speed) {
  sph::Simulation<float> sim(scene, exec::Device::Cpu());
  sim.AddBoundaryObject(Procedural(scene.solids[0], kPlateDp), "plate");
  sim.Initialize();
  PlateRun r;
  r.initial = sim.fluid_count();
  r.energy_start = Energy(sim);
  const double top = kPlateThickness / 2;
  r.s = Advance(sim, (0.15 + 0.6) / speed, [&](const sph::Simulation<float>& s) {
    for (const auto& p : s.Positions()) {
      if (std::fabs(p.x) >= kPlateHalf || std::fabs(p.y) >= kPlateHalf) continue;  // off the plate: may fall freely
      r.min_z = std::min(r.min_z, double(p.z));
      if (p.z < top) ++r.through;
    }
  });
  r.finite = AllFinite(sim);
  r.energy_end = Energy(sim);
  for (const auto& v : sim.Velocities()) r.mean_vz_end += double(v.z) / double(sim.fluid_count());
  EXPECT_EQ(sim.fluid_count() + sim.removed_total(), r.initial) << "particles are neither created nor lost";
  return r;
}

class ExtremesPlateImpact : public ::testing::TestWithParam<double> {};

TEST_P(ExtremesPlateImpact, CflStepStopsTheWaterOnTheNearSide) {
  const double speed = GetParam();
  const PlateRun r = RunPlate(PlateScene(speed), speed);
  std::printf(
      "impact %g m/s: %s; lowest particle over the plate %.3g d_p above its top, %d particle-steps through it, "
      "mean vz at the end %.3g m/s, energy %.4g -> %.4g J/kg\n",
      speed, Describe(r.s).c_str(), (r.min_z - kPlateThickness / 2) / kPlateDp, r.through, r.mean_vz_end, r.energy_start, r.energy_end);
  ExpectStable(r.s, r.finite);
  EXPECT_EQ(r.through, 0) << "particles tunnelled into or through the plate";
  // The run is not vacuous: the water reached the plate (within a spacing of it) and was stopped.
  EXPECT_LT(r.min_z, kPlateThickness / 2 + kPlateDp);
  EXPECT_GT(r.mean_vz_end, -0.2 * speed);
  EXPECT_LE(r.energy_end, r.energy_start) << "an impact dissipates energy; it must not create any";
}

INSTANTIATE_TEST_SUITE_P(Speeds, ExtremesPlateImpact, ::testing::Values(10.0, 30.0, 50.0),
                         [](const auto& info) { return std::to_string(int(info.param)) + "mps"; });

// ------------------------------------------------------------------------------------------------
// Fixed Δt at and beyond the CFL limit, on the 50 m/s impact. λ = v Δt / d_p.

io::Scene FixedStepPlateScene(double speed, double lambda) {
  io::Scene scene = PlateScene(speed);
  scene.solver.time_step = rime::io::TimeStep::kFixed;
  scene.solver.dt = lambda * kPlateDp / speed;
  return scene;
}

TEST(ExtremesFixedStep, AtTheCflLimitTheWaterStaysOnThePlate) {
  const double speed = 50;
  const PlateRun r = RunPlate(FixedStepPlateScene(speed, 0.4), speed);
  std::printf("fixed dt at lambda 0.4, 50 m/s: %s; lowest particle %.3g d_p above the plate\n", Describe(r.s).c_str(),
              (r.min_z - kPlateThickness / 2) / kPlateDp);
  ExpectStable(r.s, r.finite);
  EXPECT_EQ(r.through, 0);
  EXPECT_LT(r.min_z, kPlateThickness / 2 + kPlateDp);
}

// λ = 1: particles cross one spacing per step. Either the run stays on the near side or it stops
// with the divergence diagnosis.
TEST(ExtremesFixedStep, BeyondTheCflLimitIsStableOrDiagnosed) {
  const double speed = 50;
  const PlateRun r = RunPlate(FixedStepPlateScene(speed, 1.0), speed);
  std::printf("fixed dt at lambda 1, 50 m/s: %s; %d particle-steps through the plate, lowest %.3g m; %s\n", Describe(r.s).c_str(),
              r.through, r.min_z, r.s.error ? r.s.error->what() : "no error");
  if (r.s.error) {
    EXPECT_EQ(r.s.error->code(), ExitCode::kDiverged);
    EXPECT_NE(std::string(r.s.error->what()).find("worst particle id"), std::string::npos) << r.s.error->what();
  } else {
    EXPECT_EQ(r.through, 0) << "particles tunnelled through the plate without any diagnosis";
  }
}

// The scene accepts cfl up to 2 for the adaptive rule: a value beyond the stable limit must be
// refused by the scene reader, diagnosed, or stable.
TEST(ExtremesAdaptiveStep, CflOfOneIsRefusedDiagnosedOrStable) {
  io::Scene scene = PlateScene(50);
  try {
    scene.solver.cfl = io::ParseScene("[sim]\ncfl = 1.0\n", "cfl.toml").solver.cfl;
  } catch (const Error& e) {
    std::printf("cfl = 1: %s\n", e.what());
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("cfl"), std::string::npos) << e.what();
    return;
  }
  const PlateRun r = RunPlate(scene, 50);
  std::printf("adaptive cfl 1, 50 m/s: %s; %d particle-steps through the plate, lowest %.3g m; %s\n", Describe(r.s).c_str(), r.through,
              r.min_z, r.s.error ? r.s.error->what() : "no error");
  if (r.s.error) {
    EXPECT_EQ(r.s.error->code(), ExitCode::kDiverged) << r.s.error->what();
  } else {
    EXPECT_EQ(r.through, 0) << "particles tunnelled through the plate without any diagnosis";
  }
}

// λ = 2.5: refused on the first step with the divergence diagnosis (step, cause, worst particle);
// rime-sim prefixes the frame (tools/sim/tests).
TEST(ExtremesFixedStep, FarBeyondTheCflLimitIsDiagnosedOnTheFirstStep) {
  const double speed = 50;
  const PlateRun r = RunPlate(FixedStepPlateScene(speed, 2.5), speed);
  ASSERT_TRUE(r.s.error.has_value()) << "no diagnosis; " << Describe(r.s);
  std::printf("fixed dt at lambda 2.5: %s\n", r.s.error->what());
  EXPECT_EQ(r.s.error->code(), ExitCode::kDiverged);
  EXPECT_EQ(r.s.steps, 0) << "the very first step must be refused";
  const std::string what = r.s.error->what();
  for (const char* part : {"diverged at step 0", "spacings per step", "time step is too large", "worst particle id"})
    EXPECT_NE(what.find(part), std::string::npos) << "message lacks '" << part << "': " << what;
  EXPECT_TRUE(r.finite);
}

// ------------------------------------------------------------------------------------------------
// A dam break: an n³ block in the corner of a box twice its width (open top, walls 2n d_p high).

struct Dam {
  double dp;
  int n = 8;
  double width() const { return 2 * sph::test::BoxWidth(dp, n); }
  double depth() const { return sph::test::BoxWidth(dp, n); }
  double height() const { return 2 * n * dp; }
  io::Scene Scene(const io::Scene& base, Vec3d offset = {}) const {
    io::Scene scene = base;
    scene.fluid.spacing = dp;
    io::FluidBlock block;
    block.min = offset + Vec3d(1.1 * dp, 1.1 * dp, 1.1 * dp);
    block.max = block.min + Vec3d((n - 1) * dp, (n - 1) * dp, (n - 1) * dp);
    scene.fluid_blocks.push_back(block);
    return scene;
  }
  template <class T>
  std::unique_ptr<sph::Simulation<T>> Make(const io::Scene& base, Vec3d offset = {}) const {
    auto sim = std::make_unique<sph::Simulation<T>>(Scene(base, offset), exec::Device::Cpu());
    io::ParticleFrame box = sph::test::BoxBoundary(dp, width(), depth(), height());
    auto p = box.GetPositions<double>();
    for (auto& q : p) q += offset;
    box.SetPositions(p);
    sim->AddBoundaryObject(box, "box");
    sim->Initialize();
    return sim;
  }
  // Particles beyond a wall sheet below the top of the walls (above it, water may spill out).
  template <class T>
  int OutsideTheWalls(const sph::Simulation<T>& sim) const {
    int count = 0;
    for (const auto& p : sim.Positions())
      if (p.z < height() && (p.x < 0 || p.y < 0 || p.z < 0 || p.x > width() || p.y > depth())) ++count;
    return count;
  }
};

struct DamRun {
  RunSummary s;
  int outside = 0;                                              // particle-steps beyond a wall
  double energy_start = 0, energy_end = 0, centroid_shift = 0;  // shift in x, m
  bool finite = true;
};

DamRun RunDam(const Dam& dam, const io::Scene& base, double t_end) {
  DamRun r;
  std::unique_ptr<sph::Simulation<float>> sim;
  try {
    sim = dam.Make<float>(base);
  } catch (const Error& e) {  // refused before the first step
    r.s.error = e;
    r.finite = true;
    return r;
  }
  r.energy_start = Energy(*sim);
  const std::int64_t n = sim->fluid_count();
  auto centroid_x = [&] {
    double c = 0;
    for (const auto& p : sim->Positions()) c += double(p.x) / double(sim->fluid_count());
    return c;
  };
  const double c0 = centroid_x();
  r.s = Advance(*sim, t_end, [&](const sph::Simulation<float>& s) { r.outside += dam.OutsideTheWalls(s); });
  r.finite = AllFinite(*sim);
  r.energy_end = Energy(*sim);
  r.centroid_shift = centroid_x() - c0;
  EXPECT_EQ(sim->fluid_count() + sim->removed_total(), n);
  return r;
}

void ExpectStableDam(const DamRun& r, bool energy_must_not_grow = true) {
  ExpectStable(r.s, r.finite);
  EXPECT_EQ(r.outside, 0) << "particle-steps beyond a wall sheet";
  if (energy_must_not_grow) {
    EXPECT_LE(r.energy_end, r.energy_start) << "a dam break only dissipates energy";
  }
}

// Particle spacings at both ends of the range users ask for, over 8 characteristic times √(H/g).
class ExtremesSpacing : public ::testing::TestWithParam<double> {};

TEST_P(ExtremesSpacing, DamBreakIsStable) {
  const Dam dam{GetParam()};
  io::Scene base;
  base.modules = {"gravity", "viscosity"};
  const double t_end = 8 * std::sqrt(dam.n * dam.dp / kG);
  const DamRun r = RunDam(dam, base, t_end);
  std::printf("d_p = %g m, %.3g s: %s; front moved %.3g d_p, energy %.4g -> %.4g J/kg\n", dam.dp, t_end, Describe(r.s).c_str(),
              r.centroid_shift / dam.dp, r.energy_start, r.energy_end);
  ExpectStableDam(r);
  EXPECT_GT(r.centroid_shift, 2 * dam.dp) << "the column collapsed towards the empty half";
}

INSTANTIATE_TEST_SUITE_P(Spacings, ExtremesSpacing, ::testing::Values(0.0005, 0.1), [](const auto& info) {
  return info.param < 0.01 ? std::string("HalfMillimetre") : std::string("TenCentimetres");
});

TEST(ExtremesSpacing, HalfMillimetreWithSurfaceTensionIsStableOrRefusedNamingIt) {
  const Dam dam{0.0005};
  io::Scene base;
  base.modules = {"gravity", "viscosity", "surface_tension"};
  const DamRun r = RunDam(dam, base, 2 * std::sqrt(dam.n * dam.dp / kG));
  std::printf("d_p = 0.5 mm with surface tension: %s; %s\n", Describe(r.s).c_str(), r.s.error ? r.s.error->what() : "no error");
  if (r.s.error && std::string(r.s.error->what()).find("surface_tension") != std::string::npos) return;  // a refusal naming the cause
  ExpectStableDam(r, false);  // surface energy turns into kinetic energy
}

// ------------------------------------------------------------------------------------------------
// Zero and very high viscosity and surface tension, on the 2 cm dam break (8³ particles).

io::Scene WithViscosity(double mu, double beta0, double wall_beta0) {
  io::Scene scene;
  scene.modules = {"gravity", "viscosity"};
  scene.viscosity.mu = mu;
  scene.viscosity.beta0 = beta0;
  scene.viscosity.wall_beta0 = wall_beta0;
  return scene;
}

io::Scene WithSurfaceTension(double kappa) {
  io::Scene scene;
  scene.modules = {"gravity", "viscosity", "surface_tension"};
  scene.surface_tension.kappa = scene.surface_tension.kappa_boundary = kappa;
  return scene;
}

TEST(ExtremesViscosity, ZeroIsStable) {
  const DamRun r = RunDam(Dam{0.02}, WithViscosity(0, 0, 0), 0.5);
  std::printf("viscosity 0: %s; energy %.4g -> %.4g J/kg\n", Describe(r.s).c_str(), r.energy_start, r.energy_end);
  ExpectStableDam(r);
}

// The sticky fluid term (β0 = 10, 100× the default) is limited by the Δt rule (Δt = 0.2 ms).
TEST(ExtremesViscosity, HighMonaghanStickinessIsStable) {
  const DamRun r = RunDam(Dam{0.02}, WithViscosity(1e-3, 10, 1), 0.15);
  std::printf("viscosity beta0 10: %s; energy %.4g -> %.4g J/kg\n", Describe(r.s).c_str(), r.energy_start, r.energy_end);
  ExpectStableDam(r);
}

// The wall term is implicit: β0b = 1000 is stable at the ordinary step.
TEST(ExtremesViscosity, VeryHighWallStickinessIsStable) {
  const DamRun r = RunDam(Dam{0.02}, WithViscosity(1e-3, 0.1, 1000), 0.5);
  std::printf("viscosity wall_beta0 1000: %s; energy %.4g -> %.4g J/kg\n", Describe(r.s).c_str(), r.energy_start, r.energy_end);
  ExpectStableDam(r);
}

TEST(ExtremesViscosity, VeryHighMorrisViscosityIsStable) {
  const DamRun r = RunDam(Dam{0.02}, WithViscosity(100, 0.1, 1), 0.2);
  std::printf("viscosity mu 100: %s; energy %.4g -> %.4g J/kg\n", Describe(r.s).c_str(), r.energy_start, r.energy_end);
  ExpectStableDam(r);
}

// β0 = 1000: the viscous limit (2 µs) is below dt_min (10 µs). Stable (with a smaller step) or
// refused naming the viscosity, never clamped to an unstable step.
TEST(ExtremesViscosity, StickinessBeyondTheMinimumStepIsRefusedNamingIt) {
  const DamRun r = RunDam(Dam{0.02}, WithViscosity(1e-3, 1000, 1), 0.05);
  std::printf("viscosity beta0 1000: %s; %s\n", Describe(r.s).c_str(), r.s.error ? r.s.error->what() : "no error");
  if (r.s.error) {
    EXPECT_EQ(r.s.error->code(), ExitCode::kBadInput) << r.s.error->what();
    EXPECT_NE(std::string(r.s.error->what()).find("beta0"), std::string::npos) << r.s.error->what();
  } else {
    ExpectStableDam(r);
  }
}

// p_atm ten times the paper's at d_p = 1 cm pushes a free-surface particle at ~5000 m/s²: the step
// must follow that push, not only the flow's speed, or a surface particle jumps a spacing per step.
TEST(ExtremesAirPressure, TenTimesThePapersIsStable) {
  io::Scene base;
  base.modules = {"gravity", "viscosity", "air_pressure"};
  base.air_pressure.p_atm = 50000;
  const DamRun r = RunDam(Dam{0.01}, base, 0.2);
  std::printf("air pressure 50 kPa: %s\n", Describe(r.s).c_str());
  ExpectStableDam(r, false);  // the push does work on the surface
}

TEST(ExtremesSurfaceTension, ZeroIsStable) {
  const DamRun r = RunDam(Dam{0.02}, WithSurfaceTension(0), 0.5);
  std::printf("surface tension 0: %s\n", Describe(r.s).c_str());
  ExpectStableDam(r);
}

// κ = 1 N (50× the default): cohesion pulls the front back, the step shrinks, nothing leaks.
TEST(ExtremesSurfaceTension, HighIsStable) {
  const DamRun r = RunDam(Dam{0.02}, WithSurfaceTension(1), 0.5);
  std::printf("surface tension 1: %s\n", Describe(r.s).c_str());
  ExpectStableDam(r, false);
}

TEST(ExtremesSurfaceTension, VeryHighIsStableOrRefused) {
  const DamRun r = RunDam(Dam{0.02}, WithSurfaceTension(100), 0.5);
  std::printf("surface tension 100: %s; %d particle-steps beyond a wall; %s\n", Describe(r.s).c_str(), r.outside,
              r.s.error ? r.s.error->what() : "no error");
  if (r.s.error) {
    EXPECT_NE(std::string(r.s.error->what()).find("surface_tension"), std::string::npos) << r.s.error->what();
    return;
  }
  ExpectStableDam(r, false);
}

// ------------------------------------------------------------------------------------------------
// The dam break 10 km from the origin against the same scene at the origin (6³ particles, 0.3 s).

struct Comparison {
  double rms_position = 0, max_position = 0, rms_velocity = 0, rms_speed = 0;  // m, m, m/s, m/s
};

template <class T>
std::map<std::int64_t, std::pair<Vec3d, Vec3d>> DamState(double offset_x, std::optional<Error>* error) {
  const Dam dam{0.02, 6};
  io::Scene base;
  base.modules = {"gravity", "viscosity"};
  const Vec3d offset(offset_x, 0, 0);
  std::map<std::int64_t, std::pair<Vec3d, Vec3d>> state;
  try {
    auto sim = dam.Make<T>(base, offset);
    const RunSummary s = Advance(*sim, 0.3);
    EXPECT_FALSE(s.error.has_value()) << s.error->what();
    const auto x = sim->Positions();
    const auto v = sim->Velocities();
    const auto id = sim->Ids();
    for (std::size_t i = 0; i < x.size(); ++i) state[id[i]] = {Vec3d(x[i]) - offset, Vec3d(v[i])};
  } catch (const Error& e) {
    *error = e;
  }
  return state;
}

Comparison Compare(const std::map<std::int64_t, std::pair<Vec3d, Vec3d>>& a, const std::map<std::int64_t, std::pair<Vec3d, Vec3d>>& b) {
  Comparison c;
  EXPECT_EQ(a.size(), b.size());
  for (const auto& [id, s] : a) {
    const auto& o = b.at(id);
    const double dx = Norm(s.first - o.first), dv = Norm(s.second - o.second);
    c.rms_position += dx * dx;
    c.max_position = std::max(c.max_position, dx);
    c.rms_velocity += dv * dv;
    c.rms_speed += Dot(s.second, s.second);
  }
  c.rms_position = std::sqrt(c.rms_position / a.size());
  c.rms_velocity = std::sqrt(c.rms_velocity / a.size());
  c.rms_speed = std::sqrt(c.rms_speed / a.size());
  return c;
}

TEST(ExtremesFarFromOrigin, DoubleMatchesTheSceneAtTheOrigin) {
  std::optional<Error> error;
  const auto here = DamState<double>(0, &error), far = DamState<double>(1e4, &error);
  ASSERT_FALSE(error.has_value()) << error->what();
  const Comparison c = Compare(here, far);
  std::printf("double, 10 km vs origin after 0.3 s: positions rms %.3g d_p (max %.3g), velocities rms %.3g of the rms speed\n",
              c.rms_position / 0.02, c.max_position / 0.02, c.rms_velocity / c.rms_speed);
  EXPECT_LT(c.max_position, 1e-6 * 0.02);
  EXPECT_LT(c.rms_velocity, 1e-6 * c.rms_speed);
}

// Float resolves 10 km to 2^-10 m ≈ 0.05 d_p. Either the solver works relative to the scene (then
// only the output rounding, ≤ 0.025 d_p, separates the runs) or it refuses the scene naming the
// precision.
TEST(ExtremesFarFromOrigin, FloatMatchesTheSceneAtTheOriginOrIsRefused) {
  std::optional<Error> error;
  const auto here = DamState<float>(0, &error);
  ASSERT_FALSE(error.has_value()) << error->what();
  const auto far = DamState<float>(1e4, &error);
  if (error) {
    EXPECT_EQ(error->code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(error->what()).find("precision"), std::string::npos) << error->what();
    return;
  }
  const Comparison c = Compare(here, far);
  std::printf("float, 10 km vs origin after 0.3 s: positions rms %.3g d_p (max %.3g), velocities rms %.3g of the rms speed\n",
              c.rms_position / 0.02, c.max_position / 0.02, c.rms_velocity / c.rms_speed);
  EXPECT_LT(c.rms_position, 0.05 * 0.02);
  EXPECT_LT(c.rms_velocity, 0.01 * c.rms_speed);
}

// ------------------------------------------------------------------------------------------------
// Everything frozen: thresholds 0 freeze every particle that touches a wet solid or ice, so the
// block turns to ice layer by layer from the floor up.

TEST(ExtremesFreezing, EverythingFreezesWithConsistentCountsAndNoNaN) {
  const double dp = 0.02;
  io::Scene scene;
  scene.fluid.spacing = dp;
  scene.modules = {"gravity", "viscosity", "freezing"};
  io::FluidBlock b;
  b.min = {0.3, 0.3, 1.1 * dp};
  b.max = {0.42, 0.42, 0.15};
  scene.fluid_blocks.push_back(b);
  scene.freezing.glaze_threshold = 0;
  scene.freezing.icicle_threshold = 0;
  // Growth against the flow, mapped: every wetted neighbour then has some energy. With the default
  // (with the flow, clamped) water the flow points away from keeps zero energy and stays liquid.
  scene.freezing.growth_sign = 1;
  scene.freezing.fr_mode = rime::io::FrMode::kMap;
  sph::Simulation<float> sim(scene, exec::Device::Cpu());
  sim.AddBoundaryObject(sph::test::BoxBoundary(dp, 0.72, 0.72, 0.2), "box");
  sim.Initialize();
  const std::int64_t water = sim.fluid_count(), solid = sim.boundary_count();
  std::map<std::int64_t, Vec3f> ice;
  double all_frozen_at = -1;
  for (int frame = 1; frame <= 8; ++frame) {  // 1/3 s
    const RunSummary s = Advance(sim, frame / 24.0);
    ASSERT_FALSE(s.error.has_value()) << s.error->what();
    ASSERT_TRUE(AllFinite(sim));
    EXPECT_EQ(sim.fluid_count() + sim.ice_count() + sim.removed_total(), water) << "water is conserved as water or ice";
    EXPECT_EQ(sim.boundary_count(), solid + sim.ice_count());
    const io::ParticleFrame f = sim.Snapshot(frame);
    const auto x = f.GetPositions<float>();
    const auto& phase = f.Get<std::uint8_t>("phase");
    const auto& id = f.Get<std::int64_t>("id");
    const auto& volume = f.Get<float>("volume");
    std::int64_t ice_now = 0;
    for (std::size_t i = 0; i < x.size(); ++i) {
      if (phase[i] == 0) continue;
      ASSERT_TRUE(IsFinite(x[i]));
      ASSERT_TRUE(std::isfinite(volume[i]) && volume[i] > 0) << "boundary volume " << volume[i];
      if (phase[i] != 2) continue;
      ++ice_now;
      const auto known = ice.find(id[i]);
      if (known == ice.end()) ice[id[i]] = x[i];
      else EXPECT_EQ(known->second, x[i]) << "ice particle " << id[i] << " moved";
    }
    EXPECT_EQ(ice_now, sim.ice_count());
    if (all_frozen_at < 0 && sim.fluid_count() == 0) all_frozen_at = sim.time();
  }
  std::printf("everything frozen: %lld water particles became %lld ice by t = %.3f s; %lld steps, still stepping at t = %.3f s\n",
              (long long)water, (long long)sim.ice_count(), all_frozen_at, (long long)sim.step_count(), sim.time());
  EXPECT_EQ(sim.fluid_count(), 0);
  EXPECT_EQ(sim.ice_count(), water);
  EXPECT_GT(all_frozen_at, 0);
  EXPECT_LT(all_frozen_at, 0.25);
}

// ------------------------------------------------------------------------------------------------
// Water placed entirely inside a closed solid (a procedural box of single-layer walls).

struct InsideCube {
  double dp = 0.02, size;
  io::Scene scene;
  explicit InsideCube(double s) : size(s) {
    scene.fluid.spacing = dp;
    scene.modules = {"gravity", "viscosity"};
    io::SolidObject cube;
    cube.name = "cube";
    cube.size = {size, size, size};
    cube.transform.translate = {0, 0, 0.5};
    scene.solids.push_back(cube);
  }
  bool Inside(const Vec3f& p) const { return std::fabs(p.x) < size / 2 && std::fabs(p.y) < size / 2 && std::fabs(p.z - 0.5) < size / 2; }
  void AddFillingBlock() {
    io::FluidBlock b;
    b.min = {-size / 2, -size / 2, 0.5 - size / 2};
    b.max = {size / 2, size / 2, 0.5 + size / 2};
    scene.fluid_blocks.push_back(b);
  }
  std::unique_ptr<sph::Simulation<float>> Make() const {
    auto sim = std::make_unique<sph::Simulation<float>>(scene, exec::Device::Cpu());
    sim->AddBoundaryObject(Procedural(scene.solids[0], dp), "cube");
    return sim;
  }
};

// A block within 1.05 d_p of the walls everywhere: every particle is dropped, and the scene is refused.
TEST(ExtremesInsideSolid, BlockAgainstTheWallsIsRefused) {
  InsideCube cube(0.04);
  cube.AddFillingBlock();
  auto sim = cube.Make();
  try {
    sim->Initialize();
    FAIL() << "accepted " << sim->fluid_count() << " water particles inside a solid";
  } catch (const Error& e) {
    std::printf("block inside a 4 cm cube: %s\n", e.what());
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("inside or against a solid"), std::string::npos) << e.what();
  }
}

TEST(ExtremesInsideSolid, BlockFillingALargeSolidIsRemovedOrRefused) {
  InsideCube cube(0.3);
  cube.AddFillingBlock();
  auto sim = cube.Make();
  try {
    sim->Initialize();
  } catch (const Error& e) {
    std::printf("block filling a 30 cm cube: %s\n", e.what());
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    return;
  }
  int inside = 0;
  for (const auto& p : sim->Positions()) inside += cube.Inside(p);
  std::printf("block filling a 30 cm cube: %lld water particles kept, %d of them inside the solid\n", (long long)sim->fluid_count(),
              inside);
  EXPECT_EQ(inside, 0);
}

TEST(ExtremesInsideSolid, EmitterInsideASolidIsRefusedOrItsWaterRemoved) {
  InsideCube cube(0.3);
  io::Emitter e;
  e.center = {0, 0, 0.5};
  e.direction = {1, 0, 0};
  e.radius = 0.05;
  e.speed = 1;
  e.stop = 0.2;
  cube.scene.emitters.push_back(e);
  auto sim = cube.Make();
  try {
    sim->Initialize();
  } catch (const Error& err) {
    std::printf("emitter inside a cube: %s\n", err.what());
    EXPECT_EQ(err.code(), ExitCode::kBadInput);
    return;
  }
  const RunSummary s = Advance(*sim, 0.3);
  ASSERT_FALSE(s.error.has_value()) << s.error->what();
  int inside = 0;
  for (const auto& p : sim->Positions()) inside += cube.Inside(p);
  std::printf("emitter inside a cube: %lld water particles, %d inside the solid\n", (long long)sim->fluid_count(), inside);
  EXPECT_EQ(inside, 0);
}

}  // namespace
}  // namespace rime
