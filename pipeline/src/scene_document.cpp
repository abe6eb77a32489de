#include "scene_document.h"

#include <fmt/format.h>

#include <fstream>
#include <sstream>
#include <toml++/toml.h>

#include "rime/core/error.h"
#include "rime/core/hash.h"
#include "rime/io/toml_reader.h"

namespace rime::bake {
namespace {

BakeSettings ParseBakeTable(io::TomlReader t) {
  BakeSettings b;
  io::LoadSettings(t, b);
  if (!(Norm(b.preview_view) > 0)) t.Fail("preview_view", "must not be the zero vector");
  if (b.FramesABox())
    for (int a = 0; a < 3; ++a)
      if (!(b.preview_frame_max[a] > b.preview_frame_min[a])) t.Fail("preview_frame_max", "must be above preview_frame_min on every axis");
  t.RejectUnknownKeys();
  return b;
}

// Canonical text of a parsed TOML value: toml++ tables are ordered maps, so the JSON form does not
// depend on key order, comments or number formatting in the file.
std::string Canonical(const toml::node& node) {
  std::ostringstream out;
  if (const auto* table = node.as_table()) {
    out << toml::json_formatter{*table};
  } else if (const auto* array = node.as_array()) {
    out << toml::json_formatter{*array};
  } else {
    toml::table wrapper;
    wrapper.insert("value", node);
    out << toml::json_formatter{wrapper};
  }
  return out.str();
}

}  // namespace

SceneDocument SceneDocument::Load(const std::filesystem::path& file) {
  SceneDocument doc;
  doc.scene_ = io::LoadScene(file);  // validates every stage's section, names file:line: field
  std::ifstream in(file, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  const toml::table root = toml::parse(text.str(), file.string());  // already known to parse
  for (const auto& [key, node] : root) {
    const std::string name(key.str());
    doc.sections_.push_back(name);
    doc.canonical_.emplace_back(name, Canonical(node));
    if (const auto* table = node.as_table())
      for (const auto& [sub_key, sub_node] : *table)
        doc.canonical_.emplace_back(name + "." + std::string(sub_key.str()), Canonical(sub_node));
  }
  io::TomlReader top(root, file.string(), "");
  doc.bake_ = ParseBakeTable(top.Table("bake"));
  return doc;
}

std::string SceneDocument::SectionHash(const std::string& dotted_name) const {
  for (const auto& [name, text] : canonical_)
    if (name == dotted_name) return HexHash(Hash64(text));
  return "absent";
}

}  // namespace rime::bake
