/// @file toml_reader.h
/// @brief Checked access to a TOML table: defaults, range checks, and errors naming file:line and
/// the field's dotted path. Keys that were never read are reported as unknown (catches typos).
#pragma once

#include <array>
#include <filesystem>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "rime/core/math.h"

namespace toml {
inline namespace v3 {
class table;
class node;
}  // namespace v3
}  // namespace toml

namespace rime::io {

struct Range {
  double min = -1e300, max = 1e300;
  bool min_exclusive = false, max_exclusive = false;
  static constexpr Range Positive() { return {0, 1e300, true, false}; }
  static constexpr Range NonNegative() { return {0, 1e300, false, false}; }
  static constexpr Range Closed(double a, double b) { return {a, b, false, false}; }
  static constexpr Range OpenClosed(double a, double b) { return {a, b, true, false}; }  // (a, b]
  static constexpr Range Open(double a, double b) { return {a, b, true, true}; }
  static constexpr Range Any() { return {}; }
  bool IsAny() const { return min < -1e299 && max > 1e299; }
  bool Contains(double v) const;
  std::string Describe() const;
};

/// Refuses TOML text nested deeper than kMaxTomlDepth tables/arrays or holding a string longer than
/// kMaxTomlString bytes, in one linear pass before parsing: toml++ recurses once per dotted-key
/// segment and overflows the stack near 1e5 levels. Throws rime::Error naming `file:line: key`.
inline constexpr int kMaxTomlDepth = 64;
inline constexpr std::size_t kMaxTomlString = 1 << 20;
void CheckTomlLimits(std::string_view text, const std::string& file);

class TomlReader {
 public:
  /// `table` must outlive the reader. `path` is the dotted prefix of this table ("" for the root).
  TomlReader(const toml::table& table, std::string file, std::string path);

  bool Has(const std::string& key) const;
  double Number(const std::string& key, double fallback, Range range = Range::Any());
  std::int64_t Integer(const std::string& key, std::int64_t fallback, Range range = Range::Any());
  bool Bool(const std::string& key, bool fallback);
  std::string String(const std::string& key, const std::string& fallback, const std::vector<std::string>& allowed = {});
  Vec3d Vector(const std::string& key, const Vec3d& fallback, Range range = Range::Any());
  /// A single number (uniform) or a 3-vector.
  Vec3d ScalarOrVector(const std::string& key, const Vec3d& fallback, Range range = Range::Any());
  std::vector<std::string> StringList(const std::string& key, const std::vector<std::string>& allowed = {});
  /// Fails "'value' is not <accepted>" unless `pattern` (ECMAScript) matches all of `value`.
  void CheckPattern(const std::string& key, const std::string& value, std::string_view pattern, std::string_view accepted) const;
  /// Sub-table (empty reader if absent).
  TomlReader Table(const std::string& key);
  /// Array of tables `[[key]]`.
  std::vector<TomlReader> TableArray(const std::string& key);
  /// Marks a key as known without reading it (e.g. a section handled elsewhere).
  void Skip(const std::string& key) { used_.insert(key); }

  /// Throws for the first key that no call above asked for: "unknown key 'spaceing'".
  void RejectUnknownKeys() const;

  /// "scene.toml:12" for a key (line of the value), or the table's line when the key is absent.
  std::string Where(const std::string& key) const;
  std::string FieldPath(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }
  [[noreturn]] void Fail(const std::string& key, const std::string& message) const;
  const std::string& file() const { return file_; }

 private:
  const toml::node* Find(const std::string& key);

  const toml::table* table_;
  std::string file_;
  std::string path_;
  std::set<std::string> used_;
};

}  // namespace rime::io
