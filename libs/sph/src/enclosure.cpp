#include "rime/sph/enclosure.h"

#include <algorithm>
#include <cmath>

namespace rime::sph {

template <class F>
void Enclosure::ForEachFaceNeighbor(std::int64_t c, F f) const {
  const std::int64_t strides[3] = {1, nx_, nx_ * ny_}, size[3] = {nx_, ny_, nz_};
  const std::int64_t coord[3] = {c % nx_, (c / nx_) % ny_, c / (nx_ * ny_)};
  for (int axis = 0; axis < 3; ++axis)
    for (int step : {-1, 1}) {
      const std::int64_t k = coord[axis] + step;
      if (k >= 0 && k < size[axis]) f(c + step * strides[axis]);
    }
}

template <class Visit>
void Enclosure::Fill(std::int64_t seed, std::uint8_t from, std::uint8_t to, Visit visit) {
  std::vector<std::int64_t> stack{seed};
  state_[std::size_t(seed)] = to;
  while (!stack.empty()) {
    const std::int64_t c = stack.back();
    stack.pop_back();
    visit(c);
    ForEachFaceNeighbor(c, [&](std::int64_t n) {
      if (state_[std::size_t(n)] != from) return;
      state_[std::size_t(n)] = to;
      stack.push_back(n);
    });
  }
}

Enclosure::Enclosure(const std::vector<Vec3d>& boundary, const std::vector<Vec3d>& normals, double spacing, std::int64_t max_cells) {
  if (boundary.empty()) return;
  Vec3d lo = boundary.front(), hi = boundary.front();
  for (const Vec3d& p : boundary) lo = Min(lo, p), hi = Max(hi, p);
  cell_ = spacing;
  const Vec3d extent = hi - lo;
  // Two padding cells on each side, so that the border is outside every solid.
  auto cells = [&](double c) {
    return (std::int64_t(extent.x / c) + 5) * (std::int64_t(extent.y / c) + 5) * (std::int64_t(extent.z / c) + 5);
  };
  while (cells(cell_) > max_cells) cell_ *= 1.25;
  origin_ = lo - Vec3d(2 * cell_, 2 * cell_, 2 * cell_);
  nx_ = std::int64_t(extent.x / cell_) + 5, ny_ = std::int64_t(extent.y / cell_) + 5, nz_ = std::int64_t(extent.z / cell_) + 5;
  state_.assign(std::size_t(nx_ * ny_ * nz_), kEnclosed);
  for (const Vec3d& p : boundary) state_[std::size_t(Cell(p))] = kWall;
  Fill(0, kEnclosed, kOutside, [](std::int64_t) {});
  enclosed_ = std::count(state_.begin(), state_.end(), std::uint8_t(kEnclosed));
  if (enclosed_ == 0 || normals.size() != boundary.size()) return;

  // Label the enclosed regions, then let the bordering wall particles vote: normal towards the
  // region's cell = the region is a tank's inside.
  std::vector<std::int32_t> region(state_.size(), -1);
  std::int32_t regions = 0;
  for (std::int64_t c = 0; c < std::int64_t(state_.size()); ++c)
    if (state_[std::size_t(c)] == kEnclosed && region[std::size_t(c)] < 0) {
      const std::int32_t r = regions++;
      // Temporarily mark as kTank while labelling; restored below.
      Fill(c, kEnclosed, kTank, [&](std::int64_t cell) { region[std::size_t(cell)] = r; });
    }
  std::vector<double> vote(std::size_t(regions), 0.0);
  for (std::size_t b = 0; b < boundary.size(); ++b) {
    if (Dot(normals[b], normals[b]) == 0) continue;
    ForEachFaceNeighbor(Cell(boundary[b]), [&](std::int64_t n) {
      const std::int32_t r = region[std::size_t(n)];
      if (r >= 0) vote[std::size_t(r)] += Dot(normals[b], CellCenter(n) - boundary[b]) > 0 ? 1 : -1;
    });
  }
  enclosed_ = 0;
  for (std::size_t c = 0; c < state_.size(); ++c)
    if (region[c] >= 0) {
      const bool tank = vote[std::size_t(region[c])] > 0;
      state_[c] = tank ? kTank : kEnclosed;
      enclosed_ += tank ? 0 : 1;
    }
}

std::int64_t Enclosure::Cell(const Vec3d& p) const {
  const Vec3d q = (p - origin_) / cell_;
  const std::int64_t i = std::clamp<std::int64_t>(std::int64_t(std::floor(q.x)), 0, nx_ - 1);
  const std::int64_t j = std::clamp<std::int64_t>(std::int64_t(std::floor(q.y)), 0, ny_ - 1);
  const std::int64_t k = std::clamp<std::int64_t>(std::int64_t(std::floor(q.z)), 0, nz_ - 1);
  return i + nx_ * (j + ny_ * k);
}

Vec3d Enclosure::CellCenter(std::int64_t c) const {
  return origin_ + Vec3d(double(c % nx_) + 0.5, double((c / nx_) % ny_) + 0.5, double(c / (nx_ * ny_)) + 0.5) * cell_;
}

bool Enclosure::Inside(const Vec3d& p) const {
  if (state_.empty() || enclosed_ == 0) return false;
  const Vec3d q = (p - origin_) / cell_;
  if (q.x < 0 || q.y < 0 || q.z < 0 || q.x >= double(nx_) || q.y >= double(ny_) || q.z >= double(nz_)) return false;
  return state_[std::size_t(Cell(p))] == kEnclosed;
}

}  // namespace rime::sph
