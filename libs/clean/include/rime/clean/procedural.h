/// @file procedural.h
/// @brief Procedural test meshes: icospheres, noisy implicit surfaces meshed like marching-cubes
/// output (surface nets on a grid: quads split in two, uneven triangles), specks and holes.
/// Used by the tests and the benchmark, so both clean the same kind of mesh.
#pragma once

#include <cstdint>
#include <functional>

#include "rime/io/mesh.h"

namespace rime::clean::procedural {

/// Unit-subdivided icosahedron projected on a sphere: 20 * 4^subdivisions triangles, outward.
io::TriMesh Icosphere(double radius, int subdivisions, Vec3d center = {0, 0, 0});

/// Moves every vertex along its direction from `center` by a random amount in [-amplitude, amplitude].
void AddRadialNoise(io::TriMesh& mesh, double amplitude, std::uint64_t seed, Vec3d center = {0, 0, 0});

/// Surface nets of the zero set of `sdf` (negative inside) on a grid of `cell` spacing over
/// [min, max]: one vertex per cell that the surface crosses, one quad (two triangles) per crossed
/// grid edge, outward. Closed when the surface stays inside the box.
io::TriMesh SurfaceNets(const std::function<double(const Vec3d&)>& sdf, Vec3d min, Vec3d max, double cell);

/// Noisy sphere ("ice ball") or torus meshed by SurfaceNets with about `target_triangles` triangles.
io::TriMesh NoisyBall(std::size_t target_triangles, std::uint64_t seed);
io::TriMesh NoisyTorus(std::size_t target_triangles, std::uint64_t seed);

/// Appends `other` (its vertex indices shifted); velocities and normals are kept only when both have them.
void Append(io::TriMesh& mesh, const io::TriMesh& other);

/// Removes the triangles whose centroid lies within `radius` of `center` (makes a hole).
void PunchHole(io::TriMesh& mesh, Vec3d center, double radius);

}  // namespace rime::clean::procedural
