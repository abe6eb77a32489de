/// @file attributes.h
/// @brief How a group of per-particle arrays declares its attributes once, and the operations
/// every group gets from that one list: grow, reorder/compact, reset, write to and read from a
/// frame, and count bytes.
///
/// A group is a struct of DeviceArrays with a member `ForEach(f)` that calls `f(info, array)` for
/// each array, in the order the struct lists them. Every array of a group holds one value per
/// particle of the group, so the operations below never name an attribute.
///
/// @code
/// struct Example {
///   DeviceArray<Vec3<T>> x;
///   template <class F> void ForEach(F&& f) { f(AttributeInfo{.name = "", .names = Names::kXyz}, x); }
/// };
/// Grow(group, 10); Gather(device, group, order, count, pool); std::size_t b = Bytes(group);
/// @endcode
#pragma once

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <typeindex>
#include <utility>
#include <vector>

#include "rime/core/math.h"
#include "rime/exec/memory.h"
#include "rime/exec/parallel.h"
#include "rime/freeze/kernels.h"
#include "rime/io/particles.h"
#include "rime/sph/kernels.h"

namespace rime::sph {

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

/// Component access for the element types of attributes: scalars, Vec3 and symmetric 3x3.
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
template <class S>
struct Components<freeze::Sym6<S>> {
  using Scalar = S;
  static constexpr int kCount = 6;
  static Scalar Get(const freeze::Sym6<S>& v, int c) { return v.c[c]; }
  static void Set(freeze::Sym6<S>& v, int c, Scalar s) { v.c[c] = s; }
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
  explicit ScratchPool(const exec::Device& device) : device_(device) {}
  template <class V>
  exec::DeviceArray<V>& Get() {
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
    explicit Holder(const exec::Device& d) : array(d) {}
    std::size_t bytes() const override { return array.bytes(); }
    exec::DeviceArray<V> array;
  };
  exec::Device device_;
  std::map<std::type_index, std::unique_ptr<Base>> arrays_;
};

template <class V>
void Reorder(const exec::Device& device, exec::DeviceArray<V>& array, exec::DeviceArray<V>& scratch, const std::uint32_t* order, Index n) {
  scratch.resize(n);
  exec::ParallelFor(device, n, kernels::Gather<V>{array.data(), order, scratch.data()});
  array.swap(scratch);
}

template <class V>
void FillValue(const exec::Device& device, exec::DeviceArray<V>& array, std::size_t from, const V& value) {
  if (array.size() <= from) return;
  const std::vector<V> values(array.size() - from, value);
  exec::CopyToDevice(device, array.data() + from, values.data(), values.size() * sizeof(V));
}

/// The value `fill` stands for, as the element type V.
template <class V>
V FillOf(Fill fill, double rest_density) {
  if constexpr (std::is_arithmetic_v<V>) return fill == Fill::kRestDensity ? V(rest_density) : V(0);
  return V{};
}

/// Appends m particles to every array of the group, with the attribute's fill value.
template <class Group>
void Grow(const exec::Device& device, Group& group, std::size_t m, double rest_density) {
  group.ForEach([&](const AttributeInfo& a, auto& array) {
    using V = typename std::decay_t<decltype(array)>::value_type;
    const std::size_t n = array.size();
    array.resize(n + m);
    if (a.fill != Fill::kZero) FillValue(device, array, n, FillOf<V>(a.fill, rest_density));
  });
}

/// Resizes every array of the group to n particles, all with the attribute's fill value.
template <class Group>
void Reset(const exec::Device& device, Group& group, std::size_t n, double rest_density) {
  group.ForEach([&](const AttributeInfo& a, auto& array) {
    using V = typename std::decay_t<decltype(array)>::value_type;
    array.resize(n);
    array.SetZero();
    if (a.fill != Fill::kZero) FillValue(device, array, 0, FillOf<V>(a.fill, rest_density));
  });
}

/// Keeps the particles order[0..count) of the group, in that order.
template <class Group>
void Gather(const exec::Device& device, Group& group, const std::uint32_t* order, Index count, ScratchPool& pool) {
  group.ForEach([&](const AttributeInfo&, auto& array) {
    using V = typename std::decay_t<decltype(array)>::value_type;
    Reorder(device, array, pool.Get<V>(), order, count);
  });
}

template <class Group>
std::size_t Bytes(const Group& group) {
  std::size_t total = 0;
  group.ForEach([&](const AttributeInfo&, const auto& array) { total += array.bytes(); });
  return total;
}

/// Writes the checkpointed attributes of `group` into rows [first, first + group size) of `frame`,
/// whose datasets have `rows` entries; a dataset another group created keeps its values elsewhere,
/// a new one is filled with the attribute's fill value.
template <class Group>
void WriteRows(const Group& group, io::ParticleFrame& frame, std::size_t first, std::size_t rows, double rest_density) {
  group.ForEach([&](const AttributeInfo& a, const auto& array) {
    if (!a.checkpointed) return;
    using V = typename std::decay_t<decltype(array)>::value_type;
    using C = Components<V>;
    using S = typename C::Scalar;
    const std::vector<V> host = array.ToHost();
    for (int c = 0; c < C::kCount; ++c) {
      const std::string name = ColumnName(a, c, C::kCount);
      if (!frame.Has(name)) frame.Set(name, std::vector<S>(rows, FillOf<S>(a.fill, rest_density)));
      auto& column = std::get<std::vector<S>>(frame.attributes.at(name));
      for (std::size_t i = 0; i < host.size(); ++i) column[first + i] = C::Get(host[i], c);
    }
  });
}

/// Sets every checkpointed attribute of `group` from the frame rows `rows`, in that order.
template <class Group>
void ReadRows(Group& group, const io::ParticleFrame& frame, const std::vector<std::size_t>& rows) {
  group.ForEach([&](const AttributeInfo& a, auto& array) {
    if (!a.checkpointed) return;
    using V = typename std::decay_t<decltype(array)>::value_type;
    using C = Components<V>;
    using S = typename C::Scalar;
    std::vector<V> host(rows.size());
    for (int c = 0; c < C::kCount; ++c) {
      const std::vector<S>& column = frame.Get<S>(ColumnName(a, c, C::kCount));
      for (std::size_t i = 0; i < rows.size(); ++i) C::Set(host[i], c, column[rows[i]]);
    }
    array.assign(host);
  });
}

}  // namespace rime::sph
