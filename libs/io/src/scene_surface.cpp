#include "rime/io/scene_surface.h"

#include "rime/io/toml_reader.h"

namespace rime::io {

void ParseSurfaceSettings(TomlReader& t, SurfaceSettings& s) {
  LoadSettings(t, s);
  if (s.resolution == 1) t.Fail("resolution", "must be 0 (off) or at least 2");
  if (t.Has("formats") && s.formats.empty()) t.Fail("formats", "needs at least one of obj, ply, vdb");
}

}  // namespace rime::io
