/// @file object.h
/// @brief One solid of a scene turned into its boundary particle file (stage 1 of the bake).
///
/// @code
/// rime::boundary::BoundarySettings settings;       // d_p, d_b/d_p, h/d_p, device, limits
/// auto object = rime::boundary::BuildBoundaryObject(solid, 0, scene.Resolve(solid.mesh), settings);
/// rime::boundary::WriteBoundaryFile("out/boundary/tank.h5part", object, scene.hash);
/// @endcode
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "rime/boundary/sampler.h"
#include "rime/core/math.h"
#include "rime/exec/device.h"
#include "rime/io/particles.h"
#include "rime/io/scene.h"

namespace rime::boundary {

struct BoundarySettings {
  double particle_spacing = 0.02;  // fluid d_p, m (scene [water] spacing)
  double smoothing_ratio = 1.0;    // h / d_p (spec §1)
  double rest_density = 1000;      // rho0, kg/m^3 (metadata only)
  std::uint64_t max_particles = 50'000'000;
  exec::Device device = exec::Device::Cpu();
  /// Called once per object before sampling allocates, with the mesh's triangles and the particles
  /// estimated from its area (a procedural shape: before it is tessellated); may throw to refuse.
  std::function<void(double triangles, double particles, const std::string& where)> before_sampling;

  /// The spacing, smoothing ratio and rest density of the scene's `[water]`, which the boundary follows.
  void UseWater(const io::FluidSettings& water) {
    particle_spacing = water.spacing;
    smoothing_ratio = water.smoothing_ratio;
    rest_density = water.rest_density;
  }
};

struct BoundaryObject {
  std::string name, shape, source;  // source: mesh file, or "procedural"
  std::string mesh_hash;            // xxHash64 of the mesh file, or of the procedural parameters
  std::string transform_text;
  std::uint32_t object_id = 0;
  double particle_spacing = 0, boundary_spacing = 0, smoothing_length = 0, rest_density = 1000;
  std::size_t meshes = 0;  // parts in the file (1 for procedural shapes)
  SampleStats stats;       // summed over parts
  std::vector<Vec3f> positions, normals;
  std::vector<float> volumes;  // V_b, m^3 (spec §3)
  double mean_spacing = 0;     // mean nearest-neighbour distance, m
  Vec3f bounds_min{0, 0, 0}, bounds_max{0, 0, 0};
  double seconds = 0;  // wall time to build (load, sample, volumes)
  std::size_t size() const { return positions.size(); }
};

/// Loads or builds the solid's mesh, applies its transform, samples it at
/// d_b = object.spacing_ratio * d_p and computes V_b with h = smoothing_ratio * d_p.
/// `mesh_path` is the resolved file for shape = "mesh" (ignored otherwise).
/// Throws rime::Error(kBadInput) naming the file or object for every bad input.
BoundaryObject BuildBoundaryObject(const io::SolidObject& object, std::uint32_t object_id, const std::filesystem::path& mesh_path,
                                   const BoundarySettings& settings);

/// The H5Part frame of kind "boundary": x y z, normal_0..2, volume (float32), object_id (uint32),
/// phase (uint8, 1 = boundary), id (int64, index within the file), and the metadata.
io::ParticleFrame ToParticleFrame(const BoundaryObject& object, const std::string& scene_hash = {});

/// Writes ToParticleFrame(object) atomically.
void WriteBoundaryFile(const std::filesystem::path& path, const BoundaryObject& object, const std::string& scene_hash = {});

}  // namespace rime::boundary
