/// @file frame_rows.h
/// @brief Attribute groups (rime/exec/attributes.h) to and from the datasets of a particle frame:
/// each checkpointed attribute is one dataset per component, named by ColumnName. Private to libs/sph.
#pragma once

#include <string>
#include <vector>

#include "rime/exec/attributes.h"
#include "rime/freeze/freezing.h"
#include "rime/io/particles.h"

namespace rime::sph {

using exec::AttributeInfo;
using exec::ColumnName;
using exec::Components;
using exec::Fill;
using exec::FillOf;

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
