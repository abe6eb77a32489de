// Every scene in examples/ loads with the same loader the stage tools use, and its [bake] table is valid.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include "rime/core/error.h"
#include "rime/io/scene.h"
#include "rime/test/files.h"
#include "scene_document.h"

namespace fs = std::filesystem;

namespace rime::bake {
namespace {

std::vector<fs::path> ExampleScenes() {
  std::vector<fs::path> scenes;
  for (const auto& entry : fs::directory_iterator(RIME_SOURCE_DIR "/examples"))
    if (entry.path().extension() == ".toml") scenes.push_back(entry.path());
  std::sort(scenes.begin(), scenes.end());
  return scenes;
}

TEST(Examples, EverySceneLoads) {
  const auto scenes = ExampleScenes();
  ASSERT_GE(scenes.size(), 6u) << "default, bunny, thrown, rotating, glaze/icicle variants, dam break";
  for (const auto& scene : scenes) {
    SCOPED_TRACE(scene.string());
    try {
      const SceneDocument doc = SceneDocument::Load(scene);
      EXPECT_FALSE(doc.scene().solids.empty());
      EXPECT_TRUE(!doc.scene().fluid_blocks.empty() || !doc.scene().emitters.empty()) << "a scene needs water";
      EXPECT_GT(doc.scene().FrameCount(), 0);
    } catch (const Error& e) {
      ADD_FAILURE() << e.what();
    }
  }
}

TEST(Examples, DefaultSceneIsProceduralAndFreezes) {
  const io::Scene scene = io::LoadScene(RIME_SOURCE_DIR "/examples/default.toml");
  for (const auto& solid : scene.solids) EXPECT_NE(solid.shape, io::SolidShape::kMesh) << solid.name;
  for (const char* module : {"gravity", "viscosity", "surface_tension", "freezing"}) EXPECT_TRUE(scene.Enabled(module)) << module;
  // Small enough to bake in about two minutes on 2 cores: a few thousand particles, a few seconds.
  const double particles = scene.WaterParticles();
  EXPECT_GT(particles, 500);
  EXPECT_LT(particles, 20000);
  EXPECT_LE(scene.info.end_time, 3.0);
}

/// The TOML settings of `text` without comments and blank lines, one per line, trimmed.
std::vector<std::string> Settings(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) {
    line = line.substr(0, line.find('#'));
    const auto first = line.find_first_not_of(" \t"), last = line.find_last_not_of(" \t\r");
    if (first != std::string::npos) lines.push_back(line.substr(first, last - first + 1));
  }
  return lines;
}

// README's annotated scene is the shipped default example, setting for setting (comments differ).
TEST(Examples, ReadmeAnnotatesTheDefaultSceneAsShipped) {
  const std::string readme = test::ReadFile(RIME_SOURCE_DIR "/README.md");
  const auto section = readme.find("## A scene, annotated");
  ASSERT_NE(section, std::string::npos);
  const auto begin = readme.find("```toml\n", section);
  ASSERT_NE(begin, std::string::npos);
  const auto end = readme.find("```", begin + 8);
  ASSERT_NE(end, std::string::npos);
  const auto shown = Settings(readme.substr(begin + 8, end - begin - 8));
  const auto shipped = Settings(test::ReadFile(RIME_SOURCE_DIR "/examples/default.toml"));
  ASSERT_FALSE(shipped.empty());
  for (std::size_t i = 0; i < std::max(shown.size(), shipped.size()); ++i)
    ASSERT_EQ(i < shown.size() ? shown[i] : "(end of README's block)", i < shipped.size() ? shipped[i] : "(end of the file)")
        << "setting " << i + 1 << " of README's annotated scene differs from examples/default.toml";
}

// Dam break (validation): a 1 x 1 x 1 m block in the corner of a 4 x 3 x 1.5 m open tank, with the
// fluid 1.1 d_p away from the walls so no particle starts inside the boundary's support.
TEST(Examples, DamBreakStartsClearOfTheWalls) {
  const io::Scene scene = io::LoadScene(RIME_SOURCE_DIR "/examples/dam_break.toml");
  ASSERT_EQ(scene.solids.size(), 1u);
  const auto& tank = scene.solids[0];
  EXPECT_TRUE(tank.container);
  EXPECT_EQ(tank.shape, io::SolidShape::kBox);
  const double d = scene.fluid.spacing;
  EXPECT_DOUBLE_EQ(d, 0.0264);
  const Vec3d tank_min = tank.transform.translate - tank.size * 0.5;
  ASSERT_EQ(scene.fluid_blocks.size(), 1u);
  const auto& block = scene.fluid_blocks[0];
  for (int a = 0; a < 3; ++a) {
    EXPECT_NEAR(block.min[a] - tank_min[a], 1.1 * d, 1e-9) << "axis " << a;
    EXPECT_NEAR(block.max[a] - block.min[a], 1.0, 1e-9) << "axis " << a;
  }
  EXPECT_NEAR(tank.size.x, 4.0, 1e-12);
  EXPECT_NEAR(tank.size.y, 3.0, 1e-12);
  EXPECT_NEAR(tank.size.z, 1.5, 1e-12);
}

TEST(Examples, MeshScenesPointAtTheSharedMeshes) {
  if (!fs::exists(RIME_SHARED_DIR "/meshes")) GTEST_SKIP() << "../shared/meshes is absent: mesh paths not checked";
  for (const auto& file : ExampleScenes()) {
    const io::Scene scene = io::LoadScene(file);
    for (const auto& solid : scene.solids) {
      if (solid.shape == io::SolidShape::kMesh) {
        EXPECT_TRUE(fs::exists(scene.Resolve(solid.mesh))) << file << ": " << solid.mesh;
      }
    }
  }
}

}  // namespace
}  // namespace rime::bake
