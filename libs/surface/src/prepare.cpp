// Per-particle inputs of the surface field: Yu & Turk centre smoothing and the anisotropy matrix D
// (spec §8, §10). No OpenVDB here.
#include <fmt/format.h>

#include <algorithm>
#include <cmath>

#include "rime/core/error.h"
#include "rime/core/hd.h"
#include "rime/exec/parallel.h"
#include "rime/neighbors/grid.h"
#include "rime/surface/reconstruct.h"

namespace rime::surface {

Field ParseField(const std::string& name) {
  Field field{};
  if (!io::ParseEnum(name, field))
    throw InputError(fmt::format("unknown field '{}' (expected ellipsoids, kernel_sum or isotropic)", name), "field");
  return field;
}

const char* FieldName(Field field) { return io::EnumName(field).data(); }

namespace {

double SmoothingLength(const ParticleSet& p) { return p.smoothing_length > 0 ? p.smoothing_length : p.spacing; }

// Smallest and largest eigenvalue of a symmetric 3x3 matrix (closed form, Smith 1961): cheaper
// than Jacobi sweeps when the stored D needs no change.
void EigenvalueRange(const std::array<float, 6>& c, double& lo, double& hi) {
  const double a = c[0], b = c[1], d = c[2], xy = c[3], xz = c[4], yz = c[5];
  const double p1 = xy * xy + xz * xz + yz * yz;
  const double q = (a + b + d) / 3;
  if (p1 <= 1e-20 * (q * q + 1e-30)) {
    lo = std::min({a, b, d}), hi = std::max({a, b, d});
    return;
  }
  const double p2 = (a - q) * (a - q) + (b - q) * (b - q) + (d - q) * (d - q) + 2 * p1;
  const double p = std::sqrt(p2 / 6);
  // B = (A − qI) / p; r = det(B) / 2.
  const double b00 = (a - q) / p, b11 = (b - q) / p, b22 = (d - q) / p, b01 = xy / p, b02 = xz / p, b12 = yz / p;
  const double det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02);
  const double r = std::clamp(det / 2, -1.0, 1.0);
  const double phi = std::acos(r) / 3;
  hi = q + 2 * p * std::cos(phi);
  lo = q + 2 * p * std::cos(phi + 2.0943951023931953);
}

// s_1 s_2 s_3 = 1 / det D for a stored D = R diag(1/s) Rᵀ.
double StretchVolume(const std::array<float, 6>& c) {
  const double a = c[0], b = c[1], d = c[2], xy = c[3], xz = c[4], yz = c[5];
  return 1 / (a * (b * d - yz * yz) - xy * (xy * d - yz * xz) + xz * (xy * yz - b * xz));
}

// Stretches as §8 leaves them: within [s_min, s_max] and s_1 / s_k <= k_r (float slack).
bool WithinBounds(double s_lo, double s_hi, const anisotropy::Params<double>& p) {
  constexpr double kSlack = 1e-4;
  return s_lo >= p.s_min * (1 - kSlack) && s_hi <= p.s_max * (1 + kSlack) && s_hi <= s_lo * p.k_r * (1 + kSlack);
}

// Brings a stored D that breaks them (hand-made or from another tool) back to the §8 bounds.
void ClampToBounds(Vec3f& s, const anisotropy::Params<double>& p) {
  const float s_hi = std::min(std::max({s.x, s.y, s.z}), float(p.s_max));
  const float lo = std::max(float(p.s_min), s_hi / float(p.k_r));
  for (int k = 0; k < 3; ++k) s[k] = std::clamp(s[k], lo, std::max(lo, s_hi));
}

constexpr std::uint32_t kSumLanes = 16;  // one AVX-512 register of floats
constexpr float kFar = 1e30f;            // padding lanes: r² overflows, outside the support

// Kernel-weighted neighbour sums of up to kSumLanes particles side by side: Σ W, Σ W r, Σ W r rᵀ
// (r = x_j − x_i) and the neighbour count, as anisotropy::CovarianceAccumulator keeps them.
struct LaneSums {
  alignas(64) float x[kSumLanes], y[kSumLanes], z[kSumLanes];
  alignas(64) float weight[kSumLanes], fx[kSumLanes] = {}, fy[kSumLanes] = {}, fz[kSumLanes] = {};
  alignas(64) float second[6][kSumLanes] = {};
  alignas(64) std::int32_t count[kSumLanes] = {};

  // Candidate (xj, yj, zj); lane `self` is the candidate itself (any value >= kSumLanes: none).
  template <bool kSecondMoments>
  void Add(float xj, float yj, float zj, std::uint32_t self, float support, const CubicSpline<float>& kernel) {
    const float r2max = support * support;
    RIME_IVDEP
    for (std::uint32_t l = 0; l < kSumLanes; ++l) {
      const float rx = xj - x[l], ry = yj - y[l], rz = zj - z[l];
      const float r2 = rx * rx + ry * ry + rz * rz;
      const bool in = (r2 < r2max) & (l != self);
      const float q = std::sqrt(r2) * kernel.inv_h;  // for every lane: a blend, not a branch
      const float w = in ? kernel.w_norm * CubicSpline<float>::ShapeBranchFree(q) : 0.0f;
      weight[l] += w;
      fx[l] += rx * w, fy[l] += ry * w, fz[l] += rz * w;
      if constexpr (kSecondMoments) {
        second[0][l] += w * rx * rx, second[1][l] += w * ry * ry, second[2][l] += w * rz * rz;
        second[3][l] += w * rx * ry, second[4][l] += w * rx * rz, second[5][l] += w * ry * rz;
      }
      count[l] += in;
    }
  }

  anisotropy::CovarianceAccumulator<float> Accumulator(std::uint32_t l) const {
    anisotropy::CovarianceAccumulator<float> acc;
    acc.weight_sum = weight[l];
    acc.first = Vec3f(fx[l], fy[l], fz[l]);
    for (int k = 0; k < 6; ++k) acc.second[k] = second[k][l];
    acc.neighbors = count[l];
    return acc;
  }
};

}  // namespace

double VoxelSize(const ParticleSet& particles, const Settings& settings) {
  if (settings.voxel_size > 0) return settings.voxel_size;
  if (settings.resolution > 1 && !particles.positions.empty()) {
    // Paper grid (spec §10): `resolution` nodes over the bounding box padded by 2h + r_iso.
    Vec3d lo = particles.positions[0], hi = lo;
    for (const Vec3d& p : particles.positions) lo = Min(lo, p), hi = Max(hi, p);
    const double pad = 2 * SmoothingLength(particles) + settings.r_iso * particles.spacing;
    const Vec3d extent = hi - lo + Vec3d::Splat(2 * pad);
    return std::max({extent.x, extent.y, extent.z}) / (settings.resolution - 1);
  }
  return settings.voxel_ratio * particles.spacing;
}

PreparedParticles Prepare(const ParticleSet& particles, const Settings& settings, double voxel_size) {
  PreparedParticles out;
  const std::size_t n = particles.size();
  if (n == 0) return out;
  const double h = SmoothingLength(particles);
  const double spacing = particles.spacing;

  Vec3d lo = particles.positions[0];
  for (const Vec3d& p : particles.positions) lo = Min(lo, p);
  out.origin = lo;
  std::vector<Vec3f> local(n);
  exec::cpu::ParallelFor(Index(n), [&](Index i) { local[i] = Vec3f(particles.positions[i] - lo); });

  const bool stored = !particles.stored_anisotropy.empty() && !settings.recompute_anisotropy;
  const bool anisotropic = settings.field != Field::kIsotropic;
  const bool need_pca = anisotropic && !stored;
  const bool need_neighbors =
      need_pca || settings.lambda > 0 || settings.field == Field::kEllipsoids || settings.field == Field::kIsotropic;

  const float support = float(2 * h);
  exec::Device cpu = exec::Device::Cpu();
  neighbors::UniformGrid<float> grid(cpu);
  // Visit particles in the grid's Z-curve order so neighbours are close in memory.
  std::vector<std::uint32_t> order(n);
  std::vector<Vec3f> sorted(n);
  if (need_neighbors) {
    grid.Build(local.data(), Index(n), support);
    std::copy(grid.order(), grid.order() + n, order.begin());
    exec::cpu::ParallelFor(Index(n), [&](Index k) { sorted[k] = local[order[k]]; });
    grid.AdoptOrder(sorted.data());
  } else {
    for (std::size_t k = 0; k < n; ++k) order[k] = std::uint32_t(k), sorted[k] = local[k];
  }
  const neighbors::GridView<float> view = grid.view();
  const CubicSpline<float> kernel{float(h)};

  out.centers.resize(n);
  out.D.resize(anisotropic ? n : 0);
  out.min_stretch.assign(n, 1.0f);
  out.max_stretch.assign(n, 1.0f);
  out.interior.assign(n, 0);

  // Smallest semi-axis allowed: r_iso s >= Δx/2 for ellipsoids (spec §10, T27); for the kernel
  // sum the kernel's core radius h s >= Δx/2, so no particle falls between voxels.
  const double level = settings.field == Field::kKernelSum ? h : settings.r_iso * spacing;
  const double s_floor = std::min(1.0, 0.5 * voxel_size / level);
  const bool unit_volume = settings.field == Field::kEllipsoids;
  // A full neighbourhood (the 26 lattice neighbours within 2h at h = d_p) scaled to h / d_p.
  const double full_count = 26.0 * std::pow(h / spacing, 3);
  anisotropy::Params<float> params;
  params.k_s = float(settings.anisotropy.k_s), params.k_r = float(settings.anisotropy.k_r);
  params.k_n = float(settings.anisotropy.k_n), params.n_eps = settings.anisotropy.n_eps;
  params.s_min = float(settings.anisotropy.s_min), params.s_max = float(settings.anisotropy.s_max);
  params.center_on_particle = settings.anisotropy.center_on_particle;

  // Per particle, from its neighbour sums: the smoothed centre and D.
  const auto finish = [&](Index k, const anisotropy::CovarianceAccumulator<float>& acc) {
    const Index i = order[k];
    const Vec3f mean_offset = acc.MeanOffset();
    // Centre smoothing (Yu & Turk): x̄ = (1 − λ) x + λ x̄^w.
    out.centers[i] = local[i] + mean_offset * float(settings.lambda);
    out.interior[i] = acc.neighbors >= 0.9 * full_count && Norm(mean_offset) < 0.1 * spacing;
    if (!anisotropic) return;

    // D = R diag(1/s) Rᵀ with s within the §8 bounds, of unit volume for ellipsoids, then raised to
    // the floor (a non-positive stored D is repaired on the way). Eq. 41 has no det G factor as
    // W_A has: with every s_k <= 1 a surface ellipsoid would be smaller than the interior sphere in
    // all directions and the surface would sink (1.1 voxels on a lattice ball). Unit volume keeps
    // the r_iso sphere's volume (the PCA sets the shape, not the size); stretches stay <= s_max,
    // so a lone protruding particle, elongated outwards by its own weight, does not become a spike.
    anisotropy::Anisotropy<float> a;
    if (stored) {
      const auto& c = particles.stored_anisotropy[i];
      double lo, hi;
      EigenvalueRange(c, lo, hi);
      const double scale = unit_volume && lo > 0 ? std::cbrt(StretchVolume(c)) : 1.0;  // D' = D (Π s)^(1/3)
      if (lo > 0 && WithinBounds(1 / hi, 1 / lo, settings.anisotropy) && hi * scale * s_floor <= 1 &&
          lo * scale * settings.anisotropy.s_max >= 1) {
        // Within every bound after scaling: no eigen-solve (most particles).
        for (int k = 0; k < 6; ++k) out.D[i][k] = float(c[k] * scale);
        out.min_stretch[i] = float(1 / (hi * scale));
        out.max_stretch[i] = float(1 / (lo * scale));
        return;
      }
      Vec3f inv_s;
      SymmetricEigen(anisotropy::FromComponents(c.data()), inv_s, a.rotation);
      for (int k = 0; k < 3; ++k) a.stretch[k] = inv_s[k] > 0 ? 1.0f / inv_s[k] : 1.0f;
      ClampToBounds(a.stretch, settings.anisotropy);
    } else {
      a = anisotropy::Compute(acc.Covariance(params.center_on_particle), acc.neighbors, float(h), params);
    }
    if (unit_volume) {
      a.stretch = a.stretch / std::cbrt(a.stretch.x * a.stretch.y * a.stretch.z);
      for (int k = 0; k < 3; ++k) a.stretch[k] = std::min(a.stretch[k], float(settings.anisotropy.s_max));
    }
    for (int k = 0; k < 3; ++k) a.stretch[k] = std::max(a.stretch[k], float(s_floor));
    anisotropy::ToComponents(a.D(), out.D[i].data());
    out.min_stretch[i] = std::min({a.stretch.x, a.stretch.y, a.stretch.z});
    out.max_stretch[i] = std::max({a.stretch.x, a.stretch.y, a.stretch.z});
  };

  if (!need_neighbors) {
    exec::cpu::ParallelFor(Index(n), [&](Index k) {
      anisotropy::CovarianceAccumulator<float> acc;
      acc.AddSelf(kernel.W0());
      finish(k, acc);
    });
    return out;
  }
  // Cell by cell: the 27 neighbour cells are looked up once for all particles of a cell (in grid
  // order, so slot = index), and up to kSumLanes of its particles are summed side by side (SIMD across
  // particles, candidates in sequence, as the boundary volumes). Each particle's sums add the same
  // terms in the same order whatever the thread count.
  std::vector<float> sx(n), sy(n), sz(n);
  exec::cpu::ParallelFor(Index(n), [&](Index k) { sx[k] = sorted[k].x, sy[k] = sorted[k].y, sz[k] = sorted[k].z; });
  exec::cpu::ParallelFor(Index(grid.cell_count()), [&](Index cell) {
    const neighbors::kernels::CellNeighborhood<float> hood(view, view, std::uint32_t(cell));
    const std::uint32_t begin = view.cell_start[cell], end = view.cell_start[cell + 1];
    for (std::uint32_t s0 = begin; s0 < end; s0 += kSumLanes) {
      const std::uint32_t m = std::min<std::uint32_t>(kSumLanes, end - s0);
      LaneSums sums;
      for (std::uint32_t l = 0; l < kSumLanes; ++l) {
        sums.x[l] = l < m ? sx[s0 + l] : kFar;
        sums.y[l] = l < m ? sy[s0 + l] : kFar;
        sums.z[l] = l < m ? sz[s0 + l] : kFar;
        sums.weight[l] = kernel.W0();  // the particle itself
      }
      for (int c = 0; c < hood.count; ++c)
        for (std::uint32_t t = hood.begin[c]; t < hood.end[c]; ++t) {
          if (need_pca) sums.Add<true>(sx[t], sy[t], sz[t], t - s0, support, kernel);
          else sums.Add<false>(sx[t], sy[t], sz[t], t - s0, support, kernel);
        }
      for (std::uint32_t l = 0; l < m; ++l) finish(s0 + l, sums.Accumulator(l));
    }
  });
  return out;
}

}  // namespace rime::surface

namespace rime::surface {

/// Per-vertex velocity: Shepard average of particle velocities with W weights of support 3h
/// (wider than the 2h kernel so that vertices up to r_iso + band from the particles find some).
std::vector<Vec3f> InterpolateVelocities(const ParticleSet& particles, const std::vector<Vec3f>& points) {
  std::vector<Vec3f> out(points.size(), Vec3f(0, 0, 0));
  if (particles.velocities.empty() || particles.positions.empty() || points.empty()) return out;
  const double h = particles.smoothing_length > 0 ? particles.smoothing_length : particles.spacing;
  const Vec3d origin = particles.positions[0];
  std::vector<Vec3f> local(particles.size());
  for (std::size_t i = 0; i < local.size(); ++i) local[i] = Vec3f(particles.positions[i] - origin);
  const float support = float(3 * h);
  neighbors::UniformGrid<float> grid(exec::Device::Cpu());
  grid.Build(local.data(), Index(local.size()), support);
  const auto view = grid.view();
  const CubicSpline<float> kernel(support / 2);
  exec::cpu::ParallelFor(Index(points.size()), [&](Index v) {
    const Vec3f x = Vec3f(Vec3d(points[v]) - origin);
    float weight = 0;
    Vec3f sum(0, 0, 0);
    view.ForEachNeighbor(x, support, [&](std::uint32_t j, const Vec3f& r, float) {
      const float w = kernel.W(Norm(r));
      weight += w;
      sum += particles.velocities[j] * w;
    });
    if (weight > 0) out[v] = sum / weight;
  });
  return out;
}

}  // namespace rime::surface
