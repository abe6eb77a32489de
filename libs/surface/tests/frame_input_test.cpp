// Reading rime-sim frames for reconstruction: phase selection, stored anisotropy, fallbacks.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>

#include "rime/core/error.h"
#include "rime/surface/frame_input.h"
#include "rime/test/temp_folder.h"

namespace rime::surface {
namespace {

namespace fs = std::filesystem;

io::ParticleFrame MakeFrame(bool with_anisotropy) {
  io::ParticleFrame frame;
  frame.spacing = 0.02;
  frame.frame = 3;
  frame.SetPositions(std::vector<Vec3f>{{0, 0, 0}, {0.02f, 0, 0}, {0.04f, 0, 0}, {1, 1, 1}});
  frame.Set("vx", std::vector<float>{1, 2, 3, 4});
  frame.Set("vy", std::vector<float>{0, 0, 0, 0});
  frame.Set("vz", std::vector<float>{0, 0, 0, 0});
  frame.Set("phase", std::vector<std::uint8_t>{2, 0, 2, 1});
  frame.Set("id", std::vector<std::int64_t>{10, 11, 12, 13});
  if (with_anisotropy)
    for (int c = 0; c < 6; ++c) frame.Set("anisotropy_" + std::to_string(c), std::vector<float>(4, c < 3 ? 2.0f : 0.0f));
  return frame;
}

TEST(FrameInput, SelectsIceWithStoredAnisotropyFromAFile) {
  const rime::test::TempFolder dir("surface_frames");
  const fs::path path = io::FramePath(dir, "particles", 3, "h5part");
  io::WriteParticleFrame(path, MakeFrame(true));
  const io::ParticleFrame frame = io::ReadParticleFrame(path, "particles");
  std::vector<std::string> warnings;
  const ParticleSet ice = SelectPhase(frame, io::Phase::kIce, {}, warnings);
  ASSERT_EQ(ice.size(), 2u);
  EXPECT_NEAR(ice.positions[1].x, 0.04, 1e-7);
  EXPECT_EQ(ice.velocities[1].x, 3.0f);
  ASSERT_EQ(ice.stored_anisotropy.size(), 2u);
  EXPECT_EQ(ice.stored_anisotropy[0][0], 2.0f);
  EXPECT_EQ(ice.spacing, 0.02);
  EXPECT_EQ(ice.smoothing_length, 0.02);
  EXPECT_TRUE(warnings.empty());
  const ParticleSet water = SelectPhase(frame, io::Phase::kFluid, {}, warnings);
  ASSERT_EQ(water.size(), 1u);
  EXPECT_TRUE(water.stored_anisotropy.empty());
}

TEST(FrameInput, MissingAnisotropyWarnsOrFailsUnderStrict) {
  const io::ParticleFrame frame = MakeFrame(false);
  std::vector<std::string> warnings;
  const ParticleSet ice = SelectPhase(frame, io::Phase::kIce, {}, warnings);
  EXPECT_EQ(ice.size(), 2u);
  EXPECT_TRUE(ice.stored_anisotropy.empty());
  ASSERT_EQ(warnings.size(), 1u);
  EXPECT_NE(warnings[0].find("anisotropy"), std::string::npos);
  SelectOptions strict;
  strict.strict = true;
  try {
    SelectPhase(frame, io::Phase::kIce, strict, warnings);
    FAIL() << "expected an error under --strict";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find("anisotropy_0"), std::string::npos);
  }
}

TEST(FrameInput, RejectsBadFrames) {
  std::vector<std::string> warnings;
  io::ParticleFrame no_spacing = MakeFrame(true);
  no_spacing.spacing = 0;
  EXPECT_THROW(SelectPhase(no_spacing, io::Phase::kIce, {}, warnings), Error);
  io::ParticleFrame no_phase = MakeFrame(true);
  no_phase.attributes.erase("phase");
  EXPECT_THROW(SelectPhase(no_phase, io::Phase::kIce, {}, warnings), Error);
  io::ParticleFrame nan = MakeFrame(true);
  nan.Set("x", std::vector<float>{0, 0, NAN, 0});
  EXPECT_THROW(SelectPhase(nan, io::Phase::kIce, {}, warnings), Error);
  io::ParticleFrame smoothing = MakeFrame(true);
  smoothing.numbers["smoothing_length"] = 0.03;
  EXPECT_EQ(SelectPhase(smoothing, io::Phase::kIce, {}, warnings).smoothing_length, 0.03);
}

}  // namespace
}  // namespace rime::surface

#include "rime/io/scene.h"

namespace rime::surface {
namespace {

TEST(SurfaceScene, ReadsTheSurfaceSectionWithRangeChecks) {
  const io::Scene scene = io::ParseScene(R"([surface]
phase = "both"
water_field = "isotropic"
voxel_ratio = 0.25
r_iso = 0.6
lambda = 0.5
smooth = 2
formats = ["ply", "vdb"]
)",
                                         "scene.toml");
  EXPECT_EQ(scene.surface.phase, io::SurfacePhases::kBoth);
  EXPECT_EQ(scene.surface.water_field, io::SurfaceField::kIsotropic);
  EXPECT_EQ(scene.surface.ice_field, io::SurfaceField::kEllipsoids);
  EXPECT_DOUBLE_EQ(scene.surface.voxel_ratio, 0.25);
  EXPECT_DOUBLE_EQ(scene.surface.r_iso, 0.6);
  EXPECT_EQ(scene.surface.smooth, 2);
  EXPECT_EQ(scene.surface.formats, (std::vector<std::string>{"ply", "vdb"}));
  for (const char* bad : {"[surface]\nlambda = 1.5\n", "[surface]\nhalf_band = 2\n", "[surface]\nphase = \"steam\"\n",
                          "[surface]\nformats = [\"stl\"]\n", "[surface]\nvoxel_raito = 0.5\n"}) {
    try {
      io::ParseScene(bad, "scene.toml");
      FAIL() << "accepted: " << bad;
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ExitCode::kBadInput) << bad;
      EXPECT_NE(std::string(e.what()).find("scene.toml"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace rime::surface
