// Sparse, parallel rasterization of the surface field into an OpenVDB narrow-band level set.
//
// Particles are binned by the 8³ OpenVDB leaf their centre lies in. Every leaf that some particle
// can reach is then filled independently (no locks, no atomics): it gathers the particles binned in
// the (2K+1)³ surrounding leaves and evaluates their ellipsoid distance (or kernel sum) on its own
// 512-voxel buffer. Only leaves near particles exist, so memory follows the particles, not the
// bounding box. The union of small ellipsoids is a distance only outside and near the surface;
// interior depth comes from erosions of the inside mask (chessboard layers), and voxels deeper
// than the band become inactive −background tiles: a proper narrow band on both sides.
#include <openvdb/openvdb.h>
#include <openvdb/tools/LevelSetFilter.h>
#include <openvdb/tools/LevelSetRebuild.h>
#include <openvdb/tools/LevelSetUtil.h>
#include <openvdb/tools/Morphology.h>
#include <openvdb/tools/Prune.h>
#include <openvdb/tree/LeafManager.h>
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <fmt/format.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif

#include <algorithm>
#include <chrono>
#include <cmath>
#include <mutex>
#include <unordered_map>

#include "grids.h"
#include "rime/core/error.h"
#include "rime/core/log.h"
#include "rime/exec/parallel.h"

namespace rime::surface {

std::vector<Vec3f> InterpolateVelocities(const ParticleSet& particles, const std::vector<Vec3f>& points);

namespace {

using Clock = std::chrono::steady_clock;
double Seconds(Clock::time_point since) { return std::chrono::duration<double>(Clock::now() - since).count(); }

constexpr int kLeafDim = 8;
constexpr std::int64_t kKeyBias = 1 << 20;

std::uint64_t LeafKey(std::int64_t lx, std::int64_t ly, std::int64_t lz) {
  return std::uint64_t(lx + kKeyBias) << 42 | std::uint64_t(ly + kKeyBias) << 21 | std::uint64_t(lz + kKeyBias);
}
void KeyToLeaf(std::uint64_t key, std::int64_t& lx, std::int64_t& ly, std::int64_t& lz) {
  const std::uint64_t mask = (1ULL << 21) - 1;
  lx = std::int64_t(key >> 42 & mask) - kKeyBias;
  ly = std::int64_t(key >> 21 & mask) - kKeyBias;
  lz = std::int64_t(key & mask) - kKeyBias;
}
std::int64_t FloorDiv(double v) { return std::int64_t(std::floor(v / kLeafDim)); }

/// Which leaves exist and which particles each one must visit.
struct Plan {
  double dx = 0;
  openvdb::Coord offset;                 // global index of local voxel (0,0,0); a multiple of 8
  std::vector<Vec3f> u;                  // particle centres in local voxel coordinates
  std::vector<float> reach;              // voxels: beyond this a particle cannot change a voxel
  std::vector<std::uint32_t> sorted;     // particle indices grouped by leaf
  std::vector<std::uint32_t> bin_start;  // per occupied leaf, into sorted (size bins + 1)
  std::unordered_map<std::uint64_t, std::uint32_t> bin_of_key;
  std::vector<std::uint64_t> targets;  // leaves to evaluate
  int K = 1;                           // neighbourhood radius in leaves
};

Plan MakePlan(const std::vector<Vec3d>& world_centers, const std::vector<float>& reach, double dx) {
  Plan plan;
  plan.dx = dx;
  const std::size_t n = world_centers.size();
  Vec3d lo = world_centers[0], hi = lo;
  for (const Vec3d& p : world_centers) lo = Min(lo, p), hi = Max(hi, p);
  float max_reach = 0;
  for (float r : reach) max_reach = std::max(max_reach, r);
  const double cells = std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z}) / dx + 2 * max_reach;
  if (!(cells < double(kKeyBias) * kLeafDim / 2) || !std::isfinite(cells))
    throw InputError(fmt::format("voxel size {:.4g} m is too small for a particle cloud {:.4g} m wide ({:.3g} voxels)", dx,
                                 std::max({hi.x - lo.x, hi.y - lo.y, hi.z - lo.z}), cells),
                     "voxel size");
  if (max_reach > 100)
    throw InputError(fmt::format("voxel size {:.4g} m is too small for the particle size: a particle would reach {:.0f} "
                                 "voxels (at most 100; use a coarser voxel size)",
                                 dx, max_reach),
                     "voxel size");
  const auto leaf_floor = [](double v) { return std::floor(v / kLeafDim) * kLeafDim; };
  plan.offset = openvdb::Coord(int(leaf_floor(std::floor(lo.x / dx))), int(leaf_floor(std::floor(lo.y / dx))),
                               int(leaf_floor(std::floor(lo.z / dx))));
  const Vec3d base(plan.offset.x() * dx, plan.offset.y() * dx, plan.offset.z() * dx);
  plan.u.resize(n);
  plan.reach = reach;
  std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed(n);
  exec::cpu::ParallelFor(Index(n), [&](Index i) {
    const Vec3d u = (world_centers[i] - base) / dx;
    plan.u[i] = Vec3f(u);
    keyed[i] = {LeafKey(FloorDiv(u.x), FloorDiv(u.y), FloorDiv(u.z)), std::uint32_t(i)};
  });
  tbb::parallel_sort(keyed.begin(), keyed.end());
  plan.sorted.resize(n);
  std::vector<std::uint64_t> bins;
  for (std::size_t s = 0; s < n; ++s) {
    plan.sorted[s] = keyed[s].second;
    if (s == 0 || keyed[s].first != keyed[s - 1].first) {
      plan.bin_of_key.emplace(keyed[s].first, std::uint32_t(bins.size()));
      bins.push_back(keyed[s].first);
      plan.bin_start.push_back(std::uint32_t(s));
    }
  }
  plan.bin_start.push_back(std::uint32_t(n));
  plan.K = std::max(1, int(std::ceil(max_reach / kLeafDim)));
  // Leaves some particle reaches: each particle's box, in leaves.
  std::vector<std::uint64_t> targets;
  targets.reserve(bins.size() * 8);
  for (std::size_t b = 0; b < bins.size(); ++b) {
    float r = 0;
    Vec3f blo = plan.u[plan.sorted[plan.bin_start[b]]], bhi = blo;
    for (std::uint32_t s = plan.bin_start[b]; s < plan.bin_start[b + 1]; ++s) {
      const std::uint32_t i = plan.sorted[s];
      r = std::max(r, plan.reach[i]);
      blo = Min(blo, plan.u[i]), bhi = Max(bhi, plan.u[i]);
    }
    for (std::int64_t lx = FloorDiv(blo.x - r); lx <= FloorDiv(bhi.x + r); ++lx)
      for (std::int64_t ly = FloorDiv(blo.y - r); ly <= FloorDiv(bhi.y + r); ++ly)
        for (std::int64_t lz = FloorDiv(blo.z - r); lz <= FloorDiv(bhi.z + r); ++lz) targets.push_back(LeafKey(lx, ly, lz));
  }
  tbb::parallel_sort(targets.begin(), targets.end());
  targets.erase(std::unique(targets.begin(), targets.end()), targets.end());
  plan.targets = std::move(targets);
  return plan;
}

/// Everything the per-leaf evaluation reads, in local voxel units.
struct FieldInputs {
  Field field = Field::kEllipsoids;
  float rho = 0;                            // ellipsoid level r_iso / Δx
  float band = 3;                           // half band, voxels
  const std::array<float, 6>* D = nullptr;  // per particle (null: isotropic)
  const float* min_stretch = nullptr;
  float inv_h = 0;   // kernel sum: 1 / h in voxels
  float volume = 0;  // kernel sum: V / Δx³
  float iso = 0.5f;
  bool track_nearest = false;
  const std::uint8_t* interior = nullptr;  // per particle: fully surrounded (Prepare); null: no DeepLeaves
};

// Leaves that lie deep inside: the leaf and its 26 neighbour leaves all hold particles, and every
// one of those particles is fully surrounded. The nearest particle that is not surrounded (and so
// any exterior) is then at least one leaf (8 voxels, 4 spacings at voxel = d_p/2) away, farther
// than the band, so every voxel of the leaf would end as an inactive −background interior voxel.
// Evaluating the field there (most of a solid body's leaves) is skipped. Inside a closed body the
// only difference can be an enclosed bubble in the level set, which the void removal (keep_voids
// off, the only mode this is used in) drops from level set and mesh anyway.
std::vector<std::uint8_t> DeepLeaves(const Plan& plan, const FieldInputs& in) {
  std::vector<std::uint8_t> deep(plan.targets.size(), 0);
  if (!in.interior) return deep;
  const std::size_t bins = plan.bin_start.size() - 1;
  std::vector<std::uint8_t> surrounded(bins);
  exec::cpu::ParallelFor(Index(bins), [&](Index b) {
    bool all = true;
    for (std::uint32_t s = plan.bin_start[b]; s < plan.bin_start[b + 1] && all; ++s) all = in.interior[plan.sorted[s]] != 0;
    surrounded[b] = all;
  });
  exec::cpu::ParallelFor(Index(plan.targets.size()), [&](Index t) {
    std::int64_t lx, ly, lz;
    KeyToLeaf(plan.targets[t], lx, ly, lz);
    bool all = true;
    for (int ox = -1; ox <= 1 && all; ++ox)
      for (int oy = -1; oy <= 1 && all; ++oy)
        for (int oz = -1; oz <= 1 && all; ++oz) {
          const auto it = plan.bin_of_key.find(LeafKey(lx + ox, ly + oy, lz + oz));
          all = it != plan.bin_of_key.end() && surrounded[it->second];
        }
    deep[t] = all;
  });
  return deep;
}

struct SymMat {
  float xx, yy, zz, xy, xz, yz;
};
SymMat Square(const SymMat& d) {
  return {d.xx * d.xx + d.xy * d.xy + d.xz * d.xz, d.xy * d.xy + d.yy * d.yy + d.yz * d.yz, d.xz * d.xz + d.yz * d.yz + d.zz * d.zz,
          d.xx * d.xy + d.xy * d.yy + d.xz * d.yz, d.xx * d.xz + d.xy * d.yz + d.xz * d.zz, d.xy * d.xz + d.yy * d.yz + d.yz * d.zz};
}

constexpr float kNoValue = 3.4e38f;  // larger than any distance: min() keeps the other value

struct LeafBuffers {
  float phi[512];
  float sum[512];
  float grad[3][512];
  std::int32_t nearest[512];
  float best[512];
};

// Ellipsoid distance (Taubin's first-order distance to ‖D r‖ = ρ, exact for spheres) of particle i
// on the voxels of its box inside the leaf; keeps the minimum (union, Eq. 41).
void SplatEllipsoid(const FieldInputs& in, std::uint32_t i, const Vec3f& c, float reach, const int lo[3], const int hi[3],
                    LeafBuffers& buf) {
  SymMat d{1, 1, 1, 0, 0, 0};
  if (in.D) {
    const auto& a = in.D[i];
    d = {a[0], a[1], a[2], a[3], a[4], a[5]};
  }
  const SymMat d2 = Square(d);
  const float rho = in.rho;
  const bool track = in.track_nearest;
  const float center_value = -rho * (in.min_stretch ? in.min_stretch[i] : 1.0f);
  for (int x = lo[0]; x <= hi[0]; ++x) {
    const float rx = float(x) - c.x;
    for (int y = lo[1]; y <= hi[1]; ++y) {
      const float ry = float(y) - c.y;
      // D r and D² r are affine in r_z along the row.
      const float ax = d.xx * rx + d.xy * ry, ay = d.xy * rx + d.yy * ry, az = d.xz * rx + d.yz * ry;
      const float bx = d2.xx * rx + d2.xy * ry, by = d2.xy * rx + d2.yy * ry, bz = d2.xz * rx + d2.yz * ry;
      const int row = x * 64 + y * 8;
      // Only the ball of radius `reach` can change a voxel: clip the row to it.
      const float rest = reach * reach - rx * rx - ry * ry;
      if (rest < 0) continue;
      const float half = std::sqrt(rest);
      const int z0 = std::max(lo[2], int(std::ceil(c.z - half))), z1 = std::min(hi[2], int(std::floor(c.z + half)));
      const auto distance = [&](int z) {
        const float rz = float(z) - c.z;
        const float px = ax + d.xz * rz, py = ay + d.yz * rz, pz = az + d.zz * rz;
        const float qx = bx + d2.xz * rz, qy = by + d2.yz * rz, qz = bz + d2.zz * rz;
        const float q2 = px * px + py * py + pz * pz;
        const float p2 = qx * qx + qy * qy + qz * qz;
        const float q = std::sqrt(q2);
        return p2 > 1e-12f ? (q - rho) * q / std::sqrt(std::max(p2, 1e-12f)) : center_value;
      };
      if (track) {
        for (int z = z0; z <= z1; ++z) {
          const float phi = distance(z);
          if (phi < buf.phi[row + z]) buf.phi[row + z] = phi, buf.nearest[row + z] = std::int32_t(i);
        }
      } else {
        // The whole row of 8 with the clipped part masked out: one fixed-length, branch-free loop
        // that the compiler vectorises (same values as looping over z0..z1).
        for (int z = 0; z < kLeafDim; ++z) {
          const float phi = distance(z);
          buf.phi[row + z] = std::min(buf.phi[row + z], z >= z0 && z <= z1 ? phi : kNoValue);
        }
      }
    }
  }
}

// Yu & Turk kernel sum Σ V W_A(x − x̄_i, G_i) and its gradient.
void SplatKernel(const FieldInputs& in, std::uint32_t i, const Vec3f& c, float reach, const int lo[3], const int hi[3], LeafBuffers& buf) {
  SymMat g{in.inv_h, in.inv_h, in.inv_h, 0, 0, 0};
  if (in.D) {
    const auto& a = in.D[i];
    g = {a[0] * in.inv_h, a[1] * in.inv_h, a[2] * in.inv_h, a[3] * in.inv_h, a[4] * in.inv_h, a[5] * in.inv_h};
  }
  const SymMat g2 = Square(g);
  const float det = g.xx * (g.yy * g.zz - g.yz * g.yz) - g.xy * (g.xy * g.zz - g.yz * g.xz) + g.xz * (g.xy * g.yz - g.yy * g.xz);
  const float scale = in.volume * 0.07957747154594767f * det;  // V σ3 det(G)
  for (int x = lo[0]; x <= hi[0]; ++x) {
    const float rx = float(x) - c.x;
    for (int y = lo[1]; y <= hi[1]; ++y) {
      const float ry = float(y) - c.y;
      const int row = x * 64 + y * 8;
      const float rest = reach * reach - rx * rx - ry * ry;
      if (rest < 0) continue;
      const float half = std::sqrt(rest);
      const int z0 = std::max(lo[2], int(std::ceil(c.z - half))), z1 = std::min(hi[2], int(std::floor(c.z + half)));
      for (int z = z0; z <= z1; ++z) {
        const float rz = float(z) - c.z;
        const float px = g.xx * rx + g.xy * ry + g.xz * rz, py = g.xy * rx + g.yy * ry + g.yz * rz, pz = g.xz * rx + g.yz * ry + g.zz * rz;
        const float q = std::sqrt(px * px + py * py + pz * pz);
        if (q >= 2.0f) continue;
        const float w = scale * CubicSpline<float>::Shape(q);
        const int v = row + z;
        buf.sum[v] += w;
        if (q > 1e-6f) {
          // ∇_x W_A = V σ3 det(G) B'(q) G (G r) / q (G symmetric).
          const float f = scale * CubicSpline<float>::ShapeDerivative(q) / q;
          buf.grad[0][v] += f * (g2.xx * rx + g2.xy * ry + g2.xz * rz);
          buf.grad[1][v] += f * (g2.xy * rx + g2.yy * ry + g2.yz * rz);
          buf.grad[2][v] += f * (g2.xz * rx + g2.yz * ry + g2.zz * rz);
        }
        if (in.track_nearest && w > buf.best[v]) buf.best[v] = w, buf.nearest[v] = std::int32_t(i);
      }
    }
  }
}

struct RasterOutput {
  openvdb::FloatTree::Ptr surface;
  openvdb::MaskTree::Ptr inside;
  openvdb::MaskTree::Ptr shallow_outside;  // 0 <= φ < 1 voxel: where enclosed voids can be
  openvdb::MaskTree::Ptr far_outside;      // φ >= 1 voxel inside allocated leaves: seeds of the exterior
  openvdb::Vec3STree::Ptr velocity;
  std::uint64_t deep_leaves = 0;  // filled as interior without evaluating the field
};

RasterOutput Rasterize(const Plan& plan, const FieldInputs& in, const std::vector<Vec3f>* velocities) {
  const float band = in.band;
  const float dx = float(plan.dx);
  const float background = band * dx;
  const std::size_t count = plan.targets.size();
  std::vector<openvdb::FloatTree::LeafNodeType*> leaves(count, nullptr);
  std::vector<openvdb::MaskTree::LeafNodeType*> inside_leaves(count, nullptr);
  std::vector<openvdb::MaskTree::LeafNodeType*> shallow_leaves(count, nullptr), far_leaves(count, nullptr);
  std::vector<openvdb::Vec3STree::LeafNodeType*> velocity_leaves(velocities ? count : 0, nullptr);
  const int K = plan.K;
  const std::vector<std::uint8_t> deep = DeepLeaves(plan, in);

  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, count, 4), [&](const tbb::blocked_range<std::size_t>& range) {
    std::unique_ptr<LeafBuffers> buf(new LeafBuffers);
    for (std::size_t t = range.begin(); t != range.end(); ++t) {
      std::int64_t lx, ly, lz;
      KeyToLeaf(plan.targets[t], lx, ly, lz);
      if (deep[t]) {
        // Interior: inactive −background values, wholly inside (BuildInteriorBand keeps both).
        const openvdb::Coord origin(plan.offset.x() + int(lx * kLeafDim), plan.offset.y() + int(ly * kLeafDim),
                                    plan.offset.z() + int(lz * kLeafDim));
        leaves[t] = new openvdb::FloatTree::LeafNodeType(origin, -background, false);
        inside_leaves[t] = new openvdb::MaskTree::LeafNodeType(origin, true);
        continue;
      }
      const Vec3f leaf_origin(float(lx * kLeafDim), float(ly * kLeafDim), float(lz * kLeafDim));
      const bool sum = in.field == Field::kKernelSum;
      if (sum) {
        std::fill(std::begin(buf->sum), std::end(buf->sum), 0.0f);
        for (auto& g : buf->grad) std::fill(std::begin(g), std::end(g), 0.0f);
        std::fill(std::begin(buf->best), std::end(buf->best), 0.0f);
      } else {
        std::fill(std::begin(buf->phi), std::end(buf->phi), band);
      }
      if (in.track_nearest) std::fill(std::begin(buf->nearest), std::end(buf->nearest), -1);
      bool touched = false;
      for (int ox = -K; ox <= K; ++ox)
        for (int oy = -K; oy <= K; ++oy)
          for (int oz = -K; oz <= K; ++oz) {
            const auto it = plan.bin_of_key.find(LeafKey(lx + ox, ly + oy, lz + oz));
            if (it == plan.bin_of_key.end()) continue;
            for (std::uint32_t s = plan.bin_start[it->second]; s < plan.bin_start[it->second + 1]; ++s) {
              const std::uint32_t i = plan.sorted[s];
              const Vec3f c = plan.u[i] - leaf_origin;
              const float r = plan.reach[i];
              int lo[3], hi[3];
              bool empty = false;
              for (int a = 0; a < 3; ++a) {
                lo[a] = std::max(0, int(std::ceil(c[a] - r)));
                hi[a] = std::min(kLeafDim - 1, int(std::floor(c[a] + r)));
                empty = empty || lo[a] > hi[a];
              }
              if (empty) continue;
              touched = true;
              if (sum) SplatKernel(in, i, c, r, lo, hi, *buf);
              else SplatEllipsoid(in, i, c, r, lo, hi, *buf);
            }
          }
      if (!touched) continue;
      if (in.field == Field::kKernelSum) {
        // Distance-like field from the sum: (iso − f) / ‖∇f‖ (first-order distance to f = iso).
        for (int v = 0; v < 512; ++v) {
          const float f = buf->sum[v];
          const float g =
              std::sqrt(buf->grad[0][v] * buf->grad[0][v] + buf->grad[1][v] * buf->grad[1][v] + buf->grad[2][v] * buf->grad[2][v]);
          const float diff = in.iso - f;
          buf->phi[v] = std::fabs(diff) < band * g ? diff / g : (diff > 0 ? band : -band);
        }
      }
      bool any = false;
      for (int v = 0; v < 512 && !any; ++v) any = buf->phi[v] < band;
      if (!any) continue;
      const openvdb::Coord origin(plan.offset.x() + int(lx * kLeafDim), plan.offset.y() + int(ly * kLeafDim),
                                  plan.offset.z() + int(lz * kLeafDim));
      auto* leaf = new openvdb::FloatTree::LeafNodeType(origin, background, false);
      auto* inside = new openvdb::MaskTree::LeafNodeType(origin, false);
      auto* shallow = new openvdb::MaskTree::LeafNodeType(origin, false);
      auto* far = new openvdb::MaskTree::LeafNodeType(origin, false);
      openvdb::Vec3STree::LeafNodeType* vel = nullptr;
      if (velocities) vel = new openvdb::Vec3STree::LeafNodeType(origin, openvdb::Vec3s(0, 0, 0), false);
      for (int v = 0; v < 512; ++v) {
        const float phi = std::max(buf->phi[v], -band);
        if (phi >= 1.0f) far->setValueOn(v);
        else if (phi >= 0.0f) shallow->setValueOn(v);
        if (phi >= band) continue;  // stays inactive background
        leaf->setValueOn(v, phi * dx);
        if (phi < 0) inside->setValueOn(v);
        if (vel && buf->nearest[v] >= 0) {
          const Vec3f& p = (*velocities)[buf->nearest[v]];
          vel->setValueOn(v, openvdb::Vec3s(p.x, p.y, p.z));
        }
      }
      leaves[t] = leaf;
      inside_leaves[t] = inside;
      shallow_leaves[t] = shallow;
      far_leaves[t] = far;
      if (vel) velocity_leaves[t] = vel;
    }
  });

  RasterOutput out;
  out.deep_leaves = std::uint64_t(std::count(deep.begin(), deep.end(), std::uint8_t(1)));
  out.surface = std::make_shared<openvdb::FloatTree>(background);
  out.inside = std::make_shared<openvdb::MaskTree>(false);
  out.shallow_outside = std::make_shared<openvdb::MaskTree>(false);
  out.far_outside = std::make_shared<openvdb::MaskTree>(false);
  if (velocities) out.velocity = std::make_shared<openvdb::Vec3STree>(openvdb::Vec3s(0, 0, 0));
  for (std::size_t t = 0; t < count; ++t) {
    if (!leaves[t]) continue;
    out.surface->addLeaf(leaves[t]);
    out.inside->addLeaf(inside_leaves[t]);
    if (shallow_leaves[t]) out.shallow_outside->addLeaf(shallow_leaves[t]);
    if (far_leaves[t]) out.far_outside->addLeaf(far_leaves[t]);
    if (velocities && velocity_leaves[t]) out.velocity->addLeaf(velocity_leaves[t]);
  }
  return out;
}

// Fills enclosed voids: shallow outside voxels (0 <= φ < 1 voxel) that no face-connected path
// through shallow voxels links to the far outside. A union of r_iso = 0.75 d_p spheres leaves
// such pockets at cubic cell centres (half diagonal 0.87 d_p); they are not surface. Returns the
// number of voxels filled.
std::uint64_t FillEnclosedVoids(openvdb::FloatTree& tree, openvdb::MaskTree& inside, const openvdb::MaskTree& shallow,
                                const openvdb::MaskTree& far, float dx) {
  // Shallow voxels connected to the outside are reached within a few steps; a pocket still
  // unreached after 12 (a crack under 2 voxels wide and over 12 deep) is closed as well. The far
  // outside (large) is dilated once; after that only the reached shallow shell (thin) grows.
  openvdb::MaskTree reached(far);
  openvdb::tools::dilateActiveValues(reached, 1, openvdb::tools::NN_FACE, openvdb::tools::IGNORE_TILES);
  reached.topologyIntersection(shallow);
  std::uint64_t previous = reached.activeVoxelCount();
  for (int iteration = 1; iteration < 12 && previous > 0; ++iteration) {
    openvdb::tools::dilateActiveValues(reached, 1, openvdb::tools::NN_FACE, openvdb::tools::IGNORE_TILES);
    reached.topologyIntersection(shallow);
    const std::uint64_t now = reached.activeVoxelCount();
    if (now == previous) break;
    previous = now;
  }
  openvdb::MaskTree voids(shallow);
  voids.topologyDifference(reached);
  const std::uint64_t filled = voids.activeVoxelCount();
  if (filled == 0) return 0;
  openvdb::tree::ValueAccessor<openvdb::FloatTree> acc(tree);
  for (auto it = voids.cbeginLeaf(); it; ++it) {
    auto* leaf = acc.probeLeaf(it->origin());
    if (!leaf) continue;
    for (auto v = it->cbeginValueOn(); v; ++v) leaf->setValueOn(v.pos(), -0.5f * dx);
  }
  inside.topologyUnion(voids);
  return filled;
}

// Interior depth from chessboard erosions of the inside mask (consumed): a voxel that survives k
// erosions is at least k voxels from the nearest outside voxel. Deeper than the band: inactive
// −background.
void BuildInteriorBand(openvdb::FloatTree& tree, openvdb::MaskTree& inside, float band_voxels, float dx) {
  const int layers = int(std::ceil(band_voxels));
  const float background = band_voxels * dx;
  openvdb::tree::LeafManager<openvdb::FloatTree> manager(tree);
  // Erodes `inside` in place, one layer at a time, and applies each layer before the next.
  for (int k = 1; k <= layers; ++k) {
    openvdb::tools::erodeActiveValues(inside, 1, openvdb::tools::NN_FACE_EDGE_VERTEX, openvdb::tools::IGNORE_TILES);
    manager.foreach ([&](openvdb::FloatTree::LeafNodeType& leaf, std::size_t) {
      const auto* mask = inside.probeConstLeaf(leaf.origin());
      if (!mask) return;
      for (auto it = mask->cbeginValueOn(); it; ++it) {
        const openvdb::Index v = it.pos();
        if (k == layers) {
          leaf.setValueOff(v, -background);
        } else {
          leaf.setValueOnly(v, std::min(leaf.getValue(v), -float(k) * dx));
        }
      }
    });
  }
}

}  // namespace

openvdb::FloatGrid::Ptr EmptyLevelSet(double voxel_size, double half_band) {
  InitializeOpenVdb();
  auto grid = openvdb::FloatGrid::create(float(half_band * voxel_size));
  grid->setTransform(openvdb::math::Transform::createLinearTransform(voxel_size));
  grid->setGridClass(openvdb::GRID_LEVEL_SET);
  grid->setName("surface");
  return grid;
}

void InitializeOpenVdb() {
  static std::once_flag once;
  std::call_once(once, [] { openvdb::initialize(); });
}

namespace {

// Keeps every value of `grid` within `limit` of `reference`'s, after each smoothing step: mean-curvature
// flow pinches a neck thinner than its curvature radius away, so an icicle would come loose from
// its eave; bounded, the neck keeps its thickness less the limit while particle bumps still smooth out.
void ClampToBand(openvdb::FloatGrid& grid, const openvdb::FloatGrid& reference, float limit) {
  const auto& ref = reference.tree();
  openvdb::tree::LeafManager<openvdb::FloatTree> leaves(grid.tree());
  leaves.foreach ([&](openvdb::FloatTree::LeafNodeType& leaf, std::size_t) {
    const auto* ref_leaf = ref.probeConstLeaf(leaf.origin());
    for (auto v = leaf.beginValueOn(); v; ++v) {
      const float r = ref_leaf ? ref_leaf->getValue(v.pos()) : ref.getValue(v.getCoord());
      v.setValue(std::clamp(*v, r - limit, r + limit));
    }
  });
}

void CheckSettings(const ParticleSet& particles, const Settings& s) {
  const auto fail = [](const std::string& what, const std::string& field) { throw InputError(what, field); };
  if (!(particles.spacing > 0)) fail("particle spacing must be positive", "spacing");
  if (s.voxel_size < 0 || !std::isfinite(s.voxel_size)) fail("voxel size must be positive (m)", "voxel_size");
  if (!(s.voxel_ratio > 0)) fail("voxel ratio must be positive", "voxel_ratio");
  if (s.resolution < 0 || s.resolution == 1) fail("resolution must be at least 2 (or 0 = off)", "resolution");
  if (!(s.r_iso > 0) || s.r_iso > 4) fail("r_iso must be in (0, 4] particle spacings", "r_iso");
  if (!(s.lambda >= 0 && s.lambda <= 1)) fail("lambda must be in [0, 1]", "lambda");
  if (!(s.iso > 0)) fail("iso value must be positive", "iso");
  if (!(s.half_band >= 3)) fail("narrow band half width must be at least 3 voxels", "half_band");
  if (s.smooth_iterations < 0) fail("smoothing iterations must be >= 0", "smooth");
  if (!(s.close_radius >= 0 && s.close_radius <= 4)) fail("closing radius must be in [0, 4] particle spacings", "close");
  if (!(s.smooth_limit >= 0 && s.smooth_limit <= 4)) fail("smoothing limit must be in [0, 4] particle spacings", "smooth_limit");
  const auto& a = s.anisotropy;
  if (!(a.k_r >= 1)) fail("k_r must be >= 1", "k_r");
  if (!(a.k_s >= 0)) fail("k_s must be >= 0 (0 = automatic)", "k_s");
  if (!(a.k_n > 0)) fail("k_n must be positive", "k_n");
  if (a.n_eps < 0) fail("N_eps must be >= 0", "n_eps");
  if (!(a.s_min > 0 && a.s_min <= a.s_max)) fail("need 0 < s_min <= s_max", "s_min");
}

std::vector<float> ReachVoxels(const ParticleSet& particles, const Settings& s, const PreparedParticles* prepared, double dx, float rho,
                               float band, float h_vox) {
  const std::size_t n = particles.size();
  std::vector<float> reach(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float max_s = prepared && !prepared->max_stretch.empty() ? prepared->max_stretch[i] : float(s.anisotropy.s_max);
    if (s.field == Field::kKernelSum) {
      reach[i] = 2 * h_vox * (s.field == Field::kIsotropic ? 1.0f : max_s);
    } else {
      const float level = rho * (s.field == Field::kIsotropic ? 1.0f : max_s);
      // A fully surrounded particle cannot be the nearest ellipsoid to voxels far outside it; one
      // voxel beyond its ellipsoid still covers the gaps between lattice neighbours (0.87 d_p).
      const bool interior = prepared && !prepared->interior.empty() && prepared->interior[i];
      reach[i] = level + (interior ? 1.0f : band);
    }
  }
  return reach;
}

// Planned leaves that lie inside the body: their 3×3×3 block of leaves holds at least 70 % of the
// particles that water at rest (one per d_p³) would put there. A leaf that a flat surface crosses
// sees at most 2/3 of that (its outer layer of neighbours is empty), a bulk leaf about all of it.
// Those leaves become tiles when the level set is pruned and carry no mesh; enclosed voids in them
// are filled before meshing (keep_voids off).
std::size_t InteriorLeaves(const Plan& plan, double spacing) {
  const double full_block = 27 * std::pow(kLeafDim * plan.dx / spacing, 3);
  std::size_t interior = 0;
  for (std::uint64_t key : plan.targets) {
    std::int64_t lx, ly, lz;
    KeyToLeaf(key, lx, ly, lz);
    std::size_t count = 0;
    for (int ox = -1; ox <= 1; ++ox)
      for (int oy = -1; oy <= 1; ++oy)
        for (int oz = -1; oz <= 1; ++oz)
          if (const auto bin = plan.bin_of_key.find(LeafKey(lx + ox, ly + oy, lz + oz)); bin != plan.bin_of_key.end())
            count += plan.bin_start[bin->second + 1] - plan.bin_start[bin->second];
    interior += double(count) >= 0.7 * full_block;
  }
  return interior;
}

}  // namespace

std::uint64_t EstimateMemoryBytes(const ParticleSet& particles, const Settings& settings, std::uint64_t* voxels) {
  CheckSettings(particles, settings);
  const std::size_t n = particles.size();
  if (voxels) *voxels = 0;
  if (n == 0) return 0;
  const double dx = VoxelSize(particles, settings);
  const double h = particles.smoothing_length > 0 ? particles.smoothing_length : particles.spacing;
  const std::vector<float> reach = ReachVoxels(particles, settings, nullptr, dx, float(settings.r_iso * particles.spacing / dx),
                                               float(settings.half_band), float(h / dx));
  const Plan plan = MakePlan(particles.positions, reach, dx);
  if (voxels) *voxels = plan.targets.size() * 512;
  // Per leaf: float values + masks (surface, inside, erosion copies) + node overhead.
  const double leaf_bytes = 512 * 4 + 64 * (4 + std::ceil(settings.half_band)) + 96 + (settings.velocity_grid ? 512 * 12 : 0) +
                            (settings.density_grid ? 512 * 4 : 0);
  const double particle_bytes = 24 + 12 + 24 + 12 + 8 + 3 + 32 + 16;  // input, centres, D, velocity, stretches, grid, plan
  // Internal nodes: 16³-child nodes cover 128³ voxels (~50 kB each), 32³-child nodes 4096³ (~400 kB).
  std::vector<std::uint64_t> upper1, upper2;
  for (std::uint64_t key : plan.targets) {
    std::int64_t lx, ly, lz;
    KeyToLeaf(key, lx, ly, lz);
    upper1.push_back(LeafKey(lx >> 4, ly >> 4, lz >> 4));
    upper2.push_back(LeafKey(lx >> 9, ly >> 9, lz >> 9));
  }
  for (auto* v : {&upper1, &upper2}) {
    std::sort(v->begin(), v->end());
    v->erase(std::unique(v->begin(), v->end()), v->end());
  }
  const double node_bytes = upper1.size() * 4096 * 12.0 + upper2.size() * 32768 * 12.0;
  // The field is evaluated in every planned leaf; the masks and the particle-side arrays are freed
  // and the interior pruned to tiles before the mesh is built, which needs only the leaves near the
  // surface: the two phases peak one after the other.
  const double all_leaves = double(plan.targets.size());
  const double surface_leaves = all_leaves - double(InteriorLeaves(plan, particles.spacing));
  // The mesh and OpenVDB's meshing buffers: 26 (jittered ball) to 146 (two-layer sheet) triangles
  // per leaf; 6 kB per surface leaf keeps the estimate above the measured peak at 0.5–2M ice
  // particles and for water at fine voxels (docs/reliability.md, memory budgets). The process's
  // fixed ~30 MB is not counted. `smooth_limit`'s copy of the level set (leaf_bytes per surface
  // leaf) is freed before the mesh is built, and grid plus copy stay below the mesh phase.
  const double mesh_bytes_per_leaf = settings.mesh ? 6000.0 : 0.0;
  const double field_phase = all_leaves * leaf_bytes * 1.5;
  const double mesh_phase = surface_leaves * (leaf_bytes * 1.5 + mesh_bytes_per_leaf);
  return std::uint64_t(std::max(field_phase, mesh_phase) + node_bytes * 2 + n * particle_bytes);
}

Result Reconstruct(const ParticleSet& particles, const Settings& settings) {
  CheckSettings(particles, settings);
  InitializeOpenVdb();
  Result result;
  result.grids = std::make_shared<Grids>();
  Stats& stats = result.stats;
  stats.particles = particles.size();
  const double dx = VoxelSize(particles, settings);
  stats.voxel_size = dx;
  const double particle_reach =
      std::max(settings.r_iso * particles.spacing, 2 * (particles.smoothing_length > 0 ? particles.smoothing_length : particles.spacing));
  if (!(particle_reach / dx <= 100))
    throw InputError(fmt::format("voxel size {:.3g} m is too small for particle spacing {:.3g} m: one particle would span "
                                 "{:.0f} voxels (at most 100)",
                                 dx, particles.spacing, particle_reach / dx),
                     "voxel_size");
  result.grids->surface = EmptyLevelSet(dx, settings.half_band);
  if (particles.size() == 0) return result;

  auto t0 = Clock::now();
  PreparedParticles prepared = Prepare(particles, settings, dx);
  stats.seconds_prepare = Seconds(t0);

  t0 = Clock::now();
  const double h = particles.smoothing_length > 0 ? particles.smoothing_length : particles.spacing;
  const float rho = float(std::max(settings.r_iso * particles.spacing, 0.5 * dx) / dx);
  const float band = float(settings.half_band);
  const std::vector<float> reach = ReachVoxels(particles, settings, &prepared, dx, rho, band, float(h / dx));
  std::vector<Vec3d> world(particles.size());
  exec::cpu::ParallelFor(Index(particles.size()), [&](Index i) { world[i] = prepared.origin + Vec3d(prepared.centers[i]); });
  Plan plan = MakePlan(world, reach, dx);
  world = {};

  FieldInputs in;
  in.field = settings.field;
  in.rho = rho;
  in.band = band;
  in.D = prepared.D.empty() ? nullptr : prepared.D.data();
  in.min_stretch = prepared.min_stretch.data();
  in.inv_h = float(dx / h);
  const double volume = particles.particle_volume > 0 ? particles.particle_volume : std::pow(particles.spacing, 3);
  in.volume = float(volume / (dx * dx * dx));
  in.iso = float(settings.iso);
  // Deep leaves are at least a leaf (8 voxels) inside: only for bands well within that.
  const bool deep_tiles =
      settings.deep_interior_tiles && !settings.keep_voids && settings.field != Field::kKernelSum && settings.half_band <= 4;
  in.interior = deep_tiles ? prepared.interior.data() : nullptr;
  const bool want_velocity = settings.velocity_grid && !particles.velocities.empty();
  in.track_nearest = want_velocity;
  const double t_plan = Seconds(t0);
  RasterOutput raster = Rasterize(plan, in, want_velocity ? &particles.velocities : nullptr);
  const double t_raster = Seconds(t0);
  const std::size_t planned_leaves = plan.targets.size();
  stats.deep_leaves = raster.deep_leaves;
  plan = Plan{};  // particle-side arrays are not needed any more: free them before meshing
  prepared = PreparedParticles{};
  if (!settings.keep_voids)
    stats.filled_void_voxels = FillEnclosedVoids(*raster.surface, *raster.inside, *raster.shallow_outside, *raster.far_outside, float(dx));
  raster.shallow_outside.reset();
  raster.far_outside.reset();
  const double t_voids = Seconds(t0);
  BuildInteriorBand(*raster.surface, *raster.inside, band, float(dx));
  raster.inside.reset();
  openvdb::tools::pruneLevelSet(*raster.surface);
  log::Debug("rasterize {} particles: plan {:.3f} s ({} leaves, {} deep), field {:.3f} s, voids {:.3f} s ({} voxels), band+prune {:.3f} s",
             particles.size(), t_plan, planned_leaves, stats.deep_leaves, t_raster - t_plan, t_voids - t_raster, stats.filled_void_voxels,
             Seconds(t0) - t_voids);
#ifdef __GLIBC__
  malloc_trim(0);  // hand freed particle arrays and mask leaves back before the mesh is built
#endif
  auto& grid = result.grids->surface;
  grid->setTree(raster.surface);
  stats.seconds_rasterize = Seconds(t0);

  t0 = Clock::now();
  // Mean-curvature flow removes the bump every particle makes in a union of particle shapes; the
  // kernel sum is smooth already, and the flow would thin its splashes and sheets away.
  const int smooth_iterations = settings.field == Field::kKernelSum ? 0 : settings.smooth_iterations;
  if (settings.close_radius > 0 || smooth_iterations > 0) {
    // Closing joins particles whose shapes leave gaps (pores, bead chains) without thinning real
    // sheets. The kernel sum's (iso − f)/‖∇f‖ is a distance only near the surface, and the
    // filters' PDEs need a true signed distance, so it is rebuilt first.
    if (settings.field == Field::kKernelSum) {
      grid = openvdb::tools::levelSetRebuild(*grid, 0.0f, float(settings.half_band));
      grid->setName("surface");
    }
    openvdb::tools::LevelSetFilter<openvdb::FloatGrid> filter(*grid);
    if (settings.close_radius > 0) {
      const float radius = float(settings.close_radius * particles.spacing);
      filter.offset(-radius);
      filter.offset(radius);
    }
    const openvdb::FloatGrid::Ptr closed = settings.smooth_limit > 0 && smooth_iterations > 0 ? grid->deepCopy() : nullptr;
    for (int k = 0; k < smooth_iterations; ++k) {
      filter.meanCurvature();
      if (closed) ClampToBand(*grid, *closed, float(settings.smooth_limit * particles.spacing));
    }
  }
  if (settings.velocity_grid) {
    auto vel = openvdb::Vec3SGrid::create(openvdb::Vec3s(0, 0, 0));
    if (raster.velocity) {
      raster.velocity->topologyIntersection(grid->tree());
      openvdb::tools::prune(*raster.velocity);
      vel->setTree(raster.velocity);
    }
    vel->setTransform(grid->transform().copy());
    vel->setName("vel");
    vel->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    result.grids->velocity = vel;
  }
  if (settings.density_grid) {
    auto density = grid->deepCopy();
    openvdb::tools::sdfToFogVolume(*density);
    density->setName("density");
    result.grids->density = density;
  }
  stats.seconds_filter = Seconds(t0);
  stats.active_voxels = grid->activeVoxelCount();
  stats.leaves = grid->tree().leafCount();
  stats.grid_bytes = grid->memUsage();

  if (settings.mesh) {
    t0 = Clock::now();
    stats.removed_void_shells = ExtractMesh(*grid, settings.keep_voids, result.mesh);
    if (settings.mesh_velocities) result.mesh.velocities = InterpolateVelocities(particles, result.mesh.positions);
    stats.vertices = result.mesh.vertex_count();
    stats.triangles = result.mesh.triangle_count();
    stats.seconds_mesh = Seconds(t0);
  }
  return result;
}

std::vector<float> SampleSurface(const Result& result, const std::vector<Vec3d>& points) {
  std::vector<float> out(points.size(), 0.0f);
  if (!result.grids || !result.grids->surface) return out;
  const auto& grid = *result.grids->surface;
  auto acc = grid.getConstAccessor();
  const auto& xform = grid.transform();
  for (std::size_t i = 0; i < points.size(); ++i) {
    const openvdb::Vec3d ijk = xform.worldToIndex(openvdb::Vec3d(points[i].x, points[i].y, points[i].z));
    // Trilinear interpolation by hand (keeps Interpolation.h out of this file).
    const openvdb::Coord base(int(std::floor(ijk.x())), int(std::floor(ijk.y())), int(std::floor(ijk.z())));
    const double fx = ijk.x() - base.x(), fy = ijk.y() - base.y(), fz = ijk.z() - base.z();
    double v = 0;
    for (int c = 0; c < 8; ++c) {
      const int ox = c & 1, oy = c >> 1 & 1, oz = c >> 2 & 1;
      const double w = (ox ? fx : 1 - fx) * (oy ? fy : 1 - fy) * (oz ? fz : 1 - fz);
      v += w * acc.getValue(base.offsetBy(ox, oy, oz));
    }
    out[i] = float(v);
  }
  return out;
}

}  // namespace rime::surface
