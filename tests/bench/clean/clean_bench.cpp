// Benchmark of the default rime-clean chain on noisy balls and tori meshed by surface nets (the
// triangle shapes of marching-cubes output), 100k / 500k / 2M triangles. Prints a table (medians
// of --runs) and writes JSON. Target: >= 100k input triangles per second per core.
#include <CLI/CLI.hpp>
#include <fmt/format.h>

#include <stdlib.h>
#include <time.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>

#include "rime/core/atomic_file.h"
#include "rime/exec/device.h"
#include "rime/io/mesh.h"
#include "rime/clean/clean.h"
#include "rime/clean/procedural.h"
#include "rime/test/measure.h"

using namespace rime;
namespace fs = std::filesystem;

namespace {
/// Largest and mean distance from the vertices and face centroids of `from` to the surface of
/// `to` (TransferVelocities with velocity = position returns the nearest surface point).
std::pair<double, double> DistanceTo(const io::TriMesh& from, const io::TriMesh& to) {
  std::vector<Vec3f> samples = from.positions;
  for (const auto& t : from.triangles) samples.push_back((from.positions[t[0]] + from.positions[t[1]] + from.positions[t[2]]) / 3.0f);
  io::TriMesh surface = to;
  surface.velocities = to.positions;
  const std::vector<Vec3f> nearest = clean::TransferVelocities(surface, samples);
  double largest = 0, sum = 0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const double d = Norm(Vec3d(samples[i]) - Vec3d(nearest[i]));
    largest = std::max(largest, d), sum += d;
  }
  return {largest, samples.empty() ? 0 : sum / double(samples.size())};
}
}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"rime-clean benchmark: default cleanup chain per frame"};
  std::vector<std::size_t> sizes = {100000, 500000, 2000000};
  std::vector<std::string> shapes = {"ball", "torus"};
  int runs = 3, threads = 1;
  std::string json_path = RIME_BENCH_OUTPUT_DIR "/results.json", scratch = RIME_BENCH_OUTPUT_DIR "/scratch";
  bool remesh = false, keep = false, hausdorff = false;
  std::string decimate_method(io::EnumName(io::CleanupSettings{}.decimate_method));
  app.add_option("--sizes", sizes, "Input triangle counts (approximate)");
  app.add_option("--shapes", shapes, "ball and/or torus")->check(CLI::IsMember({"ball", "torus"}));
  app.add_option("--runs", runs, "Runs per case (median reported)")->check(CLI::PositiveNumber);
  app.add_option("--threads", threads, "CPU threads (1 = per-core figure)")->check(CLI::PositiveNumber);
  app.add_option("--json", json_path, "JSON output");
  app.add_option("--scratch", scratch, "Folder for the read/write timing files")->capture_default_str();
  app.add_flag("--keep", keep, "Keep the generated input meshes in --scratch");
  app.add_flag("--remesh", remesh, "Also run one isotropic remeshing pass (not in the default chain)");
  app.add_option("--decimate-method", decimate_method, "batch (default) or cgal")->check(CLI::IsMember({"batch", "cgal"}));
  app.add_flag("--hausdorff", hausdorff, "Also measure the distance between input and output (untimed; slow)");
  CLI11_PARSE(app, argc, argv);
  exec::SetCpuThreads(threads);
  const bool created_scratch = fs::create_directories(scratch);

  io::CleanupSettings settings;
  settings.remesh = remesh;
  io::ParseEnum(decimate_method, settings.decimate_method);
  nlohmann::json results = nlohmann::json::array();
  fmt::print("rime-clean default chain, {} thread(s), median of {} run(s), decimation {}{}\n", threads, runs, decimate_method,
             remesh ? ", with remeshing" : "");
  fmt::print("{:>6} {:>9} {:>9} {:>7} {:>7} {:>8} {:>8} {:>8} {:>12}  per operation (CPU s)\n", "shape", "tris in", "tris out", "read s",
             "write s", "clean s", "cpu s", "k tri/s", "k tri/cpu-s");
  for (const std::string& shape : shapes)
    for (std::size_t size : sizes) {
      io::TriMesh mesh = shape == "ball" ? clean::procedural::NoisyBall(size, 1) : clean::procedural::NoisyTorus(size, 1);
      // A rigid rotation's velocity field, as rime-surface writes for motion blur.
      for (const Vec3f& p : mesh.positions) mesh.velocities.push_back(Vec3f(-p.y, p.x, 0.1f));
      const fs::path file = fs::path(scratch) / fmt::format("{}_{}.ply", shape, size);
      std::vector<double> read_s, write_s, clean_s, cpu_s, read_obj_s, write_obj_s;
      const fs::path obj_file = fs::path(file).replace_extension(".obj");
      std::map<std::string, std::vector<double>> per_op, per_op_cpu;
      clean::CleanReport last;
      io::TriMesh last_mesh;
      std::vector<double> load;
      for (int r = 0; r < runs; ++r) {
        test::Stopwatch watch;
        io::WriteMesh(file, mesh);
        write_s.push_back(watch.seconds());
        watch.Restart();
        const io::TriMesh read = io::ReadMesh(file);
        read_s.push_back(watch.seconds());
        watch.Restart();
        io::WriteMesh(obj_file, mesh);
        write_obj_s.push_back(watch.seconds());
        watch.Restart();
        if (io::ReadMesh(obj_file).triangle_count() != mesh.triangle_count()) throw std::runtime_error("OBJ round trip lost faces");
        read_obj_s.push_back(watch.seconds());
        fs::remove(obj_file);
        watch.Restart();
        const double cpu0 = test::ProcessCpuSeconds();
        clean::CleanResult result = clean::Clean(read, settings);
        clean_s.push_back(watch.seconds());
        cpu_s.push_back(test::ProcessCpuSeconds() - cpu0);
        for (const auto& op : result.report.operations) {
          per_op[op.name].push_back(op.seconds);
          per_op_cpu[op.name].push_back(op.cpu_seconds);
        }
        load.push_back(test::LoadAverage());
        last = std::move(result.report);
        last_mesh = std::move(result.mesh);
      }
      if (!keep) fs::remove(file);
      const double clean = test::Median(clean_s);
      const double rate = double(last.before.faces) / clean;
      const double cpu = test::Median(cpu_s);
      const double rate_per_core_cpu = double(last.before.faces) / cpu;
      std::string ops;
      nlohmann::json op_json, op_cpu_json;
      for (const auto& op : last.operations) {
        const double m = test::Median(per_op_cpu[op.name]);
        ops += fmt::format(" {} {:.2f}", op.name, m);
        op_json[op.name] = test::Median(per_op[op.name]);
        op_cpu_json[op.name] = m;
      }
      fmt::print("{:>6} {:>9} {:>9} {:>7.2f} {:>7.2f} {:>8.2f} {:>8.2f} {:>8.0f} {:>12.0f} {}\n", shape, last.before.faces,
                 last.after.faces, test::Median(read_s), test::Median(write_s), clean, cpu, rate / 1e3, rate_per_core_cpu / 1e3, ops);
      fmt::print("{:>6} {}\n", "", clean::SummaryLine(last));
      nlohmann::json distance;
      if (hausdorff) {
        const auto [in_out, in_out_mean] = DistanceTo(mesh, last_mesh);
        const auto [out_in, out_in_mean] = DistanceTo(last_mesh, mesh);
        const double h = std::max(in_out, out_in);
        distance = {{"hausdorff_m", h},
                    {"hausdorff_mean_edges", h / last.before.mean_edge_length},
                    {"mean_distance_m", 0.5 * (in_out_mean + out_in_mean)},
                    {"mean_input_edge_m", last.before.mean_edge_length}};
        fmt::print("{:>6} Hausdorff {:.3g} m = {:.4f} mean input edges, mean distance {:.3g} m\n", "", h, h / last.before.mean_edge_length,
                   0.5 * (in_out_mean + out_in_mean));
      }
      fmt::print("{:>6} OBJ read {:.2f} s, write {:.2f} s; binary PLY read {:.2f} s, write {:.2f} s\n", "", test::Median(read_obj_s),
                 test::Median(write_obj_s), test::Median(read_s), test::Median(write_s));
      std::fflush(stdout);
      results.push_back({{"shape", shape},
                         {"triangles_in", last.before.faces},
                         {"triangles_out", last.after.faces},
                         {"threads", threads},
                         {"runs", runs},
                         {"read_ply_seconds", test::Median(read_s)},
                         {"write_ply_seconds", test::Median(write_s)},
                         {"read_obj_seconds", test::Median(read_obj_s)},
                         {"write_obj_seconds", test::Median(write_obj_s)},
                         {"clean_seconds", clean},
                         {"input_triangles_per_second", rate},
                         {"input_triangles_per_second_per_core", rate / threads},
                         {"clean_cpu_seconds", cpu},
                         {"input_triangles_per_cpu_second", rate_per_core_cpu},
                         {"operations_seconds", op_json},
                         {"operations_cpu_seconds", op_cpu_json},
                         {"load_average_1min", test::Median(load)},
                         {"distance", distance},
                         {"report", clean::ToJson(last)}});
    }
  WriteFileAtomically(json_path, nlohmann::json({{"benchmark", "rime-clean default chain"},
                                                 {"machine", test::MachineDescription()},
                                                 {"commit", test::SourceCommit(RIME_SOURCE_DIR)},
                                                 {"threads", threads},
                                                 {"remesh", remesh},
                                                 {"decimate_method", decimate_method},
                                                 {"results", results}})
                                         .dump(2) +
                                     "\n");
  fmt::print("wrote {}\n", json_path);
  std::error_code not_empty;
  if (created_scratch) fs::remove(scratch, not_empty);  // only when empty: --keep's meshes stay
  return 0;
}
