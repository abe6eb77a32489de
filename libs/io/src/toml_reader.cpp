#include "rime/io/toml_reader.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <fmt/ranges.h>
#include <toml++/toml.h>

#include "rime/core/error.h"

namespace rime::io {

bool Range::Contains(double v) const {
  if (!std::isfinite(v)) return false;
  if (min_exclusive ? v <= min : v < min) return false;
  if (max_exclusive ? v >= max : v > max) return false;
  return true;
}

std::string Range::Describe() const {
  const bool has_min = min > -1e299, has_max = max < 1e299;
  if (has_min && has_max) return fmt::format("{}{}, {}{}", min_exclusive ? "(" : "[", min, max, max_exclusive ? ")" : "]");
  if (has_min) return fmt::format("{} {}", min_exclusive ? ">" : ">=", min);
  if (has_max) return fmt::format("{} {}", max_exclusive ? "<" : "<=", max);
  return "a finite number";
}

TomlReader::TomlReader(const toml::table& table, std::string file, std::string path)
    : table_(&table), file_(std::move(file)), path_(std::move(path)) {}

bool TomlReader::Has(const std::string& key) const { return table_->contains(key); }

const toml::node* TomlReader::Find(const std::string& key) {
  used_.insert(key);
  return table_->get(key);
}

std::string TomlReader::Where(const std::string& key) const {
  const toml::node* node = table_->get(key);
  const auto& source = node ? node->source() : table_->source();
  return source.begin.line > 0 ? fmt::format("{}:{}", file_, source.begin.line) : file_;
}

void TomlReader::Fail(const std::string& key, const std::string& message) const {
  throw InputError(message, Where(key) + ": " + FieldPath(key));
}

double TomlReader::Number(const std::string& key, double fallback, Range range) {
  const toml::node* node = Find(key);
  if (!node) return fallback;
  std::optional<double> value = node->value<double>();
  if (!value || !node->is_number()) Fail(key, "expected a number");
  if (!range.Contains(*value)) Fail(key, fmt::format("value {} out of range (must be {})", *value, range.Describe()));
  return *value;
}

std::int64_t TomlReader::Integer(const std::string& key, std::int64_t fallback, Range range) {
  const toml::node* node = Find(key);
  if (!node) return fallback;
  if (!node->is_integer()) Fail(key, "expected an integer");
  const std::int64_t value = *node->value<std::int64_t>();
  if (!range.Contains(double(value))) Fail(key, fmt::format("value {} out of range (must be {})", value, range.Describe()));
  return value;
}

bool TomlReader::Bool(const std::string& key, bool fallback) {
  const toml::node* node = Find(key);
  if (!node) return fallback;
  if (!node->is_boolean()) Fail(key, "expected true or false");
  return *node->value<bool>();
}

std::string TomlReader::String(const std::string& key, const std::string& fallback, const std::vector<std::string>& allowed) {
  const toml::node* node = Find(key);
  if (!node) return fallback;
  if (!node->is_string()) Fail(key, "expected a string");
  std::string value = *node->value<std::string>();
  if (!allowed.empty() && std::find(allowed.begin(), allowed.end(), value) == allowed.end())
    Fail(key, fmt::format("unknown value '{}' (expected one of: {})", value, fmt::join(allowed, ", ")));
  return value;
}

Vec3d TomlReader::Vector(const std::string& key, const Vec3d& fallback, Range range) {
  const toml::node* node = Find(key);
  if (!node) return fallback;
  const toml::array* array = node->as_array();
  if (!array || array->size() != 3) Fail(key, "expected an array of 3 numbers, e.g. [0.0, 0.0, 1.0]");
  Vec3d v;
  for (int a = 0; a < 3; ++a) {
    const auto x = (*array)[a].value<double>();
    if (!x || !(*array)[a].is_number()) Fail(key, "expected an array of 3 numbers");
    if (!range.Contains(*x)) Fail(key, fmt::format("component {} out of range (must be {})", *x, range.Describe()));
    v[a] = *x;
  }
  return v;
}

Vec3d TomlReader::ScalarOrVector(const std::string& key, const Vec3d& fallback, Range range) {
  const toml::node* node = table_->get(key);
  if (node && node->is_number()) {
    const double v = Number(key, 0, range);
    return {v, v, v};
  }
  return Vector(key, fallback, range);
}

std::vector<std::string> TomlReader::StringList(const std::string& key, const std::vector<std::string>& allowed) {
  const toml::node* node = Find(key);
  if (!node) return {};
  const toml::array* array = node->as_array();
  if (!array) Fail(key, "expected an array of strings");
  std::vector<std::string> out;
  for (const auto& item : *array) {
    const auto s = item.value<std::string>();
    if (!s || !item.is_string()) Fail(key, "expected an array of strings");
    if (!allowed.empty() && std::find(allowed.begin(), allowed.end(), *s) == allowed.end())
      Fail(key, fmt::format("unknown name '{}' (expected one of: {})", *s, fmt::join(allowed, ", ")));
    out.push_back(*s);
  }
  return out;
}

TomlReader TomlReader::Table(const std::string& key) {
  static const toml::table kEmpty;
  const toml::node* node = Find(key);
  if (!node) return TomlReader(kEmpty, file_, FieldPath(key));
  if (!node->is_table()) Fail(key, "expected a table");
  return TomlReader(*node->as_table(), file_, FieldPath(key));
}

std::vector<TomlReader> TomlReader::TableArray(const std::string& key) {
  const toml::node* node = Find(key);
  std::vector<TomlReader> out;
  if (!node) return out;
  const toml::array* array = node->as_array();
  if (!array) Fail(key, fmt::format("expected an array of tables ([[{}]])", key));
  for (std::size_t k = 0; k < array->size(); ++k) {
    const toml::table* t = (*array)[k].as_table();
    if (!t) Fail(key, fmt::format("expected an array of tables ([[{}]])", key));
    out.emplace_back(*t, file_, fmt::format("{}[{}]", FieldPath(key), k));
  }
  return out;
}

void TomlReader::RejectUnknownKeys() const {
  for (const auto& [key, node] : *table_) {
    const std::string name(key.str());
    if (!used_.count(name)) {
      const auto line = node.source().begin.line;
      throw InputError(fmt::format("unknown key '{}' (misspelled?)", name),
                       fmt::format("{}:{}: {}", file_, line, FieldPath(name)));
    }
  }
}

}  // namespace rime::io
