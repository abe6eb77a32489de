#include <gtest/gtest.h>

#include <fmt/format.h>

#include <cmath>
#include <fstream>
#include <sstream>

#include "rime/core/error.h"
#include "rime/io/scene.h"
#include "rime/io/scene_reference.h"

namespace rime::io {
namespace {

TEST(SceneReference, DocsTablesMatchTheDeclarations) {
  for (const std::string name : {"scene-reference.md", "tools.md", "farm.md"}) {
    const std::string path = std::string(RIME_SOURCE_DIR) + "/docs/" + name;
    std::stringstream page;
    page << std::ifstream(path, std::ios::binary).rdbuf();
    ASSERT_FALSE(page.str().empty()) << path;
    for (const ReferenceTable& table : SceneReferenceTables()) {
      if (table.page != name) continue;
      EXPECT_NE(page.str().find("<!-- generated: [" + table.section + "] -->"), std::string::npos)
          << path << " has no generated table [" << table.section << "]";
    }
    EXPECT_TRUE(UpdateReferenceTables(page.str()) == page.str())
        << path << " disagrees with the declarations: run "
        << "`build/rime/bin/rime-scene-reference docs/scene-reference.md docs/tools.md docs/farm.md`";
  }
}

TEST(SceneReference, UnknownSectionMarkerIsRefused) {
  EXPECT_THROW(UpdateReferenceTables("<!-- generated: [nowhere] -->\n<!-- end generated -->\n"), Error);
  EXPECT_THROW(UpdateReferenceTables("<!-- generated: [freezing] -->\n| table |\n"), Error);
}

// A value just outside each declared range is refused, naming the section and key: the loader
// takes its checks from the same declaration the docs show.
template <class Settings>
void ExpectRangesEnforced(const std::string& section, const std::string& preamble) {
  int checked = 0;
  const Settings defaults{};
  Settings::Visit(defaults, [&](const Param& p, const auto& value) {
    using T = std::decay_t<decltype(value)>;
    if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
      const bool integer = std::is_integral_v<T>;
      std::string below;
      if (p.range.min > -1e299)
        below = integer ? fmt::format("{}", (long long)(std::floor(p.range.min)) - (p.range.min_exclusive ? 0 : 1))
                        : fmt::format("{}", p.range.min_exclusive ? p.range.min : p.range.min - 1);
      if (below.empty()) return;
      const std::string text = fmt::format("{}[{}]\n{} = {}\n", preamble, section, p.name, below);
      try {
        ParseScene(text, "ranges.toml");
        ADD_FAILURE() << "accepted:\n" << text;
      } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find(fmt::format("{}.{}", section, p.name)), std::string::npos) << e.what();
      }
      ++checked;
    }
  });
  EXPECT_GT(checked, 0) << section;
}

TEST(SceneReference, LoaderEnforcesEveryDeclaredLowerBound) {
  const std::string all_modules = "[sim]\nmodules = [\"gravity\", \"viscosity\", \"surface_tension\", \"air_pressure\", \"freezing\"]\n";
  ExpectRangesEnforced<SceneInfo>("scene", "");
  ExpectRangesEnforced<FluidSettings>("water", "");
  ExpectRangesEnforced<ViscositySettings>("viscosity", all_modules);
  ExpectRangesEnforced<SurfaceTensionSettings>("surface_tension", all_modules);
  ExpectRangesEnforced<AirPressureSettings>("air_pressure", all_modules);
  ExpectRangesEnforced<FreezingSettings>("freezing", all_modules);
  ExpectRangesEnforced<SurfaceSettings>("surface", "");
  ExpectRangesEnforced<CleanupSettings>("clean", "");
}

TEST(SceneReference, StringOptionsBecomeEnumsAndUnknownNamesAreRefused) {
  const Scene s = ParseScene(
      "[sim]\nmodules = [\"gravity\", \"freezing\"]\ntime_step = \"fixed\"\n"
      "[freezing]\nfr_mode = \"map\"\nce_aggregation = \"sum\"\n[clean]\nsmooth = \"none\"\n",
      "enums.toml");
  EXPECT_EQ(s.solver.time_step, TimeStep::kFixed);
  EXPECT_EQ(s.freezing.fr_mode, FrMode::kMap);
  EXPECT_EQ(s.freezing.ce_aggregation, CeAggregation::kSum);
  EXPECT_EQ(s.cleanup.smooth, MeshSmoothing::kNone);
  EXPECT_EQ(EnumName(s.freezing.growth), "anisotropic");
  try {
    ParseScene("[sim]\nmodules = [\"gravity\", \"freezing\"]\n[freezing]\ngrowth = \"radial\"\n", "enums.toml");
    ADD_FAILURE() << "accepted an unknown growth";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("unknown value 'radial' (expected one of: anisotropic, isotropic)"), std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("enums.toml:4: freezing.growth"), std::string::npos) << e.what();
  }
}

TEST(SceneReference, RemovedPcaOptionIsRefusedWithAReason) {
  try {
    ParseScene("[sim]\nmodules = [\"gravity\", \"freezing\"]\n[freezing]\npca = \"w2h\"\n", "pca.toml");
    ADD_FAILURE() << "accepted freezing.pca";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("removed"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("pca.toml:4: freezing.pca"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace rime::io
