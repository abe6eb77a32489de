#include "memory_estimate.h"

namespace rime {

double EstimateSimulationBytes(const SimulationCounts& c) {
  const double t = c.scalar_bytes;
  // Water: 36 scalars of state and scratch (positions, velocities, IISPH terms, colour, normals),
  // ids, reorder slots and grid cells; freezing adds the anisotropy and phase-change scratch.
  const double fluid = 36 * t + 48 + (c.freezing ? 12 * t + 24 : 0);
  // Neighbour lists: an index, a kernel value and a gradient per pair, plus the CPU search's staged
  // copy of each index (each grid keeps its pool between steps).
  const double pairs = (40 + 20) * (4 + 4 * t + 4);
  // Boundary: positions, velocities, rest-frame positions, volumes, ids; freezing adds film,
  // growth direction, ice anisotropy and energies.
  const double boundary = 11 * t + 29 + (c.freezing ? 16 * t + 24 : 0);
  // Freezing keeps a film-Laplacian row per wetted boundary particle: ~60 boundary neighbours (the
  // boundary is sampled at half spacing), an index and two position terms each. Relisting holds old
  // and new rows at once and arrays grow by half, so up to 4x that; any boundary may get wet.
  const double film_rows = c.freezing ? 4 * 60 * (4 + 2 * t) : 0;
  // The snapshot handed to the writer thread, and HDF5's chunk buffers for it.
  const double snapshot = 2 * (16 * t + 16);
  // Taken after the check whatever the size: the solver's and HDF5's code pages and the writer
  // thread (6 MiB measured on a scene of 9.4 k water and 67 k boundary particles).
  const double after_check = 10.0 * 1048576;
  return c.fluid * (fluid + pairs + snapshot) + c.boundary * (boundary + film_rows + (c.freezing ? snapshot : 0)) + after_check;
}

}  // namespace rime
