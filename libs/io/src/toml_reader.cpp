#include "rime/io/toml_reader.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <regex>
#include <vector>
#include <fmt/ranges.h>
#include <toml++/toml.h>

#include "rime/core/error.h"

namespace rime::io {
namespace {
bool IsBlankChar(char c) { return c == ' ' || c == '\t' || c == '\r'; }
}  // namespace

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

void CheckTomlLimits(std::string_view text, const std::string& file) {
  // Depths are upper bounds of what the parser would build: every bracket, header segment and
  // dotted-key segment counts as one level; strings and comments are skipped.
  struct Open {
    char kind;  // '[' array, '{' inline table
    int depth;  // depth of what it holds
  };
  std::vector<Open> open;
  const std::size_t n = text.size();
  std::size_t line = 1;
  int table_depth = 0;     // depth of the current [table] or [[array]]
  std::string table_name;  // its name, for messages
  bool in_key = true;      // reading a key: at a statement start, after '{', or after ',' in an inline table
  int key_segments = 0;    // dots read in the current key
  int value_depth = 0;     // depth of the value being read
  std::string key;         // the current key as written, for messages
  const auto fail = [&](const std::string& what, std::size_t at_line) {
    const std::string field = table_name.empty() ? key : (key.empty() ? table_name : table_name + "." + key);
    throw InputError(what, fmt::format("{}:{}: {}", file, at_line, field.empty() ? "(top level)" : field));
  };
  const auto check_depth = [&](int depth) {
    if (depth > kMaxTomlDepth) fail(fmt::format("tables or arrays nested deeper than {} levels", kMaxTomlDepth), line);
  };
  const auto base = [&] { return open.empty() ? table_depth : open.back().depth; };
  const auto start_key = [&] {
    in_key = true;
    key_segments = 0;
    key.clear();
  };
  // Skips the string starting at text[i]; returns the index of its last character (or of the
  // character before an unterminated single-line string's newline, which the main loop counts).
  const auto skip_string = [&](std::size_t i) {
    const char quote = text[i];
    const bool basic = quote == '"';
    const bool multi = i + 2 < n && text[i + 1] == quote && text[i + 2] == quote;
    const std::size_t first_line = line;
    std::size_t j = i + (multi ? 3 : 1);
    const std::size_t start = j;
    for (; j < n; ++j) {
      const char c = text[j];
      if (basic && c == '\\') {
        if (++j < n && text[j] == '\n') ++line;
        continue;
      }
      if (c == '\n') {
        if (!multi) break;
        ++line;
        continue;
      }
      if (c == quote && (!multi || (j + 2 < n && text[j + 1] == quote && text[j + 2] == quote))) break;
    }
    if (j - start > kMaxTomlString)
      fail(fmt::format("string of {} bytes, longer than the limit of {} bytes", j - start, kMaxTomlString), first_line);
    if (j >= n) return n - 1;
    if (text[j] == '\n') return j - 1;
    if (multi) {
      j += 2;
      for (int extra = 0; extra < 2 && j + 1 < n && text[j + 1] == quote; ++extra) ++j;  // """a"""" holds a"
    }
    return j;
  };

  for (std::size_t i = 0; i < n; ++i) {
    const char c = text[i];
    if (c == '\n') {
      ++line;
      if (open.empty()) start_key();
      continue;
    }
    if (c == '#') {
      const std::size_t eol = text.find('\n', i);
      if (eol == std::string_view::npos) break;
      i = eol - 1;
      continue;
    }
    if (c == '"' || c == '\'') {
      const std::size_t end = skip_string(i);
      if (in_key) key.append(text.substr(i, end + 1 - i));
      i = end;
      continue;
    }
    if (in_key) {
      if (c == '[' && open.empty() && key.empty()) {  // [table] or [[array of tables]]
        const bool array = i + 1 < n && text[i + 1] == '[';
        table_name.clear();
        key.clear();
        table_depth = array ? 2 : 1;
        for (i += array ? 2 : 1; i < n && text[i] != ']' && text[i] != '\n'; ++i) {
          if (text[i] == '"' || text[i] == '\'') {
            const std::size_t end = skip_string(i);
            table_name.append(text.substr(i, end + 1 - i));
            i = end;
            continue;
          }
          if (text[i] == '.') check_depth(++table_depth);
          if (!IsBlankChar(text[i])) table_name += text[i];
        }
        if (i < n && text[i] == '\n') --i;
        else if (array && i + 1 < n && text[i + 1] == ']') ++i;
        in_key = false;
        continue;
      }
      if (c == '.') check_depth(base() + ++key_segments + 1);
      if (c == '=') {
        in_key = false;
        value_depth = base() + key_segments + 1;
        continue;
      }
      if (c == '}' && !open.empty()) {  // an empty inline table, or a trailing comma
        open.pop_back();
        in_key = false;
        continue;
      }
      if (!IsBlankChar(c)) key += c;
      continue;
    }
    if (c == '[') {
      open.push_back({'[', ++value_depth});
      check_depth(value_depth);
    } else if (c == '{') {
      open.push_back({'{', value_depth});
      check_depth(value_depth);
      start_key();
    } else if (c == ']' || c == '}') {
      if (!open.empty()) open.pop_back();
      if (!open.empty() && open.back().kind == '[') value_depth = open.back().depth;
    } else if (c == ',' && !open.empty() && open.back().kind == '{') {
      start_key();
    }
  }
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

void TomlReader::CheckPattern(const std::string& key, const std::string& value, std::string_view pattern, std::string_view accepted) const {
  if (!std::regex_match(value, std::regex(pattern.begin(), pattern.end()))) Fail(key, fmt::format("'{}' is not {}", value, accepted));
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
      throw InputError(fmt::format("unknown key '{}' (misspelled?)", name), fmt::format("{}:{}: {}", file_, line, FieldPath(name)));
    }
  }
}

}  // namespace rime::io
