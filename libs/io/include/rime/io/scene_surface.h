/// @file scene_surface.h
/// @brief `[surface]` section of the scene file (rime-surface settings).
#pragma once

namespace rime::io {

class TomlReader;

struct SurfaceSettings {};

/// Reads the `[surface]` table into `settings` (fields absent from the table keep their defaults).
void ParseSurfaceSettings(TomlReader& table, SurfaceSettings& settings);

}  // namespace rime::io
