// Ice look metrics (rime/clean/ice_metrics.h); the definitions are in docs/ice-metrics.md.
#include "rime/clean/ice_metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <queue>

#include "rime/core/union_find.h"
#include "rime/exec/device.h"
#include "rime/neighbors/grid.h"

namespace rime::clean {
namespace {

/// CSR lists of `points` within `radius` of each query (host vectors).
struct Lists {
  std::vector<std::uint32_t> offsets, indices;
  std::pair<const std::uint32_t*, const std::uint32_t*> Row(std::size_t i) const {
    return {indices.data() + offsets[i], indices.data() + offsets[i + 1]};
  }
};

Lists Within(const std::vector<Vec3f>& points, const std::vector<Vec3f>& queries, float radius, bool exclude_self) {
  Lists out;
  if (points.empty() || queries.empty()) {
    out.offsets.assign(queries.size() + 1, 0);
    return out;
  }
  const exec::Device cpu = exec::Device::Cpu();
  exec::DeviceArray<Vec3f> p(cpu, points), q(cpu, queries);
  neighbors::UniformGrid<float> grid(cpu);
  grid.Build(p.data(), Index(points.size()), radius);
  neighbors::NeighborList list(cpu);
  grid.Query(q.data(), Index(queries.size()), radius, exclude_self, list);
  out.offsets = list.offsets.ToHost();
  out.indices = list.indices.ToHost();
  return out;
}

double AngleDeg(const Vec3d& a, const Vec3d& b) {
  const double na = Norm(a), nb = Norm(b);
  if (!(na > 0 && nb > 0)) return -1;
  return std::acos(std::clamp(Dot(a, b) / (na * nb), -1.0, 1.0)) * 180 / std::numbers::pi;
}

/// Taubin λ|μ smoothing with uniform weights: removes the short wavelengths without shrinking.
std::vector<Vec3d> TaubinSmoothed(const io::TriMesh& mesh, int iterations) {
  const std::size_t nv = mesh.positions.size();
  std::vector<std::vector<std::uint32_t>> ring(nv);
  for (const auto& t : mesh.triangles)
    for (int e = 0; e < 3; ++e) {
      ring[t[e]].push_back(t[(e + 1) % 3]);
      ring[t[(e + 1) % 3]].push_back(t[e]);
    }
  for (auto& r : ring) {
    std::sort(r.begin(), r.end());
    r.erase(std::unique(r.begin(), r.end()), r.end());
  }
  std::vector<Vec3d> x(nv), next(nv);
  for (std::size_t v = 0; v < nv; ++v) x[v] = Vec3d(mesh.positions[v]);
  for (int it = 0; it < 2 * iterations; ++it) {
    const double factor = it % 2 == 0 ? 0.5 : -0.53;
    for (std::size_t v = 0; v < nv; ++v) {
      if (ring[v].empty()) {
        next[v] = x[v];
        continue;
      }
      Vec3d mean(0, 0, 0);
      for (auto u : ring[v]) mean += x[u];
      next[v] = x[v] + factor * (mean / double(ring[v].size()) - x[v]);
    }
    std::swap(x, next);
  }
  return x;
}

void MeasureMesh(const io::TriMesh& mesh, const std::vector<Vec3f>& solid, double dp, const IceMetricsSettings& s, IceMetrics& m) {
  const std::size_t nv = mesh.positions.size();
  m.triangles = mesh.triangles.size();
  if (m.triangles == 0) return;

  // Per-vertex area (a third of each incident triangle) and the cotangent mean-curvature normal.
  std::vector<double> vertex_area(nv, 0.0);
  std::vector<Vec3d> curvature_normal(nv, Vec3d(0, 0, 0));
  double volume = 0;  // divergence theorem, signed; exact for the closed meshes rime-clean writes
  for (const auto& t : mesh.triangles) {
    const Vec3d p[3] = {Vec3d(mesh.positions[t[0]]), Vec3d(mesh.positions[t[1]]), Vec3d(mesh.positions[t[2]])};
    const double area = 0.5 * Norm(Cross(p[1] - p[0], p[2] - p[0]));
    m.area += area;
    volume += Dot(p[0], Cross(p[1], p[2])) / 6;
    for (int k = 0; k < 3; ++k) vertex_area[t[k]] += area / 3;
    if (!(area > 0)) continue;
    for (int k = 0; k < 3; ++k) {  // the angle at corner k weighs the opposite edge (i, j)
      const int i = (k + 1) % 3, j = (k + 2) % 3;
      const Vec3d a = p[i] - p[k], b = p[j] - p[k];
      // Slivers of a marching-cubes mesh have huge cotangents; clamping keeps one from dominating.
      const double cot = std::clamp(Dot(a, b) / Norm(Cross(a, b)), -10.0, 10.0);
      curvature_normal[t[i]] += 0.5 * cot * (p[j] - p[i]);
      curvature_normal[t[j]] += 0.5 * cot * (p[i] - p[j]);
    }
  }
  double sharp = 0;
  for (std::size_t v = 0; v < nv; ++v)
    if (vertex_area[v] > 0 && Norm(curvature_normal[v]) / (2 * vertex_area[v]) * dp > s.sharp_curvature) sharp += vertex_area[v];
  m.sharp_area_fraction = m.area > 0 ? sharp / m.area : 0;
  m.volume_ratio = m.ice > 0 ? volume / (double(m.ice) * dp * dp * dp) : 0;

  double edge_sum = 0;
  for (const auto& t : mesh.triangles)
    for (int e = 0; e < 3; ++e) edge_sum += Norm(mesh.positions[t[e]] - mesh.positions[t[(e + 1) % 3]]);
  const double mean_edge = edge_sum / double(3 * m.triangles);
  m.smoothing_passes = int(std::clamp(std::round(s.smoothing_passes * std::pow(0.5 * dp / mean_edge, 2)), 1.0, 500.0));
  const std::vector<Vec3d> smooth = TaubinSmoothed(mesh, m.smoothing_passes);
  // Only the displacement along the surface normal is a distance between the two surfaces: the
  // uniform Laplacian also slides vertices along the surface wherever the triangles are uneven.
  std::vector<Vec3d> normal(nv, Vec3d(0, 0, 0));
  for (const auto& t : mesh.triangles) {
    const Vec3d area_normal = Cross(Vec3d(mesh.positions[t[1]] - mesh.positions[t[0]]), Vec3d(mesh.positions[t[2]] - mesh.positions[t[0]]));
    for (std::uint32_t v : t) normal[v] += area_normal;
  }
  double sum = 0, weight = 0;
  for (std::size_t v = 0; v < nv; ++v) {
    const double length = Norm(normal[v]);
    if (!(length > 0)) continue;
    const double d = Dot(Vec3d(mesh.positions[v]) - smooth[v], normal[v]) / length;
    sum += vertex_area[v] * d * d;
    weight += vertex_area[v];
  }
  m.noise_rms = weight > 0 ? std::sqrt(sum / weight) / dp : 0;

  // Pieces: edge-connected triangles; per piece the Euler characteristic, bounds and solid contact.
  UnionFind sets(nv);
  for (const auto& t : mesh.triangles) sets.Unite(t[0], t[1]), sets.Unite(t[1], t[2]);
  std::vector<std::uint8_t> used(nv, 0);
  for (const auto& t : mesh.triangles)
    for (auto v : t) used[v] = 1;
  const Lists near_solid = Within(solid, mesh.positions, float(s.contact_distance * dp), false);
  struct Piece {
    std::int64_t vertices = 0, faces = 0, edges2 = 0;  // edges2: half-edges
    Vec3d lo{1e300, 1e300, 1e300}, hi{-1e300, -1e300, -1e300};
    bool touches = false;
    std::int64_t boundary_edges = 0;
  };
  std::vector<std::int64_t> piece_of(nv, -1);
  std::vector<Piece> pieces;
  for (std::size_t v = 0; v < nv; ++v) {
    if (!used[v]) continue;
    const std::uint32_t root = sets.Find(std::uint32_t(v));
    if (piece_of[root] < 0) piece_of[root] = std::int64_t(pieces.size()), pieces.emplace_back();
    Piece& p = pieces[piece_of[root]];
    ++p.vertices;
    const Vec3d x(mesh.positions[v]);
    p.lo = Vec3d(std::min(p.lo.x, x.x), std::min(p.lo.y, x.y), std::min(p.lo.z, x.z));
    p.hi = Vec3d(std::max(p.hi.x, x.x), std::max(p.hi.y, x.y), std::max(p.hi.z, x.z));
    if (near_solid.offsets[v] != near_solid.offsets[v + 1]) p.touches = true;
  }
  // Edges counted once each through a sorted list of (min, max) vertex pairs.
  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges;
  edges.reserve(3 * mesh.triangles.size());
  for (const auto& t : mesh.triangles) {
    pieces[piece_of[sets.Find(t[0])]].faces++;
    for (int e = 0; e < 3; ++e) edges.emplace_back(std::min(t[e], t[(e + 1) % 3]), std::max(t[e], t[(e + 1) % 3]));
  }
  std::sort(edges.begin(), edges.end());
  for (std::size_t i = 0; i < edges.size();) {
    std::size_t j = i;
    while (j < edges.size() && edges[j] == edges[i]) ++j;
    Piece& p = pieces[piece_of[sets.Find(edges[i].first)]];
    ++p.edges2;
    if (j - i == 1) ++p.boundary_edges;
    i = j;
  }
  m.components = pieces.size();
  for (const Piece& p : pieces) {
    if (!p.touches) ++m.specks;
    if (Norm(p.hi - p.lo) <= s.tiny_size * dp) ++m.tiny_pieces;
    const std::int64_t euler = p.vertices - p.edges2 + p.faces;
    if (p.boundary_edges == 0 && euler < 2) m.handles += (2 - euler) / 2;
  }
  m.handles_per_1000_dp2 = m.area > 0 ? 1000.0 * double(m.handles) / (m.area / (dp * dp)) : 0;
}

void MeasureParticles(const io::ParticleFrame& frame, const Vec3d& gravity, const std::set<std::uint32_t>& objects,
                      const IceMetricsSettings& s, const std::vector<Vec3f>& x, IceMetrics& m) {
  const double dp = frame.spacing;
  const std::vector<std::uint8_t>& phase = frame.Get<std::uint8_t>("phase");
  const std::size_t n = phase.size();
  std::vector<std::uint32_t> ice, solid;
  for (std::uint32_t i = 0; i < n; ++i) {
    if (phase[i] == std::uint8_t(io::Phase::kFluid)) ++m.water;
    if (phase[i] == std::uint8_t(io::Phase::kIce)) ice.push_back(i);
    if (phase[i] == std::uint8_t(io::Phase::kBoundary)) solid.push_back(i);
  }
  m.ice = ice.size();
  const auto gather = [&](const std::vector<std::uint32_t>& ids) {
    std::vector<Vec3f> out(ids.size());
    for (std::size_t k = 0; k < ids.size(); ++k) out[k] = x[ids[k]];
    return out;
  };
  const std::vector<Vec3f> ice_x = gather(ice), solid_x = gather(solid);
  const float contact = float(s.contact_distance * dp);

  // Distance from the solid through the ice (Dijkstra over ice particles within contact distance,
  // seeded with each ice particle's distance to its nearest solid particle).
  std::vector<double> depth(ice.size(), std::numeric_limits<double>::infinity());
  const Lists ice_solid = Within(solid_x, ice_x, contact, false);
  const Lists ice_ice = Within(ice_x, ice_x, contact, true);
  using Entry = std::pair<double, std::uint32_t>;
  std::priority_queue<Entry, std::vector<Entry>, std::greater<>> queue;
  for (std::uint32_t k = 0; k < ice.size(); ++k) {
    auto [b, e] = ice_solid.Row(k);
    for (; b != e; ++b) depth[k] = std::min(depth[k], double(Norm(ice_x[k] - solid_x[*b])));
    if (std::isfinite(depth[k])) queue.emplace(depth[k], k);
  }
  while (!queue.empty()) {
    auto [d, k] = queue.top();
    queue.pop();
    if (d > depth[k]) continue;
    auto [b, e] = ice_ice.Row(k);
    for (; b != e; ++b) {
      const double next = d + Norm(ice_x[k] - ice_x[*b]);
      if (next < depth[*b]) depth[*b] = next, queue.emplace(next, *b);
    }
  }
  for (double d : depth) m.floating_ice += !std::isfinite(d);

  // Glaze: wetted solid particles of the measured objects, covered when ice lies within contact.
  std::vector<double> film(n, 0.0);
  if (frame.Has("water_film")) {
    const auto& data = frame.attributes.at("water_film");
    std::visit(
        [&](const auto& values) {
          for (std::size_t i = 0; i < n; ++i) film[i] = double(values[i]);
        },
        data);
  }
  std::vector<std::uint32_t> object(n, 0);
  if (frame.Has("object_id")) object = frame.Get<std::uint32_t>("object_id");
  const Lists solid_ice = Within(ice_x, solid_x, contact, false);
  double sum = 0, sum2 = 0;
  for (std::uint32_t k = 0; k < solid.size(); ++k) {
    const std::uint32_t i = solid[k];
    if (!(film[i] > 1e-3) || (!objects.empty() && !objects.count(object[i]))) continue;
    ++m.wetted;
    auto [b, e] = solid_ice.Row(k);
    if (b == e) continue;
    ++m.covered;
    // Thickness: the deepest ice within contact distance of this point, plus a particle radius.
    double deepest = 0;
    for (; b != e; ++b)
      if (std::isfinite(depth[*b])) deepest = std::max(deepest, depth[*b]);
    const double t = deepest / dp + 0.5;
    sum += t, sum2 += t * t;
  }
  m.glaze_coverage = m.wetted ? double(m.covered) / double(m.wetted) : 0;
  if (m.covered) {
    m.thickness_mean = sum / double(m.covered);
    m.thickness_spread = std::sqrt(std::max(0.0, sum2 / double(m.covered) - m.thickness_mean * m.thickness_mean));
  }

  // Icicles: connected sets of ice deeper than icicle_base; axis from the centroid of their
  // shallowest layer to the deepest particle.
  const double base = s.icicle_base * dp;
  UnionFind sets(ice.size());
  for (std::uint32_t k = 0; k < ice.size(); ++k) {
    if (!(depth[k] > base) || !std::isfinite(depth[k])) continue;
    auto [b, e] = ice_ice.Row(k);
    for (; b != e; ++b)
      if (depth[*b] > base && std::isfinite(depth[*b])) sets.Unite(k, *b);
  }
  std::vector<std::vector<std::uint32_t>> groups;
  std::vector<std::int64_t> group_of(ice.size(), -1);
  for (std::uint32_t k = 0; k < ice.size(); ++k) {
    if (!(depth[k] > base) || !std::isfinite(depth[k])) continue;
    const std::uint32_t r = sets.Find(k);
    if (group_of[r] < 0) group_of[r] = std::int64_t(groups.size()), groups.emplace_back();
    groups[group_of[r]].push_back(k);
  }
  const bool have_growth = frame.HasVec3("growth_dir");
  std::vector<Vec3d> growth;
  if (have_growth) {
    const auto& data = frame.attributes.at("growth_dir_0");
    if (std::holds_alternative<std::vector<double>>(data)) {
      for (const auto& g : frame.GetVec3<double>("growth_dir")) growth.push_back(g);
    } else {
      for (const auto& g : frame.GetVec3<float>("growth_dir")) growth.push_back(Vec3d(g));
    }
  }
  for (const auto& group : groups) {
    double deepest = 0, shallowest = std::numeric_limits<double>::infinity();
    std::uint32_t tip = group.front();
    for (auto k : group) {
      if (depth[k] > deepest) deepest = depth[k], tip = k;
      shallowest = std::min(shallowest, depth[k]);
    }
    if (deepest < s.icicle_length * dp) continue;
    Vec3d base_sum(0, 0, 0);
    std::size_t base_count = 0;
    Vec3d flow(0, 0, 0);
    for (auto k : group) {
      if (depth[k] <= shallowest + dp) base_sum += Vec3d(ice_x[k]), ++base_count;
      if (have_growth) {
        const Vec3d g = growth[ice[k]];
        if (Norm(g) > 0) flow += g / Norm(g);
      }
    }
    Icicle icicle;
    icicle.base = base_sum / double(base_count);
    icicle.tip = Vec3d(ice_x[tip]);
    const Vec3d axis = icicle.tip - icicle.base;
    const double axis_length = Norm(axis);
    double lateral2 = 0;
    for (auto k : group) {
      const Vec3d r = Vec3d(ice_x[k]) - icicle.base;
      const double along = axis_length > 0 ? Dot(r, axis) / axis_length : 0;
      lateral2 += std::max(0.0, Dot(r, r) - along * along);
    }
    icicle.width = 2 * std::sqrt(lateral2 / double(group.size())) / dp;
    icicle.length = deepest / dp;
    if (icicle.length < s.icicle_slenderness * icicle.width) continue;
    icicle.particles = group.size();
    icicle.angle_to_gravity_deg = AngleDeg(axis, gravity);
    icicle.angle_to_flow_deg = AngleDeg(axis, flow);
    if (icicle.angle_to_gravity_deg >= 0 && icicle.angle_to_gravity_deg <= s.hanging_angle_deg) ++m.hanging_icicles;
    m.icicle_length_max = std::max(m.icicle_length_max, icicle.length);
    m.icicle_length_mean += icicle.length;
    m.icicles.push_back(icicle);
  }
  if (!m.icicles.empty()) m.icicle_length_mean /= double(m.icicles.size());
}

}  // namespace

IceMetrics MeasureIce(const io::TriMesh& mesh, const io::ParticleFrame& frame, const Vec3d& gravity, const std::set<std::uint32_t>& objects,
                      const IceMetricsSettings& settings) {
  IceMetrics m;
  const double dp = frame.spacing;
  std::vector<Vec3f> x;
  if (frame.Has("x") && std::holds_alternative<std::vector<double>>(frame.attributes.at("x"))) {
    for (const auto& p : frame.GetPositions<double>()) x.push_back(Vec3f(p));
  } else if (frame.Has("x")) {
    x = frame.GetPositions<float>();
  }
  std::vector<Vec3f> solid;
  if (frame.Has("phase")) {
    const auto& phase = frame.Get<std::uint8_t>("phase");
    for (std::size_t i = 0; i < phase.size(); ++i)
      if (phase[i] == std::uint8_t(io::Phase::kBoundary)) solid.push_back(x[i]);
    MeasureParticles(frame, gravity, objects, settings, x, m);
  }
  MeasureMesh(mesh, solid, dp, settings, m);
  return m;
}

}  // namespace rime::clean
