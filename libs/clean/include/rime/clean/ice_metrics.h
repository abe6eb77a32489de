/// @file ice_metrics.h
/// @brief What an artist sees in a frame's ice, as numbers: specks, particle-scale noise,
/// topology, glaze coverage and thickness, icicles (docs/ice-metrics.md defines each).
///
/// @code
/// rime::io::TriMesh mesh = rime::io::ReadMesh("out/default/clean/ice_clean.0036.obj");
/// rime::io::ParticleFrame frame = rime::io::ReadParticleFrame("out/default/cache/sim/particles.0036.h5part");
/// rime::clean::IceMetricsSettings settings;   // lengths in particle spacings d_p
/// rime::clean::IceMetrics m = rime::clean::MeasureIce(mesh, frame, {0, 0, -9.81}, {1}, settings);
/// @endcode
#pragma once

#include <cstddef>
#include <cstdint>
#include <set>
#include <vector>

#include "rime/core/math.h"
#include "rime/io/mesh.h"
#include "rime/io/particles.h"

namespace rime::clean {

/// Lengths are in particle spacings d_p (the frame's `spacing`).
struct IceMetricsSettings {
  double contact_distance = 1.5;  // a mesh piece with no vertex this close to a solid is a speck
  double tiny_size = 3;           // a piece whose bounding-box diagonal is at most this is tiny
  // Taubin λ|μ passes of the smoothed copy the noise is measured against, for a mesh whose edges
  // are d_p/2 long; scaled by (d_p/2 ÷ mean edge)² so the measured wavelength does not depend on the mesh.
  double smoothing_passes = 10;
  double sharp_curvature = 1;       // area where |H|·d_p exceeds this is particle-scale curvature
  double icicle_base = 2;           // ice farther than this from any solid (through the ice) protrudes
  double icicle_length = 3;         // a protrusion reaching this far from the solid is an icicle ...
  double icicle_slenderness = 1.5;  // ... when its length is at least this times its width
  double hanging_angle_deg = 45;    // an icicle within this angle of gravity hangs
};

struct Icicle {
  double length = 0;                  // d_p, from the solid surface through the ice to the tip
  double width = 0;                   // d_p, twice the RMS distance of its particles from its axis
  Vec3d base{0, 0, 0}, tip{0, 0, 0};  // m
  double angle_to_gravity_deg = 0;    // axis (base -> tip) against gravity's direction
  double angle_to_flow_deg = -1;      // axis against the mean growth direction of its ice; -1 = none recorded
  std::size_t particles = 0;
};

struct IceMetrics {
  // From the mesh.
  std::size_t triangles = 0;
  std::size_t components = 0;
  std::size_t specks = 0;       // pieces touching no solid
  std::size_t tiny_pieces = 0;  // pieces at most tiny_size across
  double area = 0;              // m²
  std::int64_t handles = 0;     // Σ genus over closed pieces (tunnels and sampling holes)
  double handles_per_1000_dp2 = 0;
  double noise_rms = 0;            // d_p: area-weighted RMS distance to the Taubin-smoothed copy
  int smoothing_passes = 0;        // Taubin passes used for noise_rms (from the mean edge length)
  double sharp_area_fraction = 0;  // of the area, where |H|·d_p > sharp_curvature
  double volume_ratio = 0;         // enclosed volume / (ice particles × d_p³): what the surfacing kept
  // From the particles.
  std::size_t water = 0, ice = 0, floating_ice = 0;  // floating: ice connected to no solid
  std::size_t wetted = 0;                            // solid particles of the measured objects with a water film
  std::size_t covered = 0;                           // of those, with ice within contact_distance
  double glaze_coverage = 0;                         // covered / wetted
  double thickness_mean = 0, thickness_spread = 0;   // d_p, over covered particles (spread: std)
  std::vector<Icicle> icicles;
  std::size_t hanging_icicles = 0;
  double icicle_length_mean = 0, icicle_length_max = 0;  // d_p
};

/// Measures one frame. `objects` lists the object ids (order of the scene's [[solid]]s) whose
/// surface counts for glaze coverage (e.g. every solid except the ground); empty = every solid.
/// Specks and icicles are measured against every solid. The mesh may be empty.
IceMetrics MeasureIce(const io::TriMesh& mesh, const io::ParticleFrame& frame, const Vec3d& gravity, const std::set<std::uint32_t>& objects,
                      const IceMetricsSettings& settings);

}  // namespace rime::clean
