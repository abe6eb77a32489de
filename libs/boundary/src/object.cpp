#include "rime/boundary/object.h"

#include <fmt/format.h>

#include <chrono>
#include <cmath>

#include "rime/boundary/shapes.h"
#include "rime/boundary/volumes.h"
#include "rime/core/error.h"
#include "rime/core/hash.h"
#include "rime/core/log.h"
#include "rime/io/mesh_import.h"

namespace rime::boundary {
namespace {

void RequirePositive(double value, const std::string& what, const std::string& where) {
  if (!(value > 0) || !std::isfinite(value)) throw InputError(fmt::format("{} must be positive and finite, got {}", what, value), where);
}

std::string ProceduralKey(const io::SolidObject& o) {
  return fmt::format("shape={} size=({:.17g},{:.17g},{:.17g}) radius={:.17g} minor_radius={:.17g} height={:.17g} container={}",
                     io::EnumName(o.shape), o.size.x, o.size.y, o.size.z, o.radius, o.minor_radius, o.height, o.container);
}

void Append(SurfaceSamples& all, SurfaceSamples&& part) {
  all.positions.insert(all.positions.end(), part.positions.begin(), part.positions.end());
  all.normals.insert(all.normals.end(), part.normals.begin(), part.normals.end());
  SampleStats& s = all.stats;
  const SampleStats& p = part.stats;
  s.triangles += p.triangles, s.degenerate_skipped += p.degenerate_skipped, s.welded_vertices += p.welded_vertices;
  s.edges += p.edges, s.vertex_samples += p.vertex_samples, s.edge_samples += p.edge_samples;
  s.face_samples += p.face_samples, s.near_duplicates_removed += p.near_duplicates_removed;
}

}  // namespace

BoundaryObject BuildBoundaryObject(const io::SolidObject& object, std::uint32_t object_id, const std::filesystem::path& mesh_path,
                                   const BoundarySettings& settings) {
  const auto start = std::chrono::steady_clock::now();
  const bool from_file = object.shape == io::SolidShape::kMesh;
  const std::string where = from_file ? mesh_path.string() : "solid " + object.name;
  RequirePositive(settings.particle_spacing, "particle spacing", where);
  RequirePositive(object.spacing_ratio, "spacing ratio", where);
  RequirePositive(settings.smoothing_ratio, "smoothing ratio", where);

  BoundaryObject out;
  out.name = object.name;
  out.shape = io::EnumName(object.shape);
  out.object_id = object_id;
  out.particle_spacing = settings.particle_spacing;
  out.boundary_spacing = object.spacing_ratio * settings.particle_spacing;
  out.smoothing_length = settings.smoothing_ratio * settings.particle_spacing;
  out.rest_density = settings.rest_density;
  out.transform_text = DescribeTransform(object.transform);

  SampleOptions options;
  options.spacing = out.boundary_spacing;
  options.max_particles = settings.max_particles;
  options.source = where;

  std::vector<io::TriMesh> parts;
  if (from_file) {
    out.source = mesh_path.string();
    io::ImportStats import_stats;
    if (object.merge_meshes) parts.push_back(io::ImportMesh(mesh_path, {}, &import_stats));
    else parts = io::ImportMeshParts(mesh_path, &import_stats);
    out.meshes = import_stats.meshes;
    out.mesh_hash = HexHash(HashFile(mesh_path));
  } else {
    out.source = "procedural";
    const double estimate = ProceduralSurfaceArea(object) / (out.boundary_spacing * out.boundary_spacing);
    if (estimate > double(settings.max_particles))
      throw InputError(fmt::format("spacing {:g} m would make about {:.3g} boundary particles, more than the maximum {} "
                                   "(use a larger spacing or raise --max-particles)",
                                   out.boundary_spacing, estimate, settings.max_particles),
                       where);
    // A tessellation at d_b has about two triangles per particle.
    if (settings.before_sampling) settings.before_sampling(2 * estimate, estimate, where);
    // Tessellate so that edges are at most d_b after the transform's scale.
    const double stretch = MakeTransform(object.transform).MaxStretch();
    parts.push_back(MakeProceduralMesh(object, out.boundary_spacing / std::max(stretch, 1e-30)));
    out.meshes = 1;
    out.mesh_hash = HexHash(Hash64(ProceduralKey(object)));
  }

  for (io::TriMesh& part : parts) ApplyTransform(part, object.transform);
  if (settings.before_sampling && from_file) {
    double triangles = 0, particles = 0;
    for (const io::TriMesh& part : parts)
      triangles += double(part.triangle_count()), particles += EstimateSampleCount(part, options.spacing);
    // Beyond --max-particles the sampler refuses the input itself (exit 3), before any memory.
    if (particles <= double(settings.max_particles)) settings.before_sampling(triangles, particles, where);
  }
  SurfaceSamples samples;
  for (io::TriMesh& part : parts) Append(samples, SampleSurface(part, options));
  if (samples.positions.size() > settings.max_particles)
    throw InputError(fmt::format("{} boundary particles, more than the maximum {}", samples.positions.size(), settings.max_particles),
                     where);
  out.stats = samples.stats;
  out.positions = std::move(samples.positions);
  out.normals = std::move(samples.normals);
  out.volumes = ComputeBoundaryVolumes<float>(settings.device, out.positions, float(out.smoothing_length));

  const auto nearest = NearestNeighborDistances(out.positions, float(2 * out.boundary_spacing));
  double sum = 0;
  std::size_t counted = 0;
  for (float r : nearest)
    if (std::isfinite(r)) sum += r, ++counted;
  out.mean_spacing = counted ? sum / double(counted) : 0;
  if (!out.positions.empty()) {
    out.bounds_min = out.bounds_max = out.positions.front();
    for (const Vec3f& p : out.positions) out.bounds_min = Min(out.bounds_min, p), out.bounds_max = Max(out.bounds_max, p);
  }
  out.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return out;
}

io::ParticleFrame ToParticleFrame(const BoundaryObject& object, const std::string& scene_hash) {
  io::ParticleFrame frame;
  frame.kind = "boundary";
  frame.spacing = object.particle_spacing;
  frame.particle_radius = 0.5 * object.particle_spacing;
  frame.rest_density = object.rest_density;
  frame.scene_hash = scene_hash;
  frame.numbers["boundary_spacing"] = object.boundary_spacing;
  frame.numbers["smoothing_length"] = object.smoothing_length;
  frame.numbers["object_id"] = object.object_id;
  frame.texts["object_name"] = object.name;
  frame.texts["shape"] = object.shape;
  frame.texts["mesh_hash"] = object.mesh_hash;
  frame.texts["transform"] = object.transform_text;
  frame.texts["source"] = object.source;
  const std::size_t n = object.size();
  frame.SetPositions(object.positions);
  frame.SetVec3("normal", object.normals);
  frame.Set("volume", object.volumes);
  frame.Set("object_id", std::vector<std::uint32_t>(n, object.object_id));
  frame.Set("phase", std::vector<std::uint8_t>(n, static_cast<std::uint8_t>(io::Phase::kBoundary)));
  std::vector<std::int64_t> ids(n);
  for (std::size_t i = 0; i < n; ++i) ids[i] = static_cast<std::int64_t>(i);
  frame.Set("id", std::move(ids));
  return frame;
}

void WriteBoundaryFile(const std::filesystem::path& path, const BoundaryObject& object, const std::string& scene_hash) {
  io::WriteParticleFrame(path, ToParticleFrame(object, scene_hash));
}

}  // namespace rime::boundary
