#include "rime/core/sandbox.h"

#include <fmt/format.h>

namespace fs = std::filesystem;

namespace rime {

Sandbox::Sandbox(const fs::path& root) {
  std::error_code ec;
  if (root.empty() || !fs::is_directory(root, ec))
    throw Error(ExitCode::kUsage, "the sandbox must be an existing folder", "--sandbox " + root.string());
  root_ = fs::weakly_canonical(fs::absolute(root), ec);
  if (ec) throw Error(ExitCode::kUsage, fmt::format("cannot resolve the sandbox: {}", ec.message()), "--sandbox " + root.string());
}

bool Sandbox::Contains(const fs::path& path) const {
  if (!enabled()) return true;
  std::error_code ec;
  const fs::path resolved = fs::weakly_canonical(fs::absolute(path, ec), ec);
  if (ec) return false;  // unresolvable (a symlink loop): not provably inside
  // Relative to the root it must not start with "..": /box-other is not inside /box.
  const fs::path relative = resolved.lexically_relative(root_);
  return !relative.empty() && *relative.begin() != "..";
}

void Sandbox::Require(const fs::path& path, std::string_view field, ExitCode code) const {
  if (Contains(path)) return;
  std::error_code ec;
  const fs::path resolved = fs::weakly_canonical(fs::absolute(path, ec), ec);
  throw Error(code, fmt::format("{} {} resolves to {}, outside the sandbox {}", field, path.string(),
                                ec ? std::string("an unresolvable path") : resolved.string(), root_.string()));
}

}  // namespace rime
