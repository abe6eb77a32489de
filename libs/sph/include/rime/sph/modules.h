/// @file modules.h
/// @brief The registry of physics modules a scene turned on, the per-particle attributes they
/// allocated and the kernels they launched: a module that is off allocates and runs nothing.
#pragma once

#include <cstdint>
#include <map>
#include <set>
#include <string>

namespace rime::sph {

class ModuleRegistry {
 public:
  void Enable(const std::string& module) { enabled_.insert(module); }
  bool Enabled(const std::string& module) const { return enabled_.count(module) != 0; }
  const std::set<std::string>& enabled() const { return enabled_; }

  /// Records that `module` owns the per-particle attribute `attribute` (done by each attribute group
  /// as it is allocated, src/state.h).
  void RecordAttribute(const std::string& module, const std::string& attribute) { attributes_[attribute] = module; }
  bool HasAttribute(const std::string& attribute) const { return attributes_.count(attribute) != 0; }
  const std::map<std::string, std::string>& attributes() const { return attributes_; }

  /// Counts one kernel launch of `module`.
  void CountLaunch(const std::string& module) { ++launches_[module]; }
  std::int64_t Launches(const std::string& module) const {
    const auto it = launches_.find(module);
    return it == launches_.end() ? 0 : it->second;
  }

 private:
  std::set<std::string> enabled_;
  std::map<std::string, std::string> attributes_;
  std::map<std::string, std::int64_t> launches_;
};

}  // namespace rime::sph
