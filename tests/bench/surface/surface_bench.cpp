// rime-surface benchmark: particles per second and peak memory for 50k / 500k / 2M ice particles at
// voxel = spacing / 2, anisotropic ellipsoids (stored D), against OpenVDB's isotropic
// ParticlesToLevelSet + volumeToMesh on the same particles.
//
// Usage: rime-bench-surface [--sizes 50000,500000,2000000] [--runs 3] [--threads N] [--sheet] [--openvdb] [--json FILE]
// --threads caps the worker threads (default: the CPUs the process may use); at --threads 1 "per
// core" is measured directly instead of divided out of a shared machine's parallel run.
// Peak memory is measured in a child process per case (fork), so cases do not inherit each
// other's peaks. The parent never runs TBB, not even to generate particles: a child forked after
// TBB has started its workers gets none and runs every parallel loop on one thread.
#include <openvdb/openvdb.h>
#include <openvdb/tools/ParticlesToLevelSet.h>
#include <openvdb/tools/VolumeToMesh.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <sys/resource.h>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "rime/surface/reconstruct.h"
#include "rime/test/measure.h"
#include "rime/test/run_in_child.h"

using namespace rime;
using Clock = std::chrono::steady_clock;

namespace {

constexpr double kSpacing = 0.02;

// A jittered lattice ball of about n particles (a dense ice body) or a two-layer sheet (a glaze
// coat), with D from the PCA as stored at freezing.
surface::ParticleSet IceShape(std::size_t n, bool sheet) {
  surface::ParticleSet set;
  set.spacing = kSpacing;
  if (sheet) {
    const int side = int(std::sqrt(double(n) / 2));
    std::mt19937 rng(42);
    std::uniform_real_distribution<double> jitter(-0.05, 0.05);
    for (int i = 0; i < side; ++i)
      for (int j = 0; j < side; ++j)
        for (int k = 0; k < 2; ++k) set.positions.push_back(Vec3d(i + jitter(rng), j + jitter(rng), k + jitter(rng)) * kSpacing);
    surface::Settings settings;
    settings.lambda = 0;
    set.stored_anisotropy = surface::Prepare(set, settings, kSpacing / 2).D;
    return set;
  }
  const double radius = std::cbrt(3.0 * double(n) / (4 * M_PI)) * kSpacing;
  const int half = int(std::ceil(radius / kSpacing));
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> jitter(-0.05, 0.05);
  for (int i = -half; i <= half; ++i)
    for (int j = -half; j <= half; ++j)
      for (int k = -half; k <= half; ++k) {
        const Vec3d p = Vec3d(i, j, k) * kSpacing;
        if (Norm(p) <= radius) set.positions.push_back(p + Vec3d(jitter(rng), jitter(rng), jitter(rng)) * kSpacing);
      }
  surface::Settings settings;
  settings.lambda = 0;
  const surface::PreparedParticles prepared = surface::Prepare(set, settings, kSpacing / 2);
  set.stored_anisotropy = prepared.D;
  return set;
}

struct OpenVdbParticles {
  const std::vector<Vec3d>* p;
  double radius;
  using PosType = openvdb::Vec3R;
  std::size_t size() const { return p->size(); }
  void getPos(std::size_t n, openvdb::Vec3R& xyz) const { xyz = openvdb::Vec3R((*p)[n].x, (*p)[n].y, (*p)[n].z); }
  void getPosRad(std::size_t n, openvdb::Vec3R& xyz, openvdb::Real& rad) const {
    getPos(n, xyz);
    rad = radius;
  }
};

// IceShape in a child process, the set sent back through a pipe, so that the parent stays free of
// TBB (see the header).
surface::ParticleSet GenerateIsolated(std::size_t n, bool sheet) {
  const test::ChildResult child = test::RunInChild([&] {
    const surface::ParticleSet set = IceShape(n, sheet);
    std::string bytes;
    bytes.append(reinterpret_cast<const char*>(set.positions.data()), set.size() * sizeof(Vec3d));
    bytes.append(reinterpret_cast<const char*>(set.stored_anisotropy.data()), set.size() * sizeof(std::array<float, 6>));
    return bytes;
  });
  const std::size_t per_particle = sizeof(Vec3d) + sizeof(std::array<float, 6>);
  if (!child.exited_cleanly || child.output.size() % per_particle != 0) throw std::runtime_error("particle generator failed");
  const std::size_t count = child.output.size() / per_particle;
  surface::ParticleSet set;
  set.spacing = kSpacing;
  set.positions.resize(count);
  set.stored_anisotropy.resize(count);
  std::memcpy(set.positions.data(), child.output.data(), count * sizeof(Vec3d));
  std::memcpy(set.stored_anisotropy.data(), child.output.data() + count * sizeof(Vec3d), count * sizeof(std::array<float, 6>));
  return set;
}

struct Measure {
  double seconds = 0, prepare = 0, rasterize = 0, mesh = 0, cpu_seconds = 0;
  std::uint64_t triangles = 0, active_voxels = 0;
  std::uint64_t estimate_bytes = 0;  // surface::EstimateMemoryBytes (what --memory-budget checks)
};

Measure RunRime(const surface::ParticleSet& set) {
  surface::Settings settings;  // spec defaults: ellipsoids, λ = 0.9, voxel = d_p / 2
  const auto t0 = Clock::now();
  const surface::Result r = surface::Reconstruct(set, settings);
  Measure m;
  m.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  m.prepare = r.stats.seconds_prepare;
  m.rasterize = r.stats.seconds_rasterize;
  m.mesh = r.stats.seconds_mesh;
  m.triangles = r.stats.triangles;
  m.active_voxels = r.stats.active_voxels;
  m.estimate_bytes = surface::EstimateMemoryBytes(set, settings);
  return m;
}

Measure RunOpenVdb(const surface::ParticleSet& set) {
  openvdb::initialize();
  const auto t0 = Clock::now();
  const double dx = kSpacing / 2;
  auto grid = openvdb::createLevelSet<openvdb::FloatGrid>(dx, 3.0);
  openvdb::tools::ParticlesToLevelSet<openvdb::FloatGrid> raster(*grid);
  raster.setGrainSize(1);
  OpenVdbParticles particles{&set.positions, kSpacing};  // radius = spacing, as in LIBRARY_NOTES.md
  raster.rasterizeSpheres(particles);
  raster.finalize(true);
  Measure m;
  m.rasterize = std::chrono::duration<double>(Clock::now() - t0).count();
  std::vector<openvdb::Vec3s> points;
  std::vector<openvdb::Vec3I> triangles;
  std::vector<openvdb::Vec4I> quads;
  openvdb::tools::volumeToMesh(*grid, points, triangles, quads, 0.0, 0.0);
  m.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  m.mesh = m.seconds - m.rasterize;
  m.triangles = triangles.size() + 2 * quads.size();
  m.active_voxels = grid->activeVoxelCount();
  return m;
}

// Runs `body` in a child process with at most `threads` workers; returns its measure and peak
// resident memory.
template <class F>
bool Isolated(F body, int threads, Measure& out, std::uint64_t& peak) {
  const test::ChildResult child = test::RunInChild([&] {
    tbb::global_control limit(tbb::global_control::max_allowed_parallelism, std::size_t(threads));
    const double cpu0 = test::ProcessCpuSeconds();
    Measure m = body();
    m.cpu_seconds = test::ProcessCpuSeconds() - cpu0;
    return std::string(reinterpret_cast<const char*>(&m), sizeof m);
  });
  if (!child.exited_cleanly || child.output.size() != sizeof out) return false;
  std::memcpy(&out, child.output.data(), sizeof out);
  peak = std::uint64_t(child.usage.ru_maxrss) * 1024;
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::size_t> sizes{50000, 500000, 2000000};
  int runs = 3;
  bool openvdb_baseline = false;
  std::string json_path = RIME_BENCH_OUTPUT_DIR "/results.json";
  bool sheet = false;
  int threads = tbb::info::default_concurrency();  // the CPUs this process may use (taskset narrows it)
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    if (arg == "--sizes" && a + 1 < argc) {
      sizes.clear();
      std::string list = argv[++a];
      for (std::size_t pos = 0; pos != std::string::npos;) {
        const std::size_t comma = list.find(',', pos);
        sizes.push_back(std::stoull(list.substr(pos, comma == std::string::npos ? comma : comma - pos)));
        pos = comma == std::string::npos ? comma : comma + 1;
      }
    } else if (arg == "--runs" && a + 1 < argc) {
      runs = std::stoi(argv[++a]);
    } else if (arg == "--threads" && a + 1 < argc) {
      threads = std::max(1, std::stoi(argv[++a]));
    } else if (arg == "--sheet") {
      sheet = true;
    } else if (arg == "--openvdb") {
      openvdb_baseline = true;
    } else if (arg == "--json" && a + 1 < argc) {
      json_path = argv[++a];
    } else {
      std::fprintf(stderr, "usage: %s [--sizes N,N,...] [--runs R] [--threads N] [--sheet] [--openvdb] [--json FILE]\n", argv[0]);
      return 2;
    }
  }
  nlohmann::json results = nlohmann::json::array();
  std::printf(
      "threads: %d, voxel = spacing/2, shape: %s, median of %d runs (by wall time); M/cpu-s = particles per CPU-second (user+sys, robust "
      "to a shared machine)\n",
      threads, sheet ? "jittered two-layer ice sheet" : "jittered ice ball", runs);
  // prepare = centre smoothing + D (rime only), field = rasterizing the level set.
  std::printf("%-24s %10s %9s %9s %9s %9s %9s %10s %9s %12s %11s %10s %8s\n", "method", "particles", "wall s", "prepare s", "field s",
              "mesh s", "cpu s", "M part/s", "per core", "M/cpu-s", "triangles", "peak MB", "est. MB");  // MB = 1e6 bytes
  for (std::size_t n : sizes) {
    const surface::ParticleSet set = GenerateIsolated(n, sheet);
#ifdef __GLIBC__
    malloc_trim(0);  // the generator's freed arrays would otherwise count in every child's peak
#endif
    for (int method = 0; method < (openvdb_baseline ? 2 : 1); ++method) {
      std::vector<Measure> measures;
      std::uint64_t peak = 0;
      for (int r = 0; r < runs; ++r) {
        Measure m;
        std::uint64_t p = 0;
        if (!Isolated([&] { return method == 0 ? RunRime(set) : RunOpenVdb(set); }, threads, m, p)) {
          std::fprintf(stderr, "case failed\n");
          return 1;
        }
        measures.push_back(m);
        peak = std::max(peak, p);
      }
      std::sort(measures.begin(), measures.end(), [](const Measure& a, const Measure& b) { return a.seconds < b.seconds; });
      const Measure& m = measures[measures.size() / 2];
      const char* name = method == 0 ? "rime ellipsoids (aniso)" : "openvdb P2LS (iso)";
      double load[1] = {0};
      (void)!getloadavg(load, 1);  // after the runs: the others' share of this machine
      const double rate = double(set.size()) / m.seconds / 1e6;
      const double cpu_rate = double(set.size()) / m.cpu_seconds / 1e6;
      std::printf("%-24s %10zu %9.3f %9.3f %9.3f %9.3f %9.3f %10.3f %9.3f %12.3f %11llu %10.0f %8.0f  load %.1f\n", name, set.size(),
                  m.seconds, m.prepare, m.rasterize, m.mesh, m.cpu_seconds, rate, rate / threads, cpu_rate, (unsigned long long)m.triangles,
                  peak / 1e6, m.estimate_bytes / 1e6, load[0]);
      std::fflush(stdout);
      results.push_back({{"method", name},
                         {"particles", set.size()},
                         {"threads", threads},
                         {"seconds_median", m.seconds},
                         {"seconds_prepare", m.prepare},
                         {"seconds_field", m.rasterize},
                         {"seconds_mesh", m.mesh},
                         {"particles_per_second", rate * 1e6},
                         {"particles_per_second_per_core", rate * 1e6 / threads},
                         {"cpu_seconds", m.cpu_seconds},
                         {"particles_per_cpu_second", cpu_rate * 1e6},
                         {"triangles", m.triangles},
                         {"active_voxels", m.active_voxels},
                         {"peak_memory_bytes", peak},
                         {"estimated_memory_bytes", m.estimate_bytes},
                         {"shape", sheet ? "two-layer sheet" : "ball"},
                         {"load_average_1min", load[0]},
                         {"note", "peak memory includes the generated particle set (~100 bytes/particle)"}});
    }
  }
  const nlohmann::json document = {
      {"benchmark", "surface"}, {"machine", rime::test::MachineDescription()}, {"commit", rime::test::SourceCommit(RIME_SOURCE_DIR)},
      {"threads", threads},     {"shape", sheet ? "sheet" : "ball"},           {"results", results}};
  std::ofstream(json_path) << document.dump(2) << "\n";
  std::printf("wrote %s\n", json_path.c_str());
  return 0;
}
