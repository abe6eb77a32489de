/// @file attributes.h
/// @brief How a group of per-particle arrays declares its attributes once, and the operations
/// every group gets from that one list: grow, reorder/compact, reset and count bytes (the solver
/// writes and reads frames from the same list, libs/sph/src/frame_rows.h).
///
/// A group is a struct of DeviceArrays deriving from AttributeGroup, whose static `Visit(group, f)`
/// calls `f(info, array)` for each array, in the order the struct lists them. Every array of a group holds one value per
/// particle of the group, so the operations below never name an attribute.
///
/// @code
/// struct Example : AttributeGroup<Example> {
///   DeviceArray<Vec3<float>> x;
///   template <class Self, class F>
///   static void Visit(Self& s, F& f) { f(AttributeInfo{.name = "", .names = Names::kXyz}, s.x); }
/// };
/// GrowGroup(device, group, 10, rho0); GatherGroup(device, group, order, count, pool); GroupBytes(group);
/// @endcode
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <type_traits>
#include <typeindex>
#include <utility>
#include <vector>

#include "rime/core/math.h"
#include "rime/exec/kernels.h"
#include "rime/exec/memory.h"
#include "rime/exec/parallel.h"

namespace rime::exec {

/// How the components of a vector attribute are named in frames.
enum class Names : std::uint8_t {
  kIndexed,  // name_0, name_1, ...
  kXyz,      // name + x, y, z (H5Part's positions "x y z", velocities "vx vy vz")
};

/// The value of a particle that does not (yet) have the attribute: new particles, and frame rows of
/// another group.
enum class Fill : std::uint8_t { kZero, kRestDensity };

struct AttributeInfo {
  const char* name = "";      // dataset name in frames (and in the module registry)
  bool checkpointed = false;  // written to frames and read back on resume
  Names names = Names::kIndexed;
  Fill fill = Fill::kZero;
};

/// Gives a group its ForEach, for mutable and const groups alike, from the group's one list: its
/// static Visit(group, f).
template <class Group>
struct AttributeGroup {
  template <class F>
  void ForEach(F&& f) {
    Group::Visit(static_cast<Group&>(*this), f);
  }
  template <class F>
  void ForEach(F&& f) const {
    Group::Visit(static_cast<const Group&>(*this), f);
  }
};

/// Component access for the element types of attributes: scalars and Vec3 here; a library with its
/// own element type specialises it next to that type.
template <class V>
struct Components {
  using Scalar = V;
  static constexpr int kCount = 1;
  static Scalar Get(const V& v, int) { return v; }
  static void Set(V& v, int, Scalar s) { v = s; }
};
template <class S>
struct Components<Vec3<S>> {
  using Scalar = S;
  static constexpr int kCount = 3;
  static Scalar Get(const Vec3<S>& v, int c) { return v[c]; }
  static void Set(Vec3<S>& v, int c, Scalar s) { v[c] = s; }
};
/// Dataset name of component c of an attribute with `count` components.
inline std::string ColumnName(const AttributeInfo& a, int c, int count) {
  if (count == 1) return a.name;
  if (a.names == Names::kXyz) return std::string(a.name) + "xyz"[c];
  return std::string(a.name) + "_" + std::to_string(c);
}

/// Reorder buffers, one per element type, reused from step to step.
class ScratchPool {
 public:
  explicit ScratchPool(const Device& device) : device_(device) {}
  template <class V>
  DeviceArray<V>& Get() {
    std::unique_ptr<Base>& slot = arrays_[std::type_index(typeid(V))];
    if (!slot) slot = std::make_unique<Holder<V>>(device_);
    return static_cast<Holder<V>&>(*slot).array;
  }
  std::size_t bytes() const {
    std::size_t total = 0;
    for (const auto& [type, holder] : arrays_) total += holder->bytes();
    return total;
  }

 private:
  struct Base {
    virtual ~Base() = default;
    virtual std::size_t bytes() const = 0;
  };
  template <class V>
  struct Holder : Base {
    explicit Holder(const Device& d) : array(d) {}
    std::size_t bytes() const override { return array.bytes(); }
    DeviceArray<V> array;
  };
  Device device_;
  std::map<std::type_index, std::unique_ptr<Base>> arrays_;
};

template <class V>
void Reorder(const Device& device, DeviceArray<V>& array, DeviceArray<V>& scratch, const std::uint32_t* order, Index n) {
  scratch.resize(n);
  ParallelFor(device, n, Gather<V>{array.data(), order, scratch.data()});
  array.swap(scratch);
}

template <class V>
void FillValue(const Device& device, DeviceArray<V>& array, std::size_t from, const V& value) {
  if (array.size() <= from) return;
  const std::vector<V> values(array.size() - from, value);
  CopyToDevice(device, array.data() + from, values.data(), values.size() * sizeof(V));
}

/// The value `fill` stands for, as the element type V.
template <class V>
V FillOf(Fill fill, double rest_density) {
  if constexpr (std::is_arithmetic_v<V>) return fill == Fill::kRestDensity ? V(rest_density) : V(0);
  return V{};
}

/// Appends m particles to every array of the group, with the attribute's fill value.
template <class Group>
void GrowGroup(const Device& device, Group& group, std::size_t m, double rest_density) {
  group.ForEach([&](const AttributeInfo& a, auto& array) {
    using V = typename std::decay_t<decltype(array)>::value_type;
    const std::size_t n = array.size();
    array.resize(n + m);
    if (a.fill != Fill::kZero) FillValue(device, array, n, FillOf<V>(a.fill, rest_density));
  });
}

/// Resizes every array of the group to n particles, all with the attribute's fill value.
template <class Group>
void ResetGroup(const Device& device, Group& group, std::size_t n, double rest_density) {
  group.ForEach([&](const AttributeInfo& a, auto& array) {
    using V = typename std::decay_t<decltype(array)>::value_type;
    array.resize(n);
    array.SetZero();
    if (a.fill != Fill::kZero) FillValue(device, array, 0, FillOf<V>(a.fill, rest_density));
  });
}

/// Keeps the particles order[0..count) of the group, in that order.
template <class Group>
void GatherGroup(const Device& device, Group& group, const std::uint32_t* order, Index count, ScratchPool& pool) {
  group.ForEach([&](const AttributeInfo&, auto& array) {
    using V = typename std::decay_t<decltype(array)>::value_type;
    Reorder(device, array, pool.Get<V>(), order, count);
  });
}

template <class Group>
std::size_t GroupBytes(const Group& group) {
  std::size_t total = 0;
  group.ForEach([&](const AttributeInfo&, const auto& array) { total += array.bytes(); });
  return total;
}

/// Indices i < n with flags[i] != 0, in increasing order; returns their count.
inline Index ListFlagged(const Device& device, const DeviceArray<std::uint32_t>& flags, Index n, DeviceArray<std::uint32_t>& slot,
                         DeviceArray<std::uint32_t>& list) {
  slot.resize(n);
  const Index count = static_cast<Index>(ExclusiveScan(device, flags.data(), slot.data(), n));
  list.resize(count);
  if (count) ParallelFor(device, n, CompactionOrder{flags.data(), slot.data(), list.data()});
  return count;
}

/// Copies `values` into `array` from element `first` on.
template <class V>
void CopyTail(const Device& device, DeviceArray<V>& array, std::size_t first, const std::vector<V>& values) {
  if (!values.empty()) CopyToDevice(device, array.data() + first, values.data(), values.size() * sizeof(V));
}

}  // namespace rime::exec
