/// @file particles.h
/// @brief Particle frames in the H5Part layout (ARCHITECTURE.md "File contracts").
///
/// One file per frame with one group `Step#0` holding a float64 attribute `TimeValue` and 1-D
/// datasets (`x y z`, vectors as `name_0 name_1 name_2`, symmetric 3x3 as six components). Root
/// attributes: `format` = "rime.particles", `version`, `kind` ("particles" or "boundary"),
/// `units` = "SI", `particle_radius`, `spacing`, `rest_density`, `time`, `frame`, `scene_hash`, plus
/// free-form numbers and strings. Writes are atomic; reads check format, version and kind.
#pragma once

#include <cstdint>
#include <filesystem>
#include <map>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

#include "rime/core/math.h"

namespace rime::io {

inline constexpr const char* kParticleFormatName = "rime.particles";
inline constexpr int kParticleFormatVersion = 1;

/// Values of the `phase` dataset.
enum class Phase : std::uint8_t { kFluid = 0, kBoundary = 1, kIce = 2 };

using AttributeData = std::variant<std::vector<float>, std::vector<double>, std::vector<std::int32_t>, std::vector<std::uint32_t>,
                                   std::vector<std::int64_t>, std::vector<std::uint8_t>>;

struct ParticleFrame {
  std::string kind = "particles";  // "particles" (simulation frames) or "boundary"
  double time = 0;                 // s
  std::int64_t frame = 0;
  double spacing = 0;          // fluid particle spacing d_p, m
  double particle_radius = 0;  // d_p / 2, m
  double rest_density = 1000;  // kg/m^3
  std::string scene_hash;
  std::map<std::string, double> numbers;            // extra numeric root attributes
  std::map<std::string, std::string> texts;         // extra string root attributes
  std::map<std::string, AttributeData> attributes;  // datasets of Step#0, all of length size()
  std::string source;                               // file it was read from (for error messages); empty when built in memory

  std::size_t size() const;
  bool Has(const std::string& name) const { return attributes.count(name) != 0; }

  template <class T>
  void Set(const std::string& name, std::vector<T> values) {
    attributes[name] = std::move(values);
  }
  /// The dataset `name` with element type T; throws rime::Error naming the file and dataset.
  template <class T>
  const std::vector<T>& Get(const std::string& name) const;

  template <class T>
  void SetVec3(const std::string& base, const std::vector<Vec3<T>>& values);
  template <class T>
  std::vector<Vec3<T>> GetVec3(const std::string& base) const;
  bool HasVec3(const std::string& base) const { return Has(base + "_0") && Has(base + "_1") && Has(base + "_2"); }

  /// Positions use the H5Part names x, y, z.
  template <class T>
  void SetPositions(const std::vector<Vec3<T>>& p);
  template <class T>
  std::vector<Vec3<T>> GetPositions() const;

  /// Checks every dataset has the same length; throws otherwise.
  void Validate() const;
};

struct WriteOptions {
  int compression_level = 1;  // deflate 0..9 (0 = off); shuffle is always on when compressing
};

/// Writes `frame` atomically (temporary file + rename). Throws rime::Error(kIo) naming the file.
void WriteParticleFrame(const std::filesystem::path& path, const ParticleFrame& frame, const WriteOptions& options = {});

/// Reads and checks a frame. `expected_kind` empty accepts any kind.
ParticleFrame ReadParticleFrame(const std::filesystem::path& path, std::string_view expected_kind = {});
/// Reads only the root attributes (no datasets).
ParticleFrame ReadParticleFrameHeader(const std::filesystem::path& path, std::string_view expected_kind = {});

/// Index file whose `Step#k` groups are external links to each frame file's `Step#0`, so that
/// ParaView opens the whole sequence with its times. Paths are stored relative to the index.
struct IndexEntry {
  std::filesystem::path frame_file;
  double time = 0;
};
void WriteSequenceIndex(const std::filesystem::path& index_path, const std::vector<IndexEntry>& entries);

/// "<folder>/<stem>.<frame padded to 4>.<extension>", e.g. particles.0012.h5part.
std::filesystem::path FramePath(const std::filesystem::path& folder, std::string_view stem, std::int64_t frame, std::string_view extension,
                                int padding = 4);

}  // namespace rime::io
