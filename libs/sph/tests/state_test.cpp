// The particle groups of src/state.h: a module that is off allocates nothing, and a frame stores
// exactly the solver's arrays, checked attribute by attribute from the groups' declarations.
#include <gtest/gtest.h>

#include <unistd.h>

#include <algorithm>
#include <filesystem>
#include <set>
#include <string>

#include "../src/state.h"
#include "rime/exec/device.h"
#include "rime/sph/simulation.h"
#include "rime/test/sph_scenes.h"
#include "rime/test/temp_folder.h"

namespace rime::sph {
namespace {

// The drop scene of the freezing tests, with freezing on or off.
io::Scene DropScene(bool freezing) {
  io::Scene scene = test::DropScene(0.05, 0.01);
  if (!freezing) scene.modules.erase("freezing");
  return scene;
}

using test::MakeDrop;

TEST(ParticleGroups, FreezingOffAllocatesNothing) {
  auto without = MakeDrop(DropScene(false));
  auto with = MakeDrop(DropScene(true));
  for (int i = 0; i < 5; ++i) {
    without->Step(0.002);
    with->Step(0.002);
  }
  ASSERT_EQ(without->fluid_count(), with->fluid_count());
  std::printf("particle memory: %zu bytes without freezing, %zu with (freezing groups %zu)\n", without->MemoryBytes(), with->MemoryBytes(),
              with->MemoryBytes("freezing"));
  EXPECT_EQ(without->MemoryBytes("freezing"), 0u);
  EXPECT_FALSE(without->modules().HasAttribute("water_film"));
  EXPECT_TRUE(with->modules().HasAttribute("water_film"));
  EXPECT_FALSE(with->modules().HasAttribute("contact_time")) << "the nucleation clock exists only with freezing.freeze_delay > 0";
  // The film, growth and ice arrays hold at least 1 + 12 + 1 + 1 + 8 + 24 bytes per boundary particle.
  EXPECT_GE(with->MemoryBytes("freezing"), std::size_t(with->boundary_count()) * 47);
  EXPECT_GE(with->MemoryBytes(), without->MemoryBytes() + with->MemoryBytes("freezing"));
  // The water's persistent state alone: position, velocity, id, pressure, density.
  EXPECT_GE(without->MemoryBytes("core"), std::size_t(without->fluid_count()) * (12 + 12 + 8 + 4 + 4));
  EXPECT_EQ(without->MemoryBytes(), without->MemoryBytes("core"));
}

// Compares the checkpointed attributes of `group` with rows [first, first + size) of `frame`
// and records the datasets it checked.
template <class Group>
void ExpectRows(const Group& group, const io::ParticleFrame& frame, std::size_t first, std::set<std::string>& checked) {
  group.ForEach([&](const AttributeInfo& a, const auto& array) {
    if (!a.checkpointed) return;
    using V = typename std::decay_t<decltype(array)>::value_type;
    using C = Components<V>;
    const std::vector<V> solver = array.ToHost();
    for (int c = 0; c < C::kCount; ++c) {
      const std::string name = ColumnName(a, c, C::kCount);
      ASSERT_TRUE(frame.Has(name)) << "the frame lacks " << name;
      const auto& stored = frame.Get<typename C::Scalar>(name);
      ASSERT_GE(stored.size(), first + solver.size()) << name;
      std::size_t differ = 0;
      for (std::size_t i = 0; i < solver.size(); ++i) differ += stored[first + i] != C::Get(solver[i], c);
      EXPECT_EQ(differ, 0u) << name << ": " << differ << " of " << solver.size() << " rows differ from the solver";
      checked.insert(name);
    }
  });
}

// Writes a frame, reads it back and checks every dataset against the solver's arrays.
void ExpectFrameIsTheState(const Simulation<float>& sim, const std::string& label) {
  SCOPED_TRACE(label);
  const rime::test::TempFolder dir("state");
  const auto path = dir / "frame.h5part";
  io::WriteParticleFrame(path, sim.Snapshot(1));
  const io::ParticleFrame frame = io::ReadParticleFrame(path, "particles");
  const auto& s = sim.state();
  const std::size_t nf = std::size_t(sim.fluid_count()), nb = std::size_t(sim.boundary_count());
  ASSERT_EQ(frame.size(), nf + nb);
  std::set<std::string> checked{"phase"};
  const auto& phase = frame.Get<std::uint8_t>("phase");
  for (std::size_t i = 0; i < nf; ++i) ASSERT_EQ(phase[i], std::uint8_t(io::Phase::kFluid)) << "row " << i;
  s.ForEachFluidGroup([&](const auto& group) { ExpectRows(group, frame, 0, checked); });
  s.ForEachBoundaryGroup([&](const auto& group) { ExpectRows(group, frame, nf, checked); });
  for (const auto& [name, values] : frame.attributes) EXPECT_TRUE(checked.count(name)) << name << " is stored but declared by no group";
  // Water density is the kernel sum of the last step, not a placeholder.
  const auto density = sim.Densities();
  ASSERT_FALSE(density.empty());
  EXPECT_NE(*std::min_element(density.begin(), density.end()), *std::max_element(density.begin(), density.end()));
}

TEST(ParticleGroups, FrameFieldsAreTheSolversState) {
  io::Scene scene = DropScene(true);
  scene.freezing.freeze_delay = 0.01;  // so that the nucleation clocks are stored too
  auto sim = MakeDrop(scene);
  bool froze = false, calm = false;
  while (sim->time() < 0.5 && !(froze && calm)) {
    const StepStats stats = sim->Step(sim->NextTimeStep(0.5));
    if (stats.frozen_particles > 0 && !froze) {
      froze = true;
      ExpectFrameIsTheState(*sim, "frame of a step in which water froze");
    } else if (stats.frozen_particles == 0 && froze && !calm) {
      calm = true;
      ExpectFrameIsTheState(*sim, "frame of a step without a phase change");
    }
  }
  EXPECT_TRUE(froze) << "no water froze in 0.5 s";
  EXPECT_TRUE(calm);
}

}  // namespace
}  // namespace rime::sph
