/// @file param.h
/// @brief One declaration per scene field: name, unit, range, choices, help and command-line flag.
///
/// Every settings struct of the scene keeps its defaults as member initialisers and lists each field
/// once in a static `Visit(settings, f)`, calling `f(Param{...}, settings.field)`. The TOML loader
/// (LoadSettings), the tools' override flags (tools/common/override_flags.h) and the tables of
/// docs/scene-reference.md and docs/tools.md (scene_reference.h) are visitors over that one list,
/// so adding a field touches one struct.
///
/// @code
/// struct AirPressureSettings {
///   double p_atm = 5000;
///   template <class Self, class F> static void Visit(Self& s, F&& f) {
///     f(Param{.name = "p_atm", .unit = "Pa", .range = Range::NonNegative(), .help = "air pressure"}, s.p_atm);
///   }
/// };
/// @endcode
///
/// A string option is an enum from the moment it is loaded: the enum's values are the indices of
/// the names that `Names(E)` returns (found by argument-dependent lookup beside the enum).
#pragma once

#include <fmt/format.h>

#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "rime/core/math.h"
#include "rime/io/toml_reader.h"

namespace rime::io {

struct Param {
  std::string_view name;                           // TOML key
  std::string_view unit = {};                      // SI unit or what the value counts ("d_p", "voxels"); empty: a plain number
  Range range = Range::Any();                      // numbers, integers and every component of a vector
  std::string_view help = {};                      // one line: the flag's help and the start of the docs' meaning column
  std::string_view doc = {};                       // docs only, appended to `help` (markdown)
  std::string_view flag = {};                      // command-line override in CLI11 syntax ("--kr", "!--no-velocity"); empty: none
  std::string_view default_doc = {};               // docs: the default in words when the value alone does not say it
  std::span<const std::string_view> choices = {};  // allowed names of a string list
  std::string_view pattern = {};                   // ECMAScript regex that a non-empty string, and every item of a list, matches in full
  std::string_view accepted = {};                  // what `pattern` accepts, in words: "a Slurm memory size (e.g. 4000M or 16G)"
  bool scalar_or_vector = false;                   // a vector also accepts one number for all three components
};

template <class E>
concept NamedEnum = std::is_enum_v<E> && requires(E e) {
  { Names(e) } -> std::convertible_to<std::span<const std::string_view>>;
};

template <NamedEnum E>
std::string_view EnumName(E value) {
  return Names(value)[std::size_t(value)];
}

template <NamedEnum E>
std::vector<std::string> EnumNames() {
  const std::span<const std::string_view> names = Names(E{});
  return {names.begin(), names.end()};
}

/// The enum value named `name`; false when no value has that name.
template <NamedEnum E>
bool ParseEnum(std::string_view name, E& value) {
  const std::span<const std::string_view> names = Names(E{});
  const auto it = std::find(names.begin(), names.end(), name);
  if (it == names.end()) return false;
  value = E(it - names.begin());
  return true;
}

/// Reads each field a settings struct declares from a TOML table, keeping the current value of
/// those the table does not set.
class TomlLoader {
 public:
  explicit TomlLoader(TomlReader& table) : t_(table) {}

  void operator()(const Param& p, double& v) const { v = t_.Number(Key(p), v, p.range); }
  void operator()(const Param& p, int& v) const { v = static_cast<int>(t_.Integer(Key(p), v, p.range)); }
  void operator()(const Param& p, long long& v) const { v = t_.Integer(Key(p), v, p.range); }
  void operator()(const Param& p, bool& v) const { v = t_.Bool(Key(p), v); }
  void operator()(const Param& p, std::string& v) const {
    v = t_.String(Key(p), v);
    if (!p.pattern.empty() && !v.empty()) t_.CheckPattern(Key(p), v, p.pattern, p.accepted);
  }
  void operator()(const Param& p, std::filesystem::path& v) const { v = t_.String(Key(p), v.string()); }
  void operator()(const Param& p, Vec3d& v) const {
    v = p.scalar_or_vector ? t_.ScalarOrVector(Key(p), v, p.range) : t_.Vector(Key(p), v, p.range);
  }
  void operator()(const Param& p, std::vector<std::string>& v) const {
    if (!t_.Has(Key(p))) return;
    v = t_.StringList(Key(p), {p.choices.begin(), p.choices.end()});
    if (!p.pattern.empty())
      for (const std::string& item : v) t_.CheckPattern(Key(p), item, p.pattern, p.accepted);
  }
  template <NamedEnum E>
  void operator()(const Param& p, E& v) const {
    ParseEnum(t_.String(Key(p), std::string(EnumName(v)), EnumNames<E>()), v);
  }

 private:
  static std::string Key(const Param& p) { return std::string(p.name); }
  TomlReader& t_;
};

/// Loads every field `Settings::Visit` declares from `table`.
template <class Settings>
void LoadSettings(TomlReader& table, Settings& settings) {
  Settings::Visit(settings, TomlLoader(table));
}

/// A value as the docs and the flags' help show it.
inline std::string FormatValue(double v) { return fmt::format("{}", v); }
inline std::string FormatValue(long long v) { return fmt::format("{}", v); }
inline std::string FormatValue(int v) { return fmt::format("{}", v); }
inline std::string FormatValue(bool v) { return v ? "true" : "false"; }
inline std::string FormatValue(const std::string& v) { return fmt::format("\"{}\"", v); }
inline std::string FormatValue(const std::filesystem::path& v) { return FormatValue(v.string()); }
inline std::string FormatValue(const Vec3d& v) { return fmt::format("[{}, {}, {}]", v.x, v.y, v.z); }
inline std::string FormatValue(const std::vector<std::string>& v) {
  std::string out = "[";
  for (std::size_t k = 0; k < v.size(); ++k) out += fmt::format("{}\"{}\"", k ? ", " : "", v[k]);
  return out + "]";
}
template <NamedEnum E>
std::string FormatValue(E v) {
  return fmt::format("\"{}\"", EnumName(v));
}

}  // namespace rime::io
