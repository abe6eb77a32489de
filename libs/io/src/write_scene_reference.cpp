// rime-scene-reference: rewrites the generated tables of docs/scene-reference.md, docs/tools.md and
// docs/farm.md from the settings declarations (rime/io/scene_reference.h); the io tests fail until it has run
// after a change.
#include <fmt/format.h>

#include <fstream>
#include <sstream>

#include "rime/core/error.h"
#include "rime/io/scene_reference.h"

int main(int argc, char** argv) {
  if (argc < 2) {
    fmt::print(stderr, "usage: rime-scene-reference docs/scene-reference.md docs/tools.md docs/farm.md\n");
    return 2;
  }
  for (int k = 1; k < argc; ++k) {
    std::stringstream page;
    page << std::ifstream(argv[k], std::ios::binary).rdbuf();
    try {
      const std::string updated = rime::io::UpdateReferenceTables(page.str());
      if (updated == page.str()) continue;
      std::ofstream(argv[k], std::ios::binary) << updated;
      fmt::print("{}: tables updated\n", argv[k]);
    } catch (const rime::Error& e) {
      fmt::print(stderr, "{}: {}\n", argv[k], e.what());
      return 3;
    }
  }
  return 0;
}
