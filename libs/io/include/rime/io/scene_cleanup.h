/// @file scene_cleanup.h
/// @brief `[cleanup]` section of the scene file (rime-clean settings).
#pragma once

namespace rime::io {

class TomlReader;

struct CleanupSettings {};

/// Reads the `[cleanup]` table into `settings` (fields absent from the table keep their defaults).
void ParseCleanupSettings(TomlReader& table, CleanupSettings& settings);

}  // namespace rime::io
