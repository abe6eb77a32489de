// OpenVDB grids behind rime::surface::Result (private to libs/surface).
#pragma once

#include <openvdb/openvdb.h>

#include "rime/surface/reconstruct.h"

namespace rime::surface {

struct Grids {
  openvdb::FloatGrid::Ptr surface;   // level set, name "surface"
  openvdb::Vec3SGrid::Ptr velocity;  // "vel", may be null
  openvdb::FloatGrid::Ptr density;   // "density" fog, may be null
};

/// An empty level set with the right name, class, transform and background.
openvdb::FloatGrid::Ptr EmptyLevelSet(double voxel_size, double half_band);

/// Triangle mesh of the zero level set, outward counter-clockwise, with area-weighted normals;
/// drops enclosed inward-facing shells unless keep_voids. Returns the number of shells dropped.
/// Meshed in slabs of at most `slab_leaves` leaves (the mesher's scratch: about 6 kB per leaf).
std::uint64_t ExtractMesh(const openvdb::FloatGrid& grid, bool keep_voids, io::TriMesh& mesh, std::size_t slab_leaves = 8192);

void InitializeOpenVdb();

}  // namespace rime::surface
