/// @file shapes.h
/// @brief Procedural solids as triangle meshes, and the object transform of the scene file.
///
/// Every shape is built around the origin in Rime's z-up frame, tessellated finely enough that no
/// edge is longer than `max_edge` (pass the boundary spacing d_b), so that sampling them puts
/// particles on a near-regular lattice:
///   box       centered, extents `size`; `container`: the +z face is left out and every face turns
///             inward (an open-top tank whose walls face the fluid inside)
///   plane     z = 0, centered, extents size.x by size.y, normal +z
///   sphere    centered, `radius`
///   cylinder  axis z, centered, `radius`, `height`, closed with flat caps
///   torus     in the xy plane, centered, major `radius`, tube `minor_radius`
#pragma once

#include <string>

#include "rime/core/math.h"
#include "rime/io/mesh.h"
#include "rime/io/scene.h"

namespace rime::boundary {

/// Triangle mesh of a procedural solid (`object.shape` other than "mesh"), before its transform.
/// Throws rime::Error(kBadInput) for non-positive dimensions.
io::TriMesh MakeProceduralMesh(const io::SolidObject& object, double max_edge);

io::TriMesh MakeBox(const Vec3d& size, bool container, double max_edge);
io::TriMesh MakePlane(double size_x, double size_y, double max_edge);
io::TriMesh MakeSphere(double radius, double max_edge);
io::TriMesh MakeCylinder(double radius, double height, double max_edge);
io::TriMesh MakeTorus(double major_radius, double minor_radius, double max_edge);

/// Surface area of a procedural solid after its transform's scale (an upper bound for non-uniform
/// scales); used to refuse a spacing that would make too many particles before building anything.
double ProceduralSurfaceArea(const io::SolidObject& object);

/// x -> translate + Rz Ry Rx (scale * (U x)), where U turns a y-up source to z-up (+90° about x).
struct AffineTransform {
  Mat3<double> linear = Mat3<double>::Identity();
  Vec3d offset{0, 0, 0};
  Vec3d Apply(const Vec3d& x) const;
  double Determinant() const;
  double MaxStretch() const;  // largest factor any length is multiplied by (bound)
};
AffineTransform MakeTransform(const io::Transform& transform);

/// Moves the mesh in place; flips the winding when the transform mirrors (negative determinant).
/// Per-vertex normals are dropped (the sampler recomputes them from the triangles).
void ApplyTransform(io::TriMesh& mesh, const io::Transform& transform);

/// "scale (1, 1, 1), rotate (0, 0, 90) deg X-Y-Z, translate (0, 0, 0.5) m, up z": for metadata.
std::string DescribeTransform(const io::Transform& transform);

}  // namespace rime::boundary
