#include <gtest/gtest.h>

#include "rime/core/error.h"
#include "rime/io/scene.h"

namespace rime::io {
namespace {

std::string ErrorOf(const std::string& text) {
  try {
    ParseScene(text, "test.toml");
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "accepted:\n" << text;
  return {};
}

TEST(Scene, DefaultsAndValues) {
  const Scene s = ParseScene(R"(
[scene]
fps = 30
end_time = 1.5
[water]
spacing = 0.01
[sim]
modules = ["gravity", "viscosity"]
omega = 0.6
[viscosity]
beta0 = 0.2
[[solid]]
name = "ground"
shape = "plane"
size = [2, 2, 1]
[[solid]]
shape = "sphere"
radius = 0.2
scale = 2
[[water_block]]
min = [0, 0, 0.5]
max = [0.1, 0.1, 0.6]
velocity = [0, 0, -1]
)",
                             "dir/test.toml");
  EXPECT_EQ(s.info.fps, 30);
  EXPECT_EQ(s.FrameCount(), 45);
  EXPECT_EQ(s.fluid.spacing, 0.01);
  EXPECT_DOUBLE_EQ(s.fluid.particle_mass(), 1e-3);
  EXPECT_TRUE(s.Enabled("viscosity"));
  EXPECT_FALSE(s.Enabled("freezing"));
  EXPECT_EQ(s.viscosity.beta0, 0.2);
  EXPECT_EQ(s.viscosity.beta1, 10);
  EXPECT_EQ(s.solver.omega, 0.6);
  EXPECT_EQ(s.solver.eta, 0.001);
  ASSERT_EQ(s.solids.size(), 2u);
  EXPECT_EQ(s.solids[1].name, "solid1");
  EXPECT_EQ(s.solids[1].transform.scale, Vec3d(2, 2, 2));
  EXPECT_EQ(s.fluid_blocks[0].velocity, Vec3d(0, 0, -1));
  EXPECT_EQ(s.Resolve("mesh.obj"), std::filesystem::path("dir/mesh.obj"));
}

TEST(Scene, RejectsUnknownModuleWithFileAndLine) {
  const std::string e = ErrorOf("[sim]\nmodules = [\"gravity\", \"vorticity\"]\n");
  EXPECT_NE(e.find("unknown name 'vorticity'"), std::string::npos) << e;
  EXPECT_NE(e.find("test.toml:2"), std::string::npos) << e;
  EXPECT_NE(e.find("sim.modules"), std::string::npos) << e;
}

TEST(Scene, FormerSectionNamesAreRefusedNamingTheCurrentOne) {
  for (const auto& [former, current] : {std::pair<std::string, std::string>{"simulation", "sim"}, {"cleanup", "clean"}}) {
    try {
      ParseScene("[scene]\nfps = 24\n[" + former + "]\n", "test.toml");
      ADD_FAILURE() << "[" << former << "] accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kBadInput) << e.what();
      EXPECT_NE(std::string(e.what()).find("[" + former + "] is now called [" + current + "]"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("test.toml:3"), std::string::npos) << e.what();
    }
  }
}

TEST(Scene, RejectsNegativeSpacingWithFileAndLine) {
  const std::string e = ErrorOf("[scene]\nfps = 24\n[water]\nspacing = -0.01\n");
  EXPECT_NE(e.find("test.toml:4"), std::string::npos) << e;
  EXPECT_NE(e.find("water.spacing"), std::string::npos) << e;
  EXPECT_NE(e.find("out of range"), std::string::npos) << e;
  const std::string r = ErrorOf("[[solid]]\nshape = \"sphere\"\nradius = -1\n");
  EXPECT_NE(r.find("test.toml:3"), std::string::npos) << r;
  EXPECT_NE(r.find("solid[0].radius"), std::string::npos) << r;
}

TEST(Scene, RejectsMisspelledKeyWithFileAndLine) {
  const std::string e = ErrorOf("[water]\nspaceing = 0.01\n");
  EXPECT_NE(e.find("unknown key 'spaceing'"), std::string::npos) << e;
  EXPECT_NE(e.find("test.toml:2"), std::string::npos) << e;
  const std::string top = ErrorOf("[watre]\nspacing = 0.01\n");
  EXPECT_NE(top.find("unknown key 'watre'"), std::string::npos) << top;
}

TEST(Scene, OtherChecks) {
  EXPECT_NE(ErrorOf("[viscosity]\nbeta0 = 0.1\n").find("not enabled"), std::string::npos);
  EXPECT_NE(ErrorOf("[water]\nspacing = \"small\"\n").find("expected a number"), std::string::npos);
  EXPECT_NE(ErrorOf("[water]\nspacing = nan\n").find("out of range"), std::string::npos);
  EXPECT_NE(ErrorOf("[sim]\nomega = 0.5\nomega = 0.6\n").find("syntax"), std::string::npos);
  EXPECT_NE(ErrorOf("[[solid]]\nshape = \"mesh\"\n").find("needs a mesh"), std::string::npos);
  EXPECT_NE(ErrorOf("[[water_block]]\nmin = [0,0,0]\nmax = [1,1,-1]\n").find("max must exceed"), std::string::npos);
  EXPECT_NE(ErrorOf("[[solid]]\nname = \"a\"\n[[solid]]\nname = \"a\"\n").find("two solids"), std::string::npos);
}

TEST(Scene, QualityPresetsSetDefaultsAndExplicitValuesWin) {
  const Scene preview = ParseScene("[scene]\nquality = \"preview\"\n", "q.toml");
  EXPECT_EQ(preview.solver.eta, 0.01);
  EXPECT_EQ(preview.solver.cfl, 0.6);
  const Scene reference = ParseScene("[scene]\nquality = \"reference\"\n[sim]\neta = 0.0005\n", "q.toml");
  EXPECT_EQ(reference.solver.eta, 0.0005) << "an explicit value overrides the preset";
  EXPECT_EQ(reference.solver.cfl, 0.2);
  EXPECT_EQ(reference.fluid.precision, Precision::kDouble);
  const Scene plain = ParseScene("", "q.toml");
  EXPECT_EQ(plain.solver.eta, 0.001);
  EXPECT_EQ(plain.fluid.precision, Precision::kFloat);
}

TEST(Scene, Im2013MethodPresetSetsTheBaselineAndExplicitValuesWin) {
  const Scene plain = ParseScene("", "m.toml");
  EXPECT_EQ(plain.info.method, Method::kRime);
  EXPECT_EQ(plain.freezing.growth, Growth::kAnisotropic);
  EXPECT_EQ(plain.surface_tension.model, SurfaceTensionModel::kHe2014);
  EXPECT_GT(plain.viscosity.wall_beta0, 0);
  const Scene im = ParseScene("[scene]\nmethod = \"im2013\"\n", "m.toml");
  EXPECT_EQ(im.freezing.growth, Growth::kIsotropic);
  EXPECT_EQ(im.surface_tension.model, SurfaceTensionModel::kAkinci2013);
  EXPECT_EQ(im.viscosity.wall_beta0, 0);
  const Scene sticky =
      ParseScene("[scene]\nmethod = \"im2013\"\n[sim]\nmodules = [\"gravity\", \"viscosity\"]\n[viscosity]\nwall_beta0 = 0.5\n", "m.toml");
  EXPECT_EQ(sticky.viscosity.wall_beta0, 0.5) << "an explicit value overrides the preset";
  EXPECT_THROW(ParseScene("[scene]\nmethod = \"im2014\"\n", "m.toml"), rime::Error);
}

// The closed-form counts that size limits and memory estimates use are the lattices the solver
// seeds, point for point.
TEST(Scene, ParticleCountsMatchTheSeededLattices) {
  const double dp = 0.01;
  for (const Vec3d& extent : {Vec3d{0.3, 0.3, 0.24}, Vec3d{0.255, 0.1, 0.049}, Vec3d{0.01, 0.02, 0.005}}) {
    FluidBlock box{.shape = BlockShape::kBox, .min = {0.1, -0.2, 0.3}, .max = Vec3d{0.1, -0.2, 0.3} + extent};
    double points = 0;
    box.ForEachLatticePoint(dp, [&](const Vec3d&) { ++points; });
    EXPECT_EQ(box.Particles(dp), points) << extent.x << " x " << extent.y << " x " << extent.z;
  }
  for (double radius : {0.005, 0.01, 0.0499, 0.05, 0.137}) {
    FluidBlock sphere{.shape = BlockShape::kSphere, .center = {0.3, 0.1, -0.2}, .radius = radius};
    double points = 0;
    sphere.ForEachLatticePoint(dp, [&](const Vec3d&) { ++points; });
    EXPECT_EQ(sphere.Particles(dp), points) << "sphere of radius " << radius;
    Emitter disc{.shape = EmitterShape::kDisc, .radius = radius, .speed = dp, .stop = 3};  // one layer per second
    double layer = 0;
    disc.ForEachLayerPoint(dp, [&](double, double) { ++layer; });
    EXPECT_EQ(disc.EmittedParticles(2.5, dp), 2 * layer) << "disc of radius " << radius;
  }
  Emitter nozzle{.shape = EmitterShape::kRectangle, .width = 0.12, .height = 0.02, .speed = 0.4, .stop = 1.5};
  double layer = 0;
  nozzle.ForEachLayerPoint(dp, [&](double, double) { ++layer; });
  EXPECT_EQ(layer, 13 * 3);
  EXPECT_EQ(nozzle.EmittedParticles(3.0, dp), 60 * layer);
}

}  // namespace
}  // namespace rime::io
