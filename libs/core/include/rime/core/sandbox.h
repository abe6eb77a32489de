/// @file sandbox.h
/// @brief `--sandbox DIR`: every file a tool reads or writes must resolve inside one folder, so a
/// scene from someone else cannot make a bake read or overwrite files elsewhere.
#pragma once

#include <filesystem>
#include <string>
#include <string_view>

#include "rime/core/error.h"

namespace rime {

class Sandbox {
 public:
  Sandbox() = default;  // off: every path is allowed
  /// `root` must be an existing folder (else rime::Error kUsage); it is resolved through symlinks.
  explicit Sandbox(const std::filesystem::path& root);

  bool enabled() const { return !root_.empty(); }
  const std::filesystem::path& root() const { return root_; }

  /// Whether `path` (relative paths against the working folder) resolves inside the root after
  /// following every symlink that exists (std::filesystem::weakly_canonical).
  bool Contains(const std::filesystem::path& path) const;
  /// Throws rime::Error(code) naming `field` (a flag or `scene.toml: solid.mesh`) and the path,
  /// when the sandbox is on and `path` resolves outside it.
  void Require(const std::filesystem::path& path, std::string_view field, ExitCode code) const;

 private:
  std::filesystem::path root_;
};

}  // namespace rime
