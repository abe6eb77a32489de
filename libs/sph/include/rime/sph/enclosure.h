/// @file enclosure.h
/// @brief Which points lie inside closed solids, from the solids' boundary particles alone: water
/// placed there would be simulated inside the object, where the single-layer walls hold it.
#pragma once

#include <cstdint>
#include <vector>

#include "rime/core/math.h"

namespace rime::sph {

/// A voxel grid over the solids' bounding box (padded) whose cells are marked wall (holding a
/// boundary particle), outside (reached from the grid's border by a 6-connected flood fill through
/// non-wall cells) or enclosed (neither). A surface sampled at spacing s occupies a 26-connected
/// layer of cells of size ≥ s, which a 6-connected fill cannot cross, so open containers stay
/// open and only closed surfaces enclose cells. A closed surface may be a solid or a sealed tank:
/// each enclosed region is a tank when the normals of the wall particles bordering it point into
/// it (containers face inward), a solid otherwise or when the particles carry no normals.
class Enclosure {
 public:
  /// `normals`: one per boundary particle, or empty; zero vectors do not vote. `spacing`: the
  /// boundary sampling spacing; cells are at least this large (coarser when the grid would exceed
  /// `max_cells`, which keeps surfaces closed but may miss thin cavities).
  Enclosure(const std::vector<Vec3d>& boundary, const std::vector<Vec3d>& normals, double spacing, std::int64_t max_cells = 32 << 20);
  /// True when p lies in an enclosed cell (inside a closed solid). Points outside the grid, and in
  /// wall cells, are not enclosed: those near walls are the proximity test's business.
  bool Inside(const Vec3d& p) const;
  std::int64_t enclosed_cells() const { return enclosed_; }

 private:
  enum : std::uint8_t { kEnclosed = 0, kWall = 1, kOutside = 2, kTank = 3 };
  std::int64_t Cell(const Vec3d& p) const;
  Vec3d CellCenter(std::int64_t c) const;
  template <class F>
  void ForEachFaceNeighbor(std::int64_t c, F f) const;  // the up to 6 cells sharing a face with c
  // 6-connected fill from `seed` through cells in state `from`, setting them to `to`; calls
  // visit(cell) for each.
  template <class Visit>
  void Fill(std::int64_t seed, std::uint8_t from, std::uint8_t to, Visit visit);
  Vec3d origin_;
  double cell_ = 1;
  std::int64_t nx_ = 0, ny_ = 0, nz_ = 0, enclosed_ = 0;
  std::vector<std::uint8_t> state_;
};

}  // namespace rime::sph
