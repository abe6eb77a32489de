// Boundary sampling throughput: particles per second for the Stanford bunny scaled to
// 0.5 m and for a 1-million-triangle torus, volumes included. Prints a table and writes JSON.
//
//   rime-bench-boundary [--repeats N] [--threads N] [--json FILE] [--mesh-dir DIR] [--case TEXT]
//
// --case runs only the cases whose name contains TEXT (for profiling one of them).
#include <fmt/format.h>

#include <algorithm>
#include <chrono>
#include <ctime>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "rime/boundary/sampler.h"
#include "rime/boundary/shapes.h"
#include "rime/boundary/volumes.h"
#include "rime/core/log.h"
#include "rime/exec/device.h"
#include "rime/io/mesh_import.h"
#include "rime/test/measure.h"

namespace {

namespace fs = std::filesystem;
using namespace rime;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point a, Clock::time_point b) { return std::chrono::duration<double>(b - a).count(); }

struct Case {
  std::string name;
  std::function<io::TriMesh()> load;  // mesh in place (timed separately)
  double particle_spacing;            // d_p, m; d_b = d_p / 2, h = d_p
};

nlohmann::json RunCase(const Case& c, int repeats) {
  std::vector<double> load, sample, volumes, total, cpu;
  std::size_t triangles = 0, particles = 0;
  for (int r = 0; r < repeats; ++r) {
    const auto t0 = Clock::now();
    const io::TriMesh mesh = c.load();
    const auto t1 = Clock::now();
    const std::clock_t c1 = std::clock();
    boundary::SampleOptions options;
    options.spacing = 0.5 * c.particle_spacing;
    const boundary::SurfaceSamples s = boundary::SampleSurface(mesh, options);
    const auto t2 = Clock::now();
    const std::vector<float> v = boundary::ComputeBoundaryVolumes<float>(exec::Device::Cpu(), s.positions, float(c.particle_spacing));
    const auto t3 = Clock::now();
    cpu.push_back(double(std::clock() - c1) / CLOCKS_PER_SEC);
    if (v.size() != s.size()) std::abort();
    load.push_back(Seconds(t0, t1));
    sample.push_back(Seconds(t1, t2));
    volumes.push_back(Seconds(t2, t3));
    total.push_back(Seconds(t1, t3));
    triangles = mesh.triangle_count();
    particles = s.size();
  }
  const double rate = double(particles) / test::Median(total);
  const double cpu_rate = double(particles) / test::Median(cpu);
  fmt::print("| {:<28} | {:>9} | {:>9} | {:>8.3f} | {:>8.3f} | {:>8.3f} | {:>8.3f} | {:>9.2f} | {:>10.2f} |\n", c.name, triangles,
             particles, test::Median(load), test::Median(sample), test::Median(volumes), test::Median(total), rate / 1e6, cpu_rate / 1e6);
  return {{"case", c.name},
          {"triangles", triangles},
          {"particles", particles},
          {"particle_spacing", c.particle_spacing},
          {"boundary_spacing", 0.5 * c.particle_spacing},
          {"load_seconds_median", test::Median(load)},
          {"sample_seconds_median", test::Median(sample)},
          {"volume_seconds_median", test::Median(volumes)},
          {"sample_and_volume_seconds_median", test::Median(total)},
          {"particles_per_second", rate},
          {"cpu_seconds_median", test::Median(cpu)},
          {"particles_per_cpu_second", cpu_rate},
          {"particles_per_second_with_load", double(particles) / (test::Median(total) + test::Median(load))},
          {"repeats", repeats}};
}

}  // namespace

int main(int argc, char** argv) {
  int repeats = 5, threads = 0;
  std::string json_path = RIME_BENCH_OUTPUT_DIR "/results.json", only;
  fs::path mesh_dir = fs::path(RIME_SHARED_DIR) / "meshes";
  for (int i = 1; i + 1 < argc; i += 2) {
    if (!std::strcmp(argv[i], "--repeats")) repeats = std::max(1, std::atoi(argv[i + 1]));
    else if (!std::strcmp(argv[i], "--threads")) threads = std::atoi(argv[i + 1]);
    else if (!std::strcmp(argv[i], "--json")) json_path = argv[i + 1];
    else if (!std::strcmp(argv[i], "--mesh-dir")) mesh_dir = argv[i + 1];
    else if (!std::strcmp(argv[i], "--case")) only = argv[i + 1];
  }
  if (threads > 0) exec::SetCpuThreads(threads);
  if (std::getenv("RIME_BENCH_VERBOSE")) log::SetLevel(log::Level::kDebug);

  std::vector<Case> cases;
  const fs::path bunny = mesh_dir / "stanford-bunny.obj";
  if (fs::exists(bunny)) {
    cases.push_back({"bunny 0.5 m, d_p 5 mm",
                     [bunny] {
                       io::TriMesh m = io::ImportMesh(bunny);
                       io::Transform t;  // the bunny is about 0.16 m and y-up: scale its largest extent to 0.5 m
                       t.up_axis = rime::io::UpAxis::kY;
                       t.scale = Vec3d::Splat(0.5 / 0.155);
                       boundary::ApplyTransform(m, t);
                       return m;
                     },
                     0.005});
  } else {
    fmt::print("bunny skipped: {} not found\n", bunny.string());
  }
  // Torus with R = 0.5 m, r = 0.15 m tessellated to about 1 million triangles (edges ~2.4 mm).
  cases.push_back({"torus 1M triangles, d_p 5 mm", [] { return boundary::MakeTorus(0.5, 0.15, 0.00243); }, 0.005});
  cases.push_back({"torus 1M triangles, d_p 2 cm", [] { return boundary::MakeTorus(0.5, 0.15, 0.00243); }, 0.02});
  cases.push_back({"box 4x3x1.5 m tank, d_p 1 cm", [] { return boundary::MakeBox(Vec3d(4, 3, 1.5), true, 0.005); }, 0.01});

  const double load_start = test::LoadAverage();
  fmt::print("rime-boundary sampling + Akinci volumes, CPU, {} threads, median of {} runs (h = d_p, d_b = d_p/2), load average {:.2f}\n",
             exec::CpuThreads(), repeats, load_start);
  fmt::print("| {:<28} | {:>9} | {:>9} | {:>8} | {:>8} | {:>8} | {:>8} | {:>9} | {:>10} |\n", "case", "triangles", "particles", "load s",
             "sample s", "volume s", "total s", "M part/s", "M/CPU-s");
  fmt::print("|{:-<30}|{:->11}|{:->11}|{:->10}|{:->10}|{:->10}|{:->10}|{:->11}|{:->12}|\n", "", "", "", "", "", "", "", "", "");
  nlohmann::json results = nlohmann::json::array();
  for (const Case& c : cases)
    if (c.name.find(only) != std::string::npos) results.push_back(RunCase(c, repeats));
  fmt::print(
      "(load = mesh file import or procedural tessellation, not included in M part/s; M/CPU-s = particles per\n"
      " second of process CPU time over all threads, which stays meaningful on a machine shared with other work)\n");
  const double load_end = test::LoadAverage();
  fmt::print("load average at the end: {:.2f}\n", load_end);
  std::ofstream(json_path) << nlohmann::json{{"benchmark", "boundary"},
                                             {"machine", test::MachineDescription()},
                                             {"commit", test::SourceCommit(RIME_SOURCE_DIR)},
                                             {"threads", exec::CpuThreads()},
                                             {"repeats", repeats},
                                             {"load_average_start", load_start},
                                             {"load_average_end", load_end},
                                             {"results", results}}
                                  .dump(2)
                           << "\n";
  fmt::print("wrote {}\n", json_path);
  return 0;
}
