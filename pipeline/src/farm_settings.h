/// @file farm_settings.h
/// @brief Site settings for baking on a Slurm cluster: a `[farm]` table in a site file (named by
/// --farm-config or $RIME_FARM_CONFIG) and/or in the scene, the scene's keys taking precedence.
#pragma once

#include <array>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "bake_graph.h"
#include "rime/io/scene_farm.h"

namespace rime::bake {

/// The declared `[farm]` keys (rime/io/scene_farm.h) and the per-stage values of `[farm.time]`
/// and `[farm.memory]`, indexed by Stage.
struct FarmSettings : io::FarmSettings {
  std::array<std::string, kStageCount> time{}, memory{};  // Slurm's `--time` and `--mem`; empty: the partition's default
  std::vector<std::string> sources;                       // files the settings came from, for messages
};

/// Site file first (when given), then the scene's `[farm]` table over it. Errors name
/// `file:line: farm.key` like every other scene section.
FarmSettings LoadFarmSettings(const std::optional<std::filesystem::path>& site_file, const std::filesystem::path& scene_file);

}  // namespace rime::bake
