#include "rime/io/scene_cleanup.h"

#include "rime/io/toml_reader.h"

namespace rime::io {

void ParseCleanupSettings(TomlReader& t, CleanupSettings& s) { LoadSettings(t, s); }

}  // namespace rime::io
