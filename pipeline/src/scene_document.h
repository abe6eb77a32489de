/// @file scene_document.h
/// @brief The scene file as rime-bake sees it: the validated Scene, the `[bake]` table, and a hash
/// per TOML section so each stage's key covers only the sections that stage reads.
#pragma once

#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "rime/io/scene.h"

namespace rime::bake {

/// `[bake]` table of the scene file (README.md "rime-bake"). Only the optional preview stage reads it.
struct BakeSettings {
  int preview_width = 960;             // pixels
  int preview_height = 540;            // pixels
  std::string preview_engine = "workbench";  // "workbench" | "cycles"
  int preview_samples = 16;            // Cycles samples per pixel (Workbench ignores it)
  int contact_sheet_columns = 4;       // frames per row of the contact sheet
  Vec3d preview_view{1.0, -1.4, 0.8};  // direction from the scene's centre to the camera
};

class SceneDocument {
 public:
  /// Loads and validates the whole scene (rime::io::LoadScene) and the `[bake]` table.
  static SceneDocument Load(const std::filesystem::path& file);

  const io::Scene& scene() const { return scene_; }
  const BakeSettings& bake() const { return bake_; }
  /// Top-level keys present in the file ("scene", "water", "solid", ...), sorted.
  const std::vector<std::string>& sections() const { return sections_; }
  /// Hash of one section's parsed value ("water", or a dotted key such as "scene.quality"), so
  /// comments, key order and formatting do not matter; "absent" when the file does not set it.
  std::string SectionHash(const std::string& dotted_name) const;

 private:
  io::Scene scene_;
  BakeSettings bake_;
  std::vector<std::string> sections_;
  std::vector<std::pair<std::string, std::string>> canonical_;  // dotted name -> canonical JSON text
};

}  // namespace rime::bake
