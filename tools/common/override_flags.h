/// @file override_flags.h
/// @brief Command-line overrides of scene fields, derived from their declarations (rime/io/param.h).
///
/// A field whose `Param::flag` is set becomes a flag of every tool that adds its settings struct:
/// its help, unit, default and range check come from the one declaration. Flags given on the
/// command line replace the scene's (or the default) values.
///
/// @code
/// tool::OverrideFlags<io::CleanupSettings> overrides;
/// overrides.AddTo(app);                 // --repair, --no-degenerate, --cap-angle, ...
/// ...after parsing:
/// io::CleanupSettings settings = io::LoadScene(file).cleanup;
/// overrides.ApplyTo(settings);
/// @endcode
#pragma once

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <fmt/ranges.h>

#include <algorithm>
#include <map>
#include <memory>
#include <stdexcept>
#include <string>
#include <string_view>
#include <type_traits>
#include <vector>

#include "rime/core/error.h"
#include "rime/io/param.h"

namespace rime::tool {

/// Refuses a number outside `range` with the loader's wording; text that is no number is left to
/// CLI11's conversion, which names it.
inline CLI::Validator RangeValidator(const io::Range& range) {
  return CLI::Validator(
      [range](std::string& text) -> std::string {
        double value = 0;
        try {
          value = std::stod(text);
        } catch (...) {
          return {};
        }
        return range.Contains(value) ? std::string() : fmt::format("value {} out of range (must be {})", text, range.Describe());
      },
      range.Describe());
}

template <class Settings>
class OverrideFlags {
 public:
  /// `check_ranges` false leaves out-of-range values to the library that uses them (for a tool
  /// whose tests pin that library's message and exit code).
  void AddTo(CLI::App& app, bool check_ranges = true) {
    const Settings defaults{};
    Settings::Visit(defaults, [&](const io::Param& p, const auto& value) {
      if (!p.flag.empty()) Add(app, p, value, check_ranges);
    });
  }

  /// Whether the flag of the field named `name` was given.
  bool Given(std::string_view name) const {
    const auto it = slots_.find(std::string(name));
    return it != slots_.end() && it->second.option->count() > 0;
  }

  /// Replaces every field whose flag was given.
  void ApplyTo(Settings& settings) const {
    Settings::Visit(settings, [&](const io::Param& p, auto& field) {
      using T = std::decay_t<decltype(field)>;
      const auto it = slots_.find(std::string(p.name));
      if (it == slots_.end() || it->second.option->count() == 0) return;
      const auto& stored = *static_cast<const Stored<T>*>(it->second.value.get());
      if constexpr (io::NamedEnum<T>) io::ParseEnum(stored, field);
      else if constexpr (std::is_same_v<T, std::vector<std::string>>) field = SplitList(stored);
      else if constexpr (std::is_same_v<T, Vec3d>) field = ToVector(p, stored);
      else field = stored;
    });
  }

 private:
  // What CLI11 parses into: an enum's name, a list as one comma-separated word (so that it does not
  // swallow the positional arguments after it), a vector's numbers, else the field's own type.
  template <class T>
  using Stored = std::conditional_t<io::NamedEnum<T> || std::is_same_v<T, std::vector<std::string>>, std::string,
                                    std::conditional_t<std::is_same_v<T, Vec3d>, std::vector<double>, T>>;

  static Vec3d ToVector(const io::Param& p, const std::vector<double>& v) {
    if (v.size() == 3) return {v[0], v[1], v[2]};
    if (v.size() == 1 && p.scalar_or_vector) return Vec3d::Splat(v[0]);
    throw Error(ExitCode::kUsage, fmt::format("{} takes {}three numbers x,y,z", p.flag, p.scalar_or_vector ? "one number or " : ""));
  }

  static std::vector<std::string> SplitList(const std::string& text) {
    std::vector<std::string> items;
    for (std::size_t start = 0;;) {
      const std::size_t comma = text.find(',', start);
      items.push_back(text.substr(start, comma - start));
      if (comma == std::string::npos) return items;
      start = comma + 1;
    }
  }

  struct Slot {
    std::shared_ptr<void> value;
    CLI::Option* option = nullptr;
  };

  template <class T>
  static std::string Shown(const T& value) {
    if constexpr (io::NamedEnum<T>) return std::string(io::EnumName(value));
    else if constexpr (std::is_same_v<T, std::vector<std::string>>) return fmt::format("{}", fmt::join(value, ","));
    else if constexpr (std::is_same_v<T, Vec3d>) return fmt::format("{},{},{}", value.x, value.y, value.z);
    else return io::FormatValue(value);
  }

  template <class T>
  void Add(CLI::App& app, const io::Param& p, const T& default_value, bool check_ranges) {
    auto value = std::make_shared<Stored<T>>();
    const std::string unit = p.unit.empty() ? std::string() : fmt::format(" {}", p.unit);
    // A flag that only turns a field off ("!--no-velocity") says so after the field's meaning.
    const bool turns_off = p.flag.front() == '!';
    const std::string help = fmt::format("{} [{}{}{}]", p.help, Shown(default_value), unit, turns_off ? "; this flag turns it off" : "");
    CLI::Option* option = nullptr;
    if constexpr (std::is_same_v<T, bool>) {
      option = app.add_flag(std::string(p.flag), *value, help);
    } else if constexpr (io::NamedEnum<T>) {
      option = app.add_option(std::string(p.flag), *value, help)->check(CLI::IsMember(io::EnumNames<T>()));
    } else if constexpr (std::is_same_v<T, std::vector<std::string>>) {
      option = app.add_option(std::string(p.flag), *value, help)->type_name("A,B,...");
      const std::vector<std::string> choices(p.choices.begin(), p.choices.end());
      option->check(CLI::Validator(
          [choices](std::string& text) -> std::string {
            for (const std::string& item : SplitList(text))
              if (!choices.empty() && std::find(choices.begin(), choices.end(), item) == choices.end())
                return fmt::format("unknown value '{}' (expected {})", item, fmt::join(choices, ", "));
            return {};
          },
          ""));
    } else if constexpr (std::is_same_v<T, Vec3d>) {
      // 1 to 3 numbers for a field that also takes one: two get ToVector's message.
      option = app.add_option(std::string(p.flag), *value, help)->delimiter(',')->expected(p.scalar_or_vector ? 1 : 3, 3);
      option->type_name(p.scalar_or_vector ? "S|X,Y,Z" : "X,Y,Z");
      if (check_ranges && !p.range.IsAny()) option->check(RangeValidator(p.range));
    } else if constexpr (std::is_arithmetic_v<T> || std::is_same_v<T, std::string>) {
      option = app.add_option(std::string(p.flag), *value, help);
      if (check_ranges && !p.range.IsAny()) option->check(RangeValidator(p.range));
    } else {
      throw std::logic_error(fmt::format("{}: no command-line form for this field's type", p.flag));
    }
    slots_[std::string(p.name)] = Slot{std::move(value), option};
  }

  std::map<std::string, Slot> slots_;
};

}  // namespace rime::tool
