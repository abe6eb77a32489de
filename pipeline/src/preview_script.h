/// @file preview_script.h
/// @brief Files the optional preview stage hands to Blender: the render script and a JSON
/// description of the scene (colliders, fixed camera bounds, image settings).
#pragma once

#include <filesystem>

#include "bake_graph.h"
#include "scene_document.h"

namespace rime::bake {

/// Writes `<cache>/preview/render_preview.py` and `preview_scene.json`, only when their content
/// changed (their content hashes are inputs of the preview jobs).
void WritePreviewFiles(const SceneDocument& doc, const BakeLayout& layout);

}  // namespace rime::bake
