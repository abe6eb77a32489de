// OBJ / PLY reading and writing (see rime/io/mesh.h).
//
// Meshes of a few million triangles are read and written per frame, so both formats are parsed by
// hand over one read buffer (std::from_chars / std::to_chars) instead of iostreams token by token.
#include "rime/io/mesh.h"

#include <fmt/format.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <memory>
#include <string>
#include <string_view>

#include "rime/core/atomic_file.h"
#include "rime/core/error.h"

namespace rime::io {
namespace fs = std::filesystem;

namespace {

// ---------------------------------------------------------------------------------------------
// Reading helpers

std::string ReadWholeFile(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError("mesh file not found", path.string());
  if (fs::is_directory(path, ec)) throw InputError("expected a mesh file, found a folder", path.string());
  std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!file) throw InputError(fmt::format("cannot open mesh file: {}", std::strerror(errno)), path.string());
  std::string data;
  const auto size = fs::file_size(path, ec);
  if (ec) throw InputError("cannot read mesh file size", path.string());
  data.resize(size);
  if (size > 0 && std::fread(data.data(), 1, size, file.get()) != size)
    throw InputError("cannot read mesh file (read fewer bytes than its size)", path.string());
  return data;
}

std::string LowerExtension(const fs::path& path) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return ext;
}

bool IsBlank(char c) { return c == ' ' || c == '\t' || c == '\r'; }
bool IsSpace(char c) { return IsBlank(c) || c == '\n'; }

/// Cursor over text; every parse stays within one line unless told otherwise.
struct TextCursor {
  const char* p;
  const char* end;

  void SkipBlanks() {
    while (p < end && IsBlank(*p)) ++p;
  }
  void SkipSpaces() {
    while (p < end && IsSpace(*p)) ++p;
  }
  void SkipLine() {
    const void* nl = std::memchr(p, '\n', std::size_t(end - p));
    p = nl ? static_cast<const char*>(nl) + 1 : end;
  }
  bool AtLineEnd() const { return p >= end || *p == '\n' || *p == '#'; }
  std::string_view Word() {
    SkipBlanks();
    const char* start = p;
    while (p < end && !IsSpace(*p)) ++p;
    return {start, std::size_t(p - start)};
  }
  // from_chars rejects a leading '+', which some writers emit.
  bool Float(double& value) {
    if (p < end && *p == '+') ++p;
    const auto r = std::from_chars(p, end, value);
    if (r.ec != std::errc()) return false;
    p = r.ptr;
    return true;
  }
  bool Integer(long long& value) {
    if (p < end && *p == '+') ++p;
    const auto r = std::from_chars(p, end, value);
    if (r.ec != std::errc()) return false;
    p = r.ptr;
    return true;
  }
};

// ---------------------------------------------------------------------------------------------
// OBJ

TriMesh ReadObj(const fs::path& path, const std::string& text) {
  TriMesh mesh;
  std::vector<Vec3f> obj_normals;
  std::vector<std::int64_t> vertex_normal;  // index into obj_normals per vertex, -1 = none
  std::vector<std::uint32_t> polygon;
  TextCursor c{text.data(), text.data() + text.size()};
  std::size_t line = 0;
  auto where = [&] { return fmt::format("{}:{}", path.string(), line); };

  auto read_vec3 = [&](const char* what) {
    double v[3];
    for (double& x : v) {
      c.SkipBlanks();
      if (!c.Float(x)) throw InputError(fmt::format("expected three numbers after '{}'", what), where());
      if (!std::isfinite(x)) throw InputError(fmt::format("NaN or infinite coordinate in '{}'", what), where());
    }
    return Vec3f(float(v[0]), float(v[1]), float(v[2]));
  };
  // OBJ indices are 1-based; negative ones count back from the last element read so far.
  auto resolve = [&](long long index, std::size_t count, const char* what) -> std::size_t {
    const long long resolved = index > 0 ? index - 1 : (index < 0 ? (long long)count + index : -1);
    if (resolved < 0 || resolved >= (long long)count)
      throw InputError(fmt::format("{} index {} out of range (1..{})", what, index, count), where());
    return std::size_t(resolved);
  };

  while (c.p < c.end) {
    ++line;
    c.SkipBlanks();
    if (c.AtLineEnd()) {
      c.SkipLine();
      continue;
    }
    const std::string_view keyword = c.Word();
    if (keyword == "v") {
      mesh.positions.push_back(read_vec3("v"));
    } else if (keyword == "vn") {
      obj_normals.push_back(read_vec3("vn"));
    } else if (keyword == "f") {
      polygon.clear();
      for (;;) {
        c.SkipBlanks();
        if (c.AtLineEnd()) break;
        long long vi = 0;
        if (!c.Integer(vi)) throw InputError("expected a vertex index in 'f'", where());
        const std::size_t v = resolve(vi, mesh.positions.size(), "vertex");
        if (c.p < c.end && *c.p == '/') {  // v/vt, v/vt/vn or v//vn
          ++c.p;
          long long ignored_texture = 0;
          if (c.p < c.end && *c.p != '/') c.Integer(ignored_texture);
          if (c.p < c.end && *c.p == '/') {
            ++c.p;
            long long ni = 0;
            if (!c.Integer(ni)) throw InputError("expected a normal index after '//' in 'f'", where());
            if (vertex_normal.size() < mesh.positions.size()) vertex_normal.resize(mesh.positions.size(), -1);
            vertex_normal[v] = std::int64_t(resolve(ni, obj_normals.size(), "normal"));
          }
        }
        if (c.p < c.end && !IsSpace(*c.p) && *c.p != '#') throw InputError("malformed face corner in 'f'", where());
        polygon.push_back(std::uint32_t(v));
      }
      if (polygon.size() < 3) throw InputError("face with fewer than three vertices", where());
      for (std::size_t k = 1; k + 1 < polygon.size(); ++k)  // fan triangulation
        mesh.triangles.push_back({polygon[0], polygon[k], polygon[k + 1]});
    }
    // vt, o, g, s, usemtl, mtllib, l, ... carry nothing a stage needs.
    c.SkipLine();
  }

  if (!obj_normals.empty() && !vertex_normal.empty()) {
    vertex_normal.resize(mesh.positions.size(), -1);
    mesh.normals.assign(mesh.positions.size(), Vec3f(0, 0, 0));
    for (std::size_t v = 0; v < mesh.positions.size(); ++v)
      if (vertex_normal[v] >= 0) mesh.normals[v] = obj_normals[std::size_t(vertex_normal[v])];
  } else if (!obj_normals.empty() && obj_normals.size() == mesh.positions.size()) {
    mesh.normals = std::move(obj_normals);  // faces without //n but one normal per vertex
  }
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// PLY

enum class PlyType { kInt8, kUint8, kInt16, kUint16, kInt32, kUint32, kFloat32, kFloat64 };

bool ParsePlyType(std::string_view name, PlyType& type) {
  static const std::pair<std::string_view, PlyType> kNames[] = {
      {"char", PlyType::kInt8},     {"int8", PlyType::kInt8},       {"uchar", PlyType::kUint8},    {"uint8", PlyType::kUint8},
      {"short", PlyType::kInt16},   {"int16", PlyType::kInt16},     {"ushort", PlyType::kUint16},  {"uint16", PlyType::kUint16},
      {"int", PlyType::kInt32},     {"int32", PlyType::kInt32},     {"uint", PlyType::kUint32},    {"uint32", PlyType::kUint32},
      {"float", PlyType::kFloat32}, {"float32", PlyType::kFloat32}, {"double", PlyType::kFloat64}, {"float64", PlyType::kFloat64}};
  for (const auto& [n, t] : kNames)
    if (n == name) {
      type = t;
      return true;
    }
  return false;
}

std::size_t PlyTypeSize(PlyType t) {
  switch (t) {
    case PlyType::kInt8:
    case PlyType::kUint8:
      return 1;
    case PlyType::kInt16:
    case PlyType::kUint16:
      return 2;
    case PlyType::kInt32:
    case PlyType::kUint32:
    case PlyType::kFloat32:
      return 4;
    case PlyType::kFloat64:
      return 8;
  }
  return 0;
}

// memcpy: PLY values are packed, so a pointer cast would read misaligned.
template <class T>
double Load(const char* p) {
  T v;
  std::memcpy(&v, p, sizeof v);
  return double(v);
}

double ReadBinary(const char* p, PlyType t) {
  switch (t) {
    case PlyType::kInt8:
      return Load<std::int8_t>(p);
    case PlyType::kUint8:
      return Load<std::uint8_t>(p);
    case PlyType::kInt16:
      return Load<std::int16_t>(p);
    case PlyType::kUint16:
      return Load<std::uint16_t>(p);
    case PlyType::kInt32:
      return Load<std::int32_t>(p);
    case PlyType::kUint32:
      return Load<std::uint32_t>(p);
    case PlyType::kFloat32:
      return Load<float>(p);
    case PlyType::kFloat64:
      return Load<double>(p);
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::kFloat32;
  bool is_list = false;
  PlyType count_type = PlyType::kUint8;
};

struct PlyElement {
  std::string name;
  std::size_t count = 0;
  std::vector<PlyProperty> properties;
  int Find(std::string_view n) const {
    for (std::size_t i = 0; i < properties.size(); ++i)
      if (properties[i].name == n) return int(i);
    return -1;
  }
};

// Where each TriMesh attribute comes from among a vertex element's properties (-1 = absent).
struct VertexLayout {
  int position[3], normal[3], velocity[3];
  bool has_normals = false, has_velocities = false;
  explicit VertexLayout(const PlyElement& e) {
    const char* p[3] = {"x", "y", "z"};
    const char* n[3] = {"nx", "ny", "nz"};
    const char* v[3] = {"vx", "vy", "vz"};
    for (int k = 0; k < 3; ++k) {
      position[k] = e.Find(p[k]);
      normal[k] = e.Find(n[k]);
      velocity[k] = e.Find(v[k]);
    }
    has_normals = normal[0] >= 0 && normal[1] >= 0 && normal[2] >= 0;
    has_velocities = velocity[0] >= 0 && velocity[1] >= 0 && velocity[2] >= 0;
  }
};

TriMesh ReadPly(const fs::path& path, const std::string& data) {
  const std::string file = path.string();
  TextCursor c{data.data(), data.data() + data.size()};
  if (c.Word() != "ply") throw InputError("not a PLY file (missing 'ply' magic)", file);
  c.SkipLine();
  bool binary = false;
  std::vector<PlyElement> elements;
  std::size_t line = 1;
  for (;;) {
    ++line;
    if (c.p >= c.end) throw InputError("PLY header has no 'end_header'", file);
    const std::string_view keyword = c.Word();
    const std::string where = fmt::format("{}:{}", file, line);
    if (keyword == "format") {
      const std::string_view format = c.Word();
      if (format == "ascii") binary = false;
      else if (format == "binary_little_endian") binary = true;
      else throw InputError(fmt::format("unsupported PLY format '{}' (ascii and binary_little_endian are read)", format), where);
    } else if (keyword == "element") {
      PlyElement e;
      e.name = std::string(c.Word());
      c.SkipBlanks();
      long long count = 0;
      if (!c.Integer(count) || count < 0) throw InputError("bad element count in PLY header", where);
      e.count = std::size_t(count);
      elements.push_back(std::move(e));
    } else if (keyword == "property") {
      if (elements.empty()) throw InputError("PLY property before any element", where);
      PlyProperty prop;
      std::string_view type = c.Word();
      if (type == "list") {
        prop.is_list = true;
        if (!ParsePlyType(c.Word(), prop.count_type)) throw InputError("unknown PLY list count type", where);
        type = c.Word();
      }
      if (!ParsePlyType(type, prop.type)) throw InputError(fmt::format("unknown PLY property type '{}'", type), where);
      prop.name = std::string(c.Word());
      elements.back().properties.push_back(std::move(prop));
    } else if (keyword == "end_header") {
      c.SkipLine();
      break;
    } else if (keyword != "comment" && keyword != "obj_info" && !keyword.empty()) {
      throw InputError(fmt::format("unexpected PLY header line '{}'", keyword), where);
    }
    c.SkipLine();
  }

  TriMesh mesh;
  bool have_vertices = false;
  for (const PlyElement& e : elements) {
    const bool is_vertex = e.name == "vertex";
    const bool is_face = e.name == "face";
    const VertexLayout layout(e);
    const int face_list = is_face ? std::max(e.Find("vertex_indices"), e.Find("vertex_index")) : -1;
    // Every entry with a property takes at least one byte of the file: a larger count is corrupt,
    // and would otherwise size the vertex arrays beyond memory.
    if (!e.properties.empty() && e.count > std::size_t(c.end - c.p))
      throw InputError(fmt::format("PLY element '{}' claims {} entries, more than the {} bytes left in the file", e.name, e.count,
                                   std::size_t(c.end - c.p)),
                       file);
    if (is_vertex) {
      if (layout.position[0] < 0 || layout.position[1] < 0 || layout.position[2] < 0)
        throw InputError("PLY vertex element lacks x, y or z", file);
      mesh.positions.resize(e.count);
      if (layout.has_normals) mesh.normals.resize(e.count);
      if (layout.has_velocities) mesh.velocities.resize(e.count);
      have_vertices = true;
    }
    if (is_face && face_list < 0) throw InputError("PLY face element lacks a vertex_indices list", file);
    if (is_face && !have_vertices) throw InputError("PLY face element comes before the vertex element", file);
    if (e.properties.empty()) continue;  // nothing to read, however many it claims
    std::vector<double> values(e.properties.size());
    std::vector<std::uint32_t> polygon;

    for (std::size_t i = 0; i < e.count; ++i) {
      auto where = [&] { return fmt::format("{}:{} {}", file, e.name, i); };
      polygon.clear();
      for (std::size_t k = 0; k < e.properties.size(); ++k) {
        const PlyProperty& prop = e.properties[k];
        if (!prop.is_list) {
          if (binary) {
            const std::size_t size = PlyTypeSize(prop.type);
            if (std::size_t(c.end - c.p) < size)
              throw InputError(fmt::format("truncated binary PLY: file ends inside {} {} of {}", e.name, i, e.count), file);
            values[k] = ReadBinary(c.p, prop.type);
            c.p += size;
          } else {
            c.SkipSpaces();
            if (!c.Float(values[k])) throw InputError("expected a number", where());
          }
          continue;
        }
        long long n = 0;
        if (binary) {
          const std::size_t size = PlyTypeSize(prop.count_type);
          if (std::size_t(c.end - c.p) < size)
            throw InputError(fmt::format("truncated binary PLY: file ends inside {} {} of {}", e.name, i, e.count), file);
          const double count = ReadBinary(c.p, prop.count_type);
          c.p += size;
          // Checked before the cast: a float count type can hold values no integer can.
          if (!(count >= 0 && count <= double(c.end - c.p)))
            throw InputError(fmt::format("list length {} out of range (file ends sooner)", count), where());
          n = (long long)count;
        } else {
          c.SkipSpaces();
          if (!c.Integer(n)) throw InputError("expected a list length", where());
        }
        if (n < 0) throw InputError("negative list length", where());
        const std::size_t item = PlyTypeSize(prop.type);
        if (binary && std::size_t(c.end - c.p) < item * std::size_t(n))
          throw InputError(fmt::format("truncated binary PLY: file ends inside {} {} of {}", e.name, i, e.count), file);
        for (long long j = 0; j < n; ++j) {
          double value = 0;
          if (binary) {
            value = ReadBinary(c.p, prop.type);
            c.p += item;
          } else {
            c.SkipSpaces();
            if (!c.Float(value)) throw InputError("expected a list item", where());
          }
          if (int(k) == face_list) {
            if (!(value >= 0 && value < double(mesh.positions.size())))
              throw InputError(fmt::format("vertex index {} out of range (0..{})", value, mesh.positions.size()), where());
            polygon.push_back(std::uint32_t(value));
          }
        }
      }
      if (is_vertex) {
        auto get = [&](const int idx[3]) { return Vec3f(float(values[idx[0]]), float(values[idx[1]]), float(values[idx[2]])); };
        mesh.positions[i] = get(layout.position);
        if (!IsFinite(mesh.positions[i])) throw InputError("NaN or infinite vertex coordinate", where());
        if (layout.has_normals) mesh.normals[i] = get(layout.normal);
        if (layout.has_velocities) {
          mesh.velocities[i] = get(layout.velocity);
          if (!IsFinite(mesh.velocities[i])) throw InputError("NaN or infinite vertex velocity", where());
        }
      } else if (is_face) {
        if (polygon.size() < 3) throw InputError("face with fewer than three vertices", where());
        for (std::size_t k = 1; k + 1 < polygon.size(); ++k) mesh.triangles.push_back({polygon[0], polygon[k], polygon[k + 1]});
      }
    }
  }
  return mesh;
}

// ---------------------------------------------------------------------------------------------
// Writing

/// Area-weighted vertex normals, for meshes that arrive without any.
std::vector<Vec3f> VertexNormals(const TriMesh& mesh) {
  std::vector<Vec3f> normals(mesh.positions.size(), Vec3f(0, 0, 0));
  for (const auto& t : mesh.triangles) {
    const Vec3f n = Cross(mesh.positions[t[1]] - mesh.positions[t[0]], mesh.positions[t[2]] - mesh.positions[t[0]]);
    for (std::uint32_t v : t) normals[v] += n;
  }
  for (Vec3f& n : normals) {
    const float length = Norm(n);
    n = length > 0 ? n / length : Vec3f(0, 0, 1);
  }
  return normals;
}

class OutputBuffer {
 public:
  OutputBuffer(std::FILE* file, const fs::path& path) : file_(file), path_(path) { buffer_.reserve(kCapacity); }
  void Append(std::string_view s) {
    buffer_.append(s);
    FlushIfFull();
  }
  void Append(const void* bytes, std::size_t n) {
    buffer_.append(static_cast<const char*>(bytes), n);
    FlushIfFull();
  }
  void Float(float v) {
    char tmp[32];
    const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
    buffer_.append(tmp, r.ptr);
  }
  void Unsigned(std::uint64_t v) {
    char tmp[24];
    const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
    buffer_.append(tmp, r.ptr);
  }
  void Char(char ch) { buffer_.push_back(ch); }
  void EndLine() {
    buffer_.push_back('\n');
    FlushIfFull();
  }
  void Flush() {
    if (!buffer_.empty() && std::fwrite(buffer_.data(), 1, buffer_.size(), file_) != buffer_.size())
      throw IoError(fmt::format("cannot write mesh: {}", std::strerror(errno)), path_.string());
    buffer_.clear();
  }

 private:
  static constexpr std::size_t kCapacity = 1 << 22;
  void FlushIfFull() {
    if (buffer_.size() > kCapacity - 256) Flush();
  }
  std::FILE* file_;
  const fs::path& path_;
  std::string buffer_;
};

void WriteObj(OutputBuffer& out, const TriMesh& mesh, const std::vector<Vec3f>& normals) {
  out.Append("# Rime mesh: ");
  out.Unsigned(mesh.positions.size());
  out.Append(" vertices, ");
  out.Unsigned(mesh.triangles.size());
  out.Append(" triangles\n");
  for (const Vec3f& p : mesh.positions) {
    out.Append("v ");
    out.Float(p.x), out.Char(' '), out.Float(p.y), out.Char(' '), out.Float(p.z);
    out.EndLine();
  }
  for (const Vec3f& n : normals) {
    out.Append("vn ");
    out.Float(n.x), out.Char(' '), out.Float(n.y), out.Char(' '), out.Float(n.z);
    out.EndLine();
  }
  for (const auto& t : mesh.triangles) {
    out.Char('f');
    for (std::uint32_t v : t) {
      out.Char(' '), out.Unsigned(v + 1), out.Append("//"), out.Unsigned(v + 1);
    }
    out.EndLine();
  }
}

void WritePly(OutputBuffer& out, const TriMesh& mesh, const std::vector<Vec3f>& normals) {
  const bool velocities = !mesh.velocities.empty();
  std::string header = fmt::format(
      "ply\nformat binary_little_endian 1.0\ncomment Rime mesh\nelement vertex {}\n"
      "property float x\nproperty float y\nproperty float z\n"
      "property float nx\nproperty float ny\nproperty float nz\n",
      mesh.positions.size());
  if (velocities) header += "property float vx\nproperty float vy\nproperty float vz\n";
  header += fmt::format("element face {}\nproperty list uchar int vertex_indices\nend_header\n", mesh.triangles.size());
  out.Append(header);
  float record[9];
  const std::size_t floats = velocities ? 9 : 6;
  for (std::size_t i = 0; i < mesh.positions.size(); ++i) {
    const Vec3f& p = mesh.positions[i];
    const Vec3f& n = normals[i];
    record[0] = p.x, record[1] = p.y, record[2] = p.z, record[3] = n.x, record[4] = n.y, record[5] = n.z;
    if (velocities) record[6] = mesh.velocities[i].x, record[7] = mesh.velocities[i].y, record[8] = mesh.velocities[i].z;
    out.Append(record, floats * sizeof(float));
  }
  char face[13];
  face[0] = 3;
  for (const auto& t : mesh.triangles) {
    const std::int32_t idx[3] = {std::int32_t(t[0]), std::int32_t(t[1]), std::int32_t(t[2])};
    std::memcpy(face + 1, idx, sizeof idx);
    out.Append(face, sizeof face);
  }
}

}  // namespace

TriMesh ReadMesh(const fs::path& path) {
  const std::string ext = LowerExtension(path);
  if (ext != ".obj" && ext != ".ply")
    throw InputError(fmt::format("unsupported mesh format '{}' (expected .obj or .ply)", ext), path.string());
  const std::string data = ReadWholeFile(path);
  TriMesh mesh = ext == ".obj" ? ReadObj(path, data) : ReadPly(path, data);
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size()) mesh.normals.clear();
  return mesh;
}

void WriteMesh(const fs::path& path, const TriMesh& mesh) {
  const std::string ext = LowerExtension(path);
  if (ext != ".obj" && ext != ".ply")
    throw Error(ExitCode::kUsage, fmt::format("unsupported mesh format '{}' (expected .obj or .ply)", ext), path.string());
  if (!mesh.normals.empty() && mesh.normals.size() != mesh.positions.size())
    throw Error(ExitCode::kFailure, "mesh has a normal count different from its vertex count", path.string());
  if (!mesh.velocities.empty() && mesh.velocities.size() != mesh.positions.size())
    throw Error(ExitCode::kFailure, "mesh has a velocity count different from its vertex count", path.string());
  const std::vector<Vec3f> computed = mesh.normals.empty() ? VertexNormals(mesh) : std::vector<Vec3f>{};
  const std::vector<Vec3f>& normals = mesh.normals.empty() ? computed : mesh.normals;

  if (path.has_parent_path()) {
    std::error_code ec;
    fs::create_directories(path.parent_path(), ec);
  }
  AtomicFile atomic(path);
  {
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file(std::fopen(atomic.temp_path().c_str(), "wb"), &std::fclose);
    if (!file) throw IoError(fmt::format("cannot create mesh file: {}", std::strerror(errno)), path.string());
    OutputBuffer out(file.get(), path);
    if (ext == ".obj") WriteObj(out, mesh, normals);
    else WritePly(out, mesh, normals);
    out.Flush();
    if (std::fclose(file.release()) != 0) throw IoError(fmt::format("cannot write mesh: {}", std::strerror(errno)), path.string());
  }
  atomic.Commit();
}

}  // namespace rime::io
