// Benchmark of the default rime-clean chain on noisy balls and tori meshed by surface nets (the
// triangle shapes of marching-cubes output), 100k / 500k / 2M triangles. Prints a table (medians
// of --runs) and writes JSON. Target (issue 8): >= 100k input triangles per second per core.
#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <time.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>

#include "rime/core/atomic_file.h"
#include "rime/exec/device.h"
#include "rime/io/mesh.h"
#include "rime/meshfix/clean.h"
#include "rime/meshfix/procedural.h"

using namespace rime;
namespace fs = std::filesystem;

namespace {
double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : (v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]));
}
/// CPU time of the whole process: on a machine shared with other work, wall time overstates the
/// cost; CPU time divided by threads is the per-core figure.
double ProcessCpuSeconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return double(t.tv_sec) + 1e-9 * double(t.tv_nsec);
}
double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"rime-clean benchmark: default cleanup chain per frame"};
  std::vector<std::size_t> sizes = {100000, 500000, 2000000};
  std::vector<std::string> shapes = {"ball", "torus"};
  int runs = 3, threads = 1;
  std::string json_path = "bench_clean.json", scratch = (fs::temp_directory_path() / "rime_bench_clean").string();
  bool remesh = false, keep = false;
  app.add_option("--sizes", sizes, "Input triangle counts (approximate)");
  app.add_option("--shapes", shapes, "ball and/or torus")->check(CLI::IsMember({"ball", "torus"}));
  app.add_option("--runs", runs, "Runs per case (median reported)")->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "CPU threads (1 = per-core figure)")->check(CLI::PositiveNumber);
  app.add_option("--json", json_path, "JSON output");
  app.add_option("--scratch", scratch, "Folder for the read/write timing files");
  app.add_flag("--keep", keep, "Keep the generated input meshes in --scratch");
  app.add_flag("--remesh", remesh, "Also run one isotropic remeshing pass (not in the default chain)");
  CLI11_PARSE(app, argc, argv);
  exec::SetCpuThreads(threads);
  fs::create_directories(scratch);

  io::CleanupSettings settings;
  settings.remesh = remesh;
  nlohmann::json results = nlohmann::json::array();
  fmt::print("rime-clean default chain, {} thread(s), median of {} run(s){}\n", threads, runs, remesh ? ", with remeshing" : "");
  fmt::print("{:>6} {:>9} {:>9} {:>7} {:>7} {:>8} {:>8} {:>8} {:>12}  per operation (wall s)\n", "shape", "tris in", "tris out",
             "read s", "write s", "clean s", "cpu s", "k tri/s", "k tri/cpu-s");
  for (const std::string& shape : shapes)
    for (std::size_t size : sizes) {
      io::TriMesh mesh = shape == "ball" ? meshfix::procedural::NoisyBall(size, 1) : meshfix::procedural::NoisyTorus(size, 1);
      // A rigid rotation's velocity field, as rime-surface writes for motion blur.
      for (const Vec3f& p : mesh.positions) mesh.velocities.push_back(Vec3f(-p.y, p.x, 0.1f));
      const fs::path file = fs::path(scratch) / fmt::format("{}_{}.ply", shape, size);
      std::vector<double> read_s, write_s, clean_s, cpu_s, read_obj_s, write_obj_s;
      const fs::path obj_file = fs::path(file).replace_extension(".obj");
      std::map<std::string, std::vector<double>> per_op;
      meshfix::CleanReport last;
      for (int r = 0; r < runs; ++r) {
        auto t = std::chrono::steady_clock::now();
        io::WriteMesh(file, mesh);
        write_s.push_back(Seconds(t));
        t = std::chrono::steady_clock::now();
        const io::TriMesh read = io::ReadMesh(file);
        read_s.push_back(Seconds(t));
        t = std::chrono::steady_clock::now();
        io::WriteMesh(obj_file, mesh);
        write_obj_s.push_back(Seconds(t));
        t = std::chrono::steady_clock::now();
        if (io::ReadMesh(obj_file).triangle_count() != mesh.triangle_count()) throw std::runtime_error("OBJ round trip lost faces");
        read_obj_s.push_back(Seconds(t));
        fs::remove(obj_file);
        t = std::chrono::steady_clock::now();
        const double cpu0 = ProcessCpuSeconds();
        meshfix::CleanResult result = meshfix::Clean(read, settings);
        clean_s.push_back(Seconds(t));
        cpu_s.push_back(ProcessCpuSeconds() - cpu0);
        for (const auto& op : result.report.operations) per_op[op.name].push_back(op.seconds);
        last = std::move(result.report);
      }
      if (!keep) fs::remove(file);
      const double clean = Median(clean_s);
      const double rate = double(last.before.faces) / clean;
      const double cpu = Median(cpu_s);
      const double rate_per_core_cpu = double(last.before.faces) / cpu;
      std::string ops;
      nlohmann::json op_json;
      for (const auto& op : last.operations) {
        const double m = Median(per_op[op.name]);
        ops += fmt::format(" {} {:.2f}", op.name, m);
        op_json[op.name] = m;
      }
      fmt::print("{:>6} {:>9} {:>9} {:>7.2f} {:>7.2f} {:>8.2f} {:>8.2f} {:>8.0f} {:>12.0f} {}\n", shape, last.before.faces,
                 last.after.faces, Median(read_s), Median(write_s), clean, cpu, rate / 1e3, rate_per_core_cpu / 1e3, ops);
      fmt::print("{:>6} {}\n", "", meshfix::SummaryLine(last));
      fmt::print("{:>6} OBJ read {:.2f} s, write {:.2f} s; binary PLY read {:.2f} s, write {:.2f} s\n", "", Median(read_obj_s),
                 Median(write_obj_s), Median(read_s), Median(write_s));
      std::fflush(stdout);
      results.push_back({{"shape", shape},
                         {"triangles_in", last.before.faces},
                         {"triangles_out", last.after.faces},
                         {"threads", threads},
                         {"runs", runs},
                         {"read_ply_seconds", Median(read_s)},
                         {"write_ply_seconds", Median(write_s)},
                         {"read_obj_seconds", Median(read_obj_s)},
                         {"write_obj_seconds", Median(write_obj_s)},
                         {"clean_seconds", clean},
                         {"input_triangles_per_second", rate},
                         {"input_triangles_per_second_per_core", rate / threads},
                         {"clean_cpu_seconds", cpu},
                         {"input_triangles_per_cpu_second", rate_per_core_cpu},
                         {"operations_seconds", op_json},
                         {"report", meshfix::ToJson(last)}});
    }
  WriteFileAtomically(json_path, nlohmann::json({{"benchmark", "rime-clean default chain"}, {"threads", threads}, {"remesh", remesh}, {"results", results}}).dump(2) + "\n");
  fmt::print("wrote {}\n", json_path);
  return 0;
}
