// Small scenes for the solver tests: an open box of single-layer boundary particles (spacing
// d_b = 0.5 d_p, spec §3) and a water column on a lattice 1.1 d_p from the walls.
#pragma once

#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "rime/io/particles.h"
#include "rime/io/scene.h"
#include "rime/exec/device.h"
#include "rime/sph/simulation.h"

namespace rime::sph::test {

/// Open-top box [0,w]x[0,d]x[0,height] sampled on its floor and four walls.
inline io::ParticleFrame BoxBoundary(double dp, double w, double d, double height, double ratio = 0.5) {
  const double db = ratio * dp;
  std::vector<Vec3d> p;
  // Walls exactly at 0 and w (d): the spacing is adjusted to divide the extent.
  const int nx = int(std::ceil(w / db - 1e-9)), ny = int(std::ceil(d / db - 1e-9)), nz = int(std::ceil(height / db - 1e-9));
  const double sx = w / nx, sy = d / ny, sz = height / nz;
  for (int i = 0; i <= nx; ++i)
    for (int j = 0; j <= ny; ++j) p.push_back({i * sx, j * sy, 0});  // floor
  for (int k = 1; k <= nz; ++k) {
    for (int i = 0; i <= nx; ++i) {
      p.push_back({i * sx, 0, k * sz});
      p.push_back({i * sx, d, k * sz});
    }
    for (int j = 1; j < ny; ++j) {
      p.push_back({0, j * sy, k * sz});
      p.push_back({w, j * sy, k * sz});
    }
  }
  io::ParticleFrame f;
  f.kind = "boundary";
  f.spacing = dp;
  f.SetPositions(p);
  return f;
}

/// Sealed tank [0,w]x[0,d]x[0,height]: the open box plus a lid, every particle carrying its
/// inward normal (how a closed container is told from a solid when the water is placed).
inline io::ParticleFrame SealedBoxBoundary(double dp, double w, double d, double height, double ratio = 0.5) {
  io::ParticleFrame box = BoxBoundary(dp, w, d, height, ratio);
  std::vector<Vec3d> p = box.GetPositions<double>();
  const double db = ratio * dp;
  const int nx = int(std::ceil(w / db - 1e-9)), ny = int(std::ceil(d / db - 1e-9));
  for (int i = 1; i < nx; ++i)
    for (int j = 1; j < ny; ++j) p.push_back({i * w / nx, j * d / ny, height});
  const double eps = 1e-9;
  std::vector<Vec3d> normals;
  for (const Vec3d& q : p) {
    const bool inner_xy = q.x > eps && q.x < w - eps && q.y > eps && q.y < d - eps;
    if (q.z < eps) normals.push_back({0, 0, 1});
    else if (q.z > height - eps && inner_xy) normals.push_back({0, 0, -1});
    else if (q.x < eps) normals.push_back({1, 0, 0});
    else if (q.x > w - eps) normals.push_back({-1, 0, 0});
    else if (q.y < eps) normals.push_back({0, 1, 0});
    else normals.push_back({0, -1, 0});
  }
  box.SetPositions(p);
  box.SetVec3("normal", normals);
  return box;
}

/// A scene with a water block of nx*ny*nz particles standing 1.1 d_p from the walls of a box
/// just large enough to hold it, walls `wall_height` high.
inline io::Scene ColumnScene(double dp, int nx, int ny, int nz, double wall_height) {
  io::Scene scene;
  scene.fluid.spacing = dp;
  scene.modules = {"gravity"};
  scene.solver.time_step = rime::io::TimeStep::kFixed;
  scene.solver.dt = 0.002;
  io::FluidBlock block;
  block.min = {1.1 * dp, 1.1 * dp, 1.1 * dp};
  block.max = {block.min.x + (nx - 1) * dp, block.min.y + (ny - 1) * dp, block.min.z + (nz - 1) * dp};
  scene.fluid_blocks.push_back(block);
  io::SolidObject box;
  box.name = "box";
  scene.solids.push_back(box);
  (void)wall_height;
  return scene;
}

inline double BoxWidth(double dp, int n) { return (n - 1) * dp + 2.2 * dp; }

inline constexpr double kDropSpacing = 0.02;

/// A block of water thrown onto the floor of a shallow box (MakeDrop), freezing on.
inline io::Scene DropScene(double glaze, double icicle, Vec3d velocity = {0, 0, -1}) {
  io::Scene scene;
  scene.fluid.spacing = kDropSpacing;
  scene.modules = {"gravity", "viscosity", "freezing"};
  io::FluidBlock b;
  b.min = {0.3, 0.3, 0.1};
  b.max = {0.42, 0.42, 0.2};
  b.velocity = velocity;
  scene.fluid_blocks.push_back(b);
  io::SolidObject box;
  box.name = "box";
  scene.solids.push_back(box);
  scene.freezing.glaze_threshold = glaze;
  scene.freezing.icicle_threshold = icicle;
  return scene;
}

/// The solver for a DropScene in its box, initialised.
inline std::unique_ptr<Simulation<float>> MakeDrop(const io::Scene& scene) {
  auto sim = std::make_unique<Simulation<float>>(scene, exec::Device::Cpu());
  sim->AddBoundaryObject(BoxBoundary(kDropSpacing, 0.72, 0.72, 0.2), "box");
  sim->Initialize();
  return sim;
}

}  // namespace rime::sph::test
