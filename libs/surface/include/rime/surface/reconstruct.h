/// @file reconstruct.h
/// @brief Particles of one phase -> sparse OpenVDB level set `surface` -> triangle mesh
/// (spec §10, paper Eqs. 41–42, Yu & Turk 2013).
///
/// @code
/// rime::surface::ParticleSet ice = rime::surface::SelectPhase(frame, rime::io::Phase::kIce, options);
/// rime::surface::Settings settings = rime::surface::FromScene(scene.surface, scene.surface.ice_field);
/// rime::surface::Result result = rime::surface::Reconstruct(ice, settings);
/// rime::surface::WriteVdb("ice.0001.vdb", result);   // atomic
/// rime::io::WriteMesh("ice.0001.obj", result.mesh);
/// @endcode
///
/// OpenVDB types stay out of this header (they are heavy to compile); the grids live behind
/// Result::grids and are written with WriteVdb.
#pragma once

#include <array>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "rime/core/anisotropy.h"
#include "rime/core/math.h"
#include "rime/io/mesh.h"
#include "rime/io/scene_surface.h"

namespace rime::surface {

// kEllipsoids: union of anisotropic ellipsoids, φ = min_i ‖D_i (x − x̄_i)‖ − r_iso (Eq. 41): ice default;
//   each of (at most) the volume of the r_iso sphere (det D_i = 1, see Prepare).
// kKernelSum: Yu & Turk: Σ_i V_i W_A(x − x̄_i, G_i) at an iso value: water default.
// kIsotropic: union of spheres of radius r_iso (comparison baseline).
// The scene's `[surface] ice_field` names the same enum.
using Field = io::SurfaceField;
Field ParseField(const std::string& name);  // "ellipsoids" | "kernel_sum" | "isotropic"
const char* FieldName(Field field);

/// The scene's `[surface]` defaults: the one declaration of the values below (io::SurfaceSettings).
const io::SurfaceSettings& SceneDefaults();

/// What Reconstruct does. The physical parameters default to the scene's; the level-set filters,
/// the extra grids and the mesh velocities default to off, so Settings{} is the plain field.
struct Settings {
  Field field = Field::kEllipsoids;
  double voxel_size = SceneDefaults().voxel_size;    // m; 0 = voxel_ratio * spacing
  double voxel_ratio = SceneDefaults().voxel_ratio;  // voxel size / d_p when voxel_size = 0
  int resolution = SceneDefaults().resolution;       // > 0: the paper's fixed grid, voxel = longest padded extent / (resolution − 1)
  double r_iso = SceneDefaults().r_iso;              // ellipsoid level, in units of d_p (spec §10)
  double lambda = SceneDefaults().lambda;            // Yu & Turk centre smoothing over same-phase neighbours (0 = off)
  anisotropy::Params<double> anisotropy;             // k_s, k_r, k_n, N_ε, s_min, s_max (spec §8)
  bool recompute_anisotropy = false;                 // ice: PCA over ice neighbours instead of the stored D
  double iso = SceneDefaults().iso;                  // kernel_sum: surface where Σ V W_A = iso
  double half_band = SceneDefaults().half_band;      // narrow band half width, voxels (>= 3)
  double close_radius = 0;          // d_p: morphological closing (dilate, then erode) that fills gaps narrower than twice this
  int smooth_iterations = 0;        // OpenVDB LevelSetFilter mean-curvature iterations after the closing (not for kKernelSum)
  double smooth_limit = 0;          // d_p: the smoothing moves the surface at most this far from the closed one (0 = no limit)
  bool velocity_grid = false;       // also build a `vel` vec3 grid
  bool density_grid = false;        // also build a `density` fog grid
  bool mesh = true;                 // extract the triangle mesh
  bool mesh_velocities = false;     // per-vertex velocity interpolated from particles (PLY)
  bool keep_voids = false;          // keep enclosed voids (gaps between ellipsoids) in the level set and mesh
  bool deep_interior_tiles = true;  // ellipsoids/isotropic, no keep_voids, half_band <= 4: leaves deep inside
                                    // a body become interior tiles without evaluating the field (same result)
};

/// The settings a scene's `[surface]` table asks for, for `field`: what rime-surface runs (with
/// filters, and the grids and mesh its `formats` need).
Settings FromScene(const io::SurfaceSettings& scene, Field field);

/// One phase of one frame, ready for reconstruction.
struct ParticleSet {
  std::vector<Vec3d> positions;                         // m
  std::vector<Vec3f> velocities;                        // m/s; empty = zero
  std::vector<std::array<float, 6>> stored_anisotropy;  // D (xx yy zz xy xz yz); empty = none stored
  double spacing = 0;                                   // d_p, m
  double smoothing_length = 0;                          // h, m (0 = spacing)
  double particle_volume = 0;                           // V_i for the kernel sum, m³ (0 = spacing³)
  std::size_t size() const { return positions.size(); }
};

struct Stats {
  std::uint64_t particles = 0;
  std::uint64_t active_voxels = 0;
  std::uint64_t leaves = 0;
  std::uint64_t deep_leaves = 0;  // leaves deep inside, filled without evaluating the field
  std::uint64_t vertices = 0, triangles = 0;
  std::uint64_t removed_void_shells = 0;  // enclosed inward-facing mesh shells dropped
  std::uint64_t filled_void_voxels = 0;   // enclosed outside voxels turned inside
  double voxel_size = 0;                  // m
  double seconds_prepare = 0;             // centres and anisotropy
  double seconds_rasterize = 0;           // field evaluation, narrow band, pruning
  double seconds_filter = 0;              // smoothing, vel, density
  double seconds_mesh = 0;
  std::uint64_t grid_bytes = 0;  // memory held by the level set
};

struct Grids;  // OpenVDB grids (src/grids.h)

struct Result {
  io::TriMesh mesh;
  Stats stats;
  std::shared_ptr<Grids> grids;
};

/// Per-particle inputs of the field after centre smoothing and anisotropy (spec §8, §10).
struct PreparedParticles {
  std::vector<Vec3f> centers;                   // x̄_i relative to origin, m
  Vec3d origin;                                 // subtracted from positions (float precision far from 0)
  std::vector<std::array<float, 6>> D;          // dimensionless D_i — empty in isotropic mode; ellipsoids:
                                                // det D = 1 unless a stretch hit s_max or the half-voxel floor
  std::vector<float> min_stretch, max_stretch;  // 1/λ_max(D), 1/λ_min(D)
  std::vector<std::uint8_t> interior;           // 1: fully surrounded (its far band cannot be the nearest)
};

/// Centre smoothing and D (stored, recomputed or from a fresh PCA) — no OpenVDB here.
PreparedParticles Prepare(const ParticleSet& particles, const Settings& settings, double voxel_size);

/// Voxel size the settings give for these particles (spacing ratio or fixed resolution).
double VoxelSize(const ParticleSet& particles, const Settings& settings);

/// Peak memory estimate (bytes) of reconstructing these particles: computed from the sparse set
/// of grid leaves the particles touch, without rasterizing.
/// `voxels`, when given, receives the voxel count of those leaves (what the estimate grows with).
std::uint64_t EstimateMemoryBytes(const ParticleSet& particles, const Settings& settings, std::uint64_t* voxels = nullptr);

/// Throws rime::Error(kBadInput) for invalid settings or particles (non-finite positions...).
Result Reconstruct(const ParticleSet& particles, const Settings& settings);

/// Writes `surface` (+ `vel`, `density` when built) atomically. An empty result gives a valid
/// file holding an empty level set.
void WriteVdb(const std::filesystem::path& path, const Result& result);

/// Reads back a VDB file's grid names, class and voxel size (for tests and checks).
struct VdbGridInfo {
  std::string name;
  std::string grid_class;  // "level set", "fog volume", "unknown"
  double voxel_size = 0;
  std::uint64_t active_voxels = 0;
  double background = 0;
};
std::vector<VdbGridInfo> InspectVdb(const std::filesystem::path& path);

/// Samples the `surface` grid of a result at world positions (trilinear); for tests.
std::vector<float> SampleSurface(const Result& result, const std::vector<Vec3d>& points);

}  // namespace rime::surface
