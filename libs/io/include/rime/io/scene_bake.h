/// @file scene_bake.h
/// @brief `[bake]` section of the scene file: the preview settings only rime-bake reads
/// (LoadScene skips the table; rime-bake loads it with LoadSettings).
#pragma once

#include <span>
#include <string_view>

#include "rime/io/param.h"

namespace rime::io {

enum class PreviewEngine { kWorkbench, kCycles };
inline std::span<const std::string_view> Names(PreviewEngine) {
  static constexpr std::string_view names[] = {"workbench", "cycles"};
  return names;
}

struct BakeSettings {
  int preview_width = 960;
  int preview_height = 540;
  PreviewEngine preview_engine = PreviewEngine::kWorkbench;
  int preview_samples = 16;
  int contact_sheet_columns = 4;
  Vec3d preview_view{1.0, -1.4, 0.8};
  // Both zero: the camera frames the whole [domain] (or the water and solids without one).
  Vec3d preview_frame_min{0, 0, 0}, preview_frame_max{0, 0, 0};
  bool FramesABox() const { return !(preview_frame_min == Vec3d{0, 0, 0} && preview_frame_max == Vec3d{0, 0, 0}); }

  template <class Self, class F>
  static void Visit(Self& s, F&& f) {
    f(Param{.name = "preview_width", .unit = "px", .range = Range::Closed(16, 16384), .help = "rendered image width"}, s.preview_width);
    f(Param{.name = "preview_height", .unit = "px", .range = Range::Closed(16, 16384), .help = "rendered image height"}, s.preview_height);
    f(Param{.name = "preview_engine", .help = "Blender render engine"}, s.preview_engine);
    f(Param{.name = "preview_samples", .range = Range::Closed(1, 65536), .help = "Cycles samples per pixel (Workbench ignores it)"},
      s.preview_samples);
    f(Param{.name = "contact_sheet_columns", .range = Range::Closed(1, 64), .help = "frames per row of `contact_sheet.png`"},
      s.contact_sheet_columns);
    f(Param{.name = "preview_view",
            .range = Range::Closed(-1e6, 1e6),
            .help = "direction from the centre of what the camera frames to the camera (z up), not the zero vector"},
      s.preview_view);
    f(Param{.name = "preview_frame_min",
            .unit = "m",
            .range = Range::Closed(-1e6, 1e6),
            .help = "lower corner of the box the preview camera frames, for a close-up (with `preview_frame_max`)",
            .default_doc = "[0, 0, 0]: the whole `[domain]`"},
      s.preview_frame_min);
    f(Param{.name = "preview_frame_max",
            .unit = "m",
            .range = Range::Closed(-1e6, 1e6),
            .help = "upper corner of that box, above `preview_frame_min` on every axis",
            .default_doc = "[0, 0, 0]: the whole `[domain]`"},
      s.preview_frame_max);
  }
};

}  // namespace rime::io
