#include "rime/io/scene_surface.h"

#include "rime/io/toml_reader.h"

namespace rime::io {

void ParseSurfaceSettings(TomlReader& table, SurfaceSettings& settings) {}

}  // namespace rime::io
