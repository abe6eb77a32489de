/// @file scene_reference.h
/// @brief The tables of docs/scene-reference.md (scene fields), docs/tools.md (the flags that
/// override them) and docs/farm.md (`[farm]`), generated from the settings declarations.
///
/// A page marks each generated table with `<!-- generated: [name] -->` above and
/// `<!-- end generated -->` below; everything else on the page is written by hand.
/// `rime-scene-reference docs/scene-reference.md docs/tools.md docs/farm.md` rewrites the tables,
/// and the io tests fail while a page and the declarations disagree.
#pragma once

#include <string>
#include <vector>

namespace rime::io {

struct ReferenceTable {
  std::string page;      // file in docs/ that shows it
  std::string section;   // "freezing", "flags: surface", ...
  std::string markdown;  // the table, ending with a newline
};

/// One table per scene section whose fields are declared (SceneInfo::Visit and the like), and
/// one per settings struct whose fields have command-line flags.
std::vector<ReferenceTable> SceneReferenceTables();

/// `page` with every generated table replaced by the current one. Throws rime::Error for a marker
/// naming an unknown section or left open.
std::string UpdateReferenceTables(const std::string& page);

}  // namespace rime::io
