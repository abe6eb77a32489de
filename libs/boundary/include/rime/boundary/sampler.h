/// @file sampler.h
/// @brief Surface sampling of a triangle mesh with boundary particles (Akinci et al. 2012, spec §3).
///
/// One layer of particles at spacing d_b: one on every vertex, evenly spaced ones inside every
/// edge, and rows inside every face at least 0.55 d_b from its edges. Vertices with identical
/// positions are welded first, so an edge shared by several triangles is sampled once. Degenerate
/// triangles (repeated vertex, zero area) are skipped and counted. A last pass removes particles
/// closer than 0.5 d_b to a kept one (vertices win over edges, edges over faces), which handles
/// tiny triangles, needle tips, unwelded seams and intersecting parts in O(n) with a grid, and
/// leaves the particles in Z-curve order. Every phase runs in parallel, and the output (particles,
/// their order, the statistics) is the same for any number of threads.
///
/// @code
/// rime::boundary::SampleOptions options{.spacing = 0.01};
/// rime::boundary::SurfaceSamples s = rime::boundary::SampleSurface(mesh, options);
/// // s.positions[i], s.normals[i] (unit, pointing out of the solid)
/// @endcode
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "rime/core/math.h"
#include "rime/exec/device.h"
#include "rime/io/mesh.h"

namespace rime::boundary {

struct SampleOptions {
  double spacing = 0.01;                     // d_b, m
  std::uint64_t max_particles = 50'000'000;  // refuse before sampling when more would be made
  bool remove_near_duplicates = true;        // the final 0.5 d_b thinning pass (and Z-curve order)
  std::string source = "mesh";               // named in error messages (file path or object name)
};

struct SampleStats {
  std::size_t triangles = 0;           // triangles in the input
  std::size_t degenerate_skipped = 0;  // repeated vertex or zero area
  std::size_t welded_vertices = 0;     // distinct vertex positions used by valid triangles
  std::size_t edges = 0;               // distinct edges
  std::size_t vertex_samples = 0, edge_samples = 0, face_samples = 0;
  std::size_t near_duplicates_removed = 0;
};

struct SurfaceSamples {
  std::vector<Vec3f> positions;  // m
  std::vector<Vec3f> normals;    // unit; vertex: area-weighted, edge: area-weighted over its faces, face: face normal
  SampleStats stats;
  std::size_t size() const { return positions.size(); }
};

/// Particles the mesh would get at `spacing` (area / d_b^2 plus edges and vertices), computed
/// without allocating; used to refuse a spacing before sampling.
double EstimateSampleCount(const io::TriMesh& mesh, double spacing);

/// Samples the mesh. Throws rime::Error(kBadInput) naming options.source for a non-positive or
/// non-finite spacing, NaN/Inf coordinates, out-of-range indices, no valid triangle, or more than
/// max_particles particles.
SurfaceSamples SampleSurface(const io::TriMesh& mesh, const SampleOptions& options);

/// Distance from every point to its nearest other point, or +inf when none is closer than
/// `search_radius` (grid search on the CPU).
std::vector<float> NearestNeighborDistances(const std::vector<Vec3f>& points, float search_radius);

}  // namespace rime::boundary
