#include "rime/io/particles.h"

#include <hdf5.h>

#include <fmt/format.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <type_traits>

#include "rime/core/atomic_file.h"
#include "rime/core/error.h"

namespace fs = std::filesystem;

namespace rime::io {
namespace {

constexpr const char* kStepGroup = "Step#0";

// Owns an HDF5 identifier and closes it with the right function.
class Handle {
 public:
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  ~Handle() {
    if (id_ >= 0) close_(id_);
  }
  Handle(Handle&& o) noexcept : id_(o.id_), close_(o.close_) { o.id_ = -1; }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  operator hid_t() const { return id_; }
  bool valid() const { return id_ >= 0; }
  herr_t Close() {
    const herr_t r = id_ >= 0 ? close_(id_) : 0;
    id_ = -1;
    return r;
  }

 private:
  hid_t id_;
  herr_t (*close_)(hid_t);
};

struct SilenceHdf5 {
  SilenceHdf5() {
    // A file whose write failed (disk full) cannot be closed; HDF5's exit handler would then
    // crash closing it again, turning a clear error and exit 5 into a segfault. Every file is
    // closed explicitly on success, so the handler has nothing to do anyway.
    H5dont_atexit();
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
};
const SilenceHdf5 g_silence;

template <class T>
hid_t NativeType();
template <>
hid_t NativeType<float>() {
  return H5T_NATIVE_FLOAT;
}
template <>
hid_t NativeType<double>() {
  return H5T_NATIVE_DOUBLE;
}
template <>
hid_t NativeType<std::int32_t>() {
  return H5T_NATIVE_INT32;
}
template <>
hid_t NativeType<std::uint32_t>() {
  return H5T_NATIVE_UINT32;
}
template <>
hid_t NativeType<std::int64_t>() {
  return H5T_NATIVE_INT64;
}
template <>
hid_t NativeType<std::uint8_t>() {
  return H5T_NATIVE_UINT8;
}

void Check(herr_t status, const std::string& what, const fs::path& file) {
  if (status >= 0) return;
  // HDF5 leaves errno from the failed write(2); only a write error's errno is named, since HDF5
  // may leave a stale one (ENOENT from a probe) when it failed for a reason of its own.
  const int error = errno;
  if (error == ENOSPC || error == EFBIG || error == EDQUOT || error == EIO || error == EROFS || error == EACCES)
    throw IoError(fmt::format("cannot write {}: {}", what, std::strerror(error)), file.string());
  throw IoError("cannot write " + what + " (disk full or not writable?)", file.string());
}

void WriteNumberAttribute(hid_t object, const char* name, hid_t type, const void* value, const fs::path& file) {
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  Handle attr(H5Acreate2(object, name, type, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.valid()) Check(-1, std::string("attribute ") + name, file);
  Check(H5Awrite(attr, type, value), std::string("attribute ") + name, file);
}

void WriteStringAttribute(hid_t object, const char* name, const std::string& value, const fs::path& file) {
  Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(type, std::max<std::size_t>(1, value.size()));
  H5Tset_strpad(type, H5T_STR_NULLPAD);
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  Handle attr(H5Acreate2(object, name, type, space, H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.valid()) Check(-1, std::string("attribute ") + name, file);
  const std::string padded = value.empty() ? std::string(1, '\0') : value;
  Check(H5Awrite(attr, type, padded.data()), std::string("attribute ") + name, file);
}

template <class T>
void WriteDataset(hid_t group, const std::string& name, const std::vector<T>& values, const WriteOptions& options, const fs::path& file) {
  const hsize_t n = values.size();
  Handle space(H5Screate_simple(1, &n, nullptr), H5Sclose);
  Handle properties(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
  // No modification times in the object headers: the same particles give byte-identical files,
  // which rime-bake's early cutoff relies on (a rerun with identical output dirties nothing).
  H5Pset_obj_track_times(properties, false);
  if (n > 0 && options.compression_level > 0) {
    const hsize_t chunk = std::min<hsize_t>(n, 1 << 16);
    H5Pset_chunk(properties, 1, &chunk);
    H5Pset_shuffle(properties);
    H5Pset_deflate(properties, options.compression_level);
  }
  Handle dataset(H5Dcreate2(group, name.c_str(), NativeType<T>(), space, H5P_DEFAULT, properties, H5P_DEFAULT), H5Dclose);
  if (!dataset.valid()) Check(-1, "dataset " + name, file);
  if (n > 0) Check(H5Dwrite(dataset, NativeType<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()), "dataset " + name, file);
}

bool HasAttribute(hid_t object, const char* name) { return H5Aexists(object, name) > 0; }

// H5Aread writes every element of the attribute: one value is read into one value's memory.
void RequireScalar(hid_t attr, const char* name, const fs::path& file) {
  Handle space(H5Aget_space(attr), H5Sclose);
  if (!space.valid() || H5Sget_simple_extent_npoints(space) != 1)
    throw InputError(fmt::format("attribute '{}' is not a single value (corrupt file)", name), file.string());
}

double ReadNumberAttribute(hid_t object, const char* name, const fs::path& file) {
  Handle attr(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  double value = 0;
  if (!attr.valid()) throw InputError(fmt::format("missing attribute '{}'", name), file.string());
  RequireScalar(attr, name, file);
  if (H5Aread(attr, H5T_NATIVE_DOUBLE, &value) < 0) throw InputError(fmt::format("unreadable attribute '{}'", name), file.string());
  return value;
}

std::string ReadStringAttribute(hid_t object, const char* name, const fs::path& file) {
  Handle attr(H5Aopen(object, name, H5P_DEFAULT), H5Aclose);
  if (!attr.valid()) throw InputError(fmt::format("missing attribute '{}'", name), file.string());
  Handle type(H5Aget_type(attr), H5Tclose);
  if (H5Tget_class(type) != H5T_STRING) throw InputError(fmt::format("attribute '{}' is not a string", name), file.string());
  RequireScalar(attr, name, file);
  if (H5Tis_variable_str(type) > 0) {
    char* value = nullptr;
    Handle memtype(H5Tcopy(H5T_C_S1), H5Tclose);
    H5Tset_size(memtype, H5T_VARIABLE);
    if (H5Aread(attr, memtype, &value) < 0) throw InputError(fmt::format("unreadable attribute '{}'", name), file.string());
    std::string s = value ? value : "";
    H5free_memory(value);
    return s;
  }
  // Fixed-size strings are stored whole in the file: a size beyond it is corrupt, not an allocation to try.
  std::error_code ec;
  const std::size_t size = H5Tget_size(type);
  if (size == 0 || size > fs::file_size(file, ec))
    throw InputError(fmt::format("attribute '{}' claims {} bytes, more than the file holds (corrupt file)", name, size), file.string());
  std::string s(size, '\0');
  if (H5Aread(attr, type, s.data()) < 0) throw InputError(fmt::format("unreadable attribute '{}'", name), file.string());
  s.erase(std::find(s.begin(), s.end(), '\0'), s.end());
  return s;
}

template <class T>
std::vector<T> ReadDataset(hid_t dataset, hsize_t n, const std::string& name, const fs::path& file) {
  std::vector<T> values(n);
  if (n > 0 && H5Dread(dataset, NativeType<T>(), H5S_ALL, H5S_ALL, H5P_DEFAULT, values.data()) < 0)
    throw InputError(fmt::format("dataset '{}/{}' is unreadable (truncated or corrupt file)", kStepGroup, name), file.string());
  return values;
}

const char* kReservedNumbers[] = {"version", "particle_radius", "spacing", "rest_density", "time", "frame"};
const char* kReservedTexts[] = {"format", "kind", "units", "scene_hash"};

bool IsReserved(const std::string& name) {
  for (const char* r : kReservedNumbers)
    if (name == r) return true;
  for (const char* r : kReservedTexts)
    if (name == r) return true;
  return false;
}

Handle OpenChecked(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError("file not found", path.string());
  if (H5Fis_hdf5(path.c_str()) <= 0) throw InputError("not an HDF5 file (corrupt, truncated or wrong type)", path.string());
  Handle file(H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT), H5Fclose);
  if (!file.valid()) throw InputError("cannot open HDF5 file (truncated or corrupt)", path.string());
  return file;
}

void ReadHeader(hid_t file, const fs::path& path, std::string_view expected_kind, ParticleFrame& frame) {
  if (!HasAttribute(file, "format")) throw InputError("not a Rime particle file (no 'format' attribute)", path.string());
  const std::string format = ReadStringAttribute(file, "format", path);
  if (format != kParticleFormatName)
    throw InputError(fmt::format("wrong format '{}' (expected '{}')", format, kParticleFormatName), path.string());
  const double version = ReadNumberAttribute(file, "version", path);
  if (!(version >= 1 && version <= kParticleFormatVersion))  // NaN too
    throw InputError(fmt::format("unsupported format version {} (this build reads version {}{})", version, kParticleFormatVersion,
                                 version > kParticleFormatVersion ? "; written by a newer Rime" : ""),
                     path.string());
  frame.kind = ReadStringAttribute(file, "kind", path);
  if (!expected_kind.empty() && frame.kind != expected_kind)
    throw InputError(fmt::format("file holds '{}' particles, expected '{}'", frame.kind, expected_kind), path.string());
  frame.time = ReadNumberAttribute(file, "time", path);
  const double frame_number = ReadNumberAttribute(file, "frame", path);
  if (!(std::abs(frame_number) < 1e15))  // also refuses NaN, whose cast to an integer is undefined
    throw InputError(fmt::format("frame number {} out of range (corrupt file)", frame_number), path.string());
  frame.frame = static_cast<std::int64_t>(frame_number);
  frame.spacing = ReadNumberAttribute(file, "spacing", path);
  frame.particle_radius = ReadNumberAttribute(file, "particle_radius", path);
  frame.rest_density = ReadNumberAttribute(file, "rest_density", path);
  frame.scene_hash = ReadStringAttribute(file, "scene_hash", path);
  frame.source = path.string();
  const hsize_t count = [&] {
    H5O_info_t info;
    if (H5Oget_info2(file, &info, H5O_INFO_NUM_ATTRS) < 0) throw InputError("unreadable root attributes (corrupt file)", path.string());
    return info.num_attrs;
  }();
  for (hsize_t a = 0; a < count; ++a) {
    char name[256];
    if (H5Aget_name_by_idx(file, ".", H5_INDEX_NAME, H5_ITER_INC, a, name, sizeof name, H5P_DEFAULT) < 0) continue;
    if (IsReserved(name)) continue;
    Handle attr(H5Aopen(file, name, H5P_DEFAULT), H5Aclose);
    if (!attr.valid()) throw InputError(fmt::format("unreadable attribute '{}' (corrupt file)", name), path.string());
    Handle type(H5Aget_type(attr), H5Tclose);
    if (H5Tget_class(type) == H5T_STRING) frame.texts[name] = ReadStringAttribute(file, name, path);
    else frame.numbers[name] = ReadNumberAttribute(file, name, path);
  }
}

ParticleFrame Read(const fs::path& path, std::string_view expected_kind, bool with_data) {
  Handle file = OpenChecked(path);
  ParticleFrame frame;
  ReadHeader(file, path, expected_kind, frame);
  if (!with_data) return frame;
  Handle group(H5Gopen2(file, kStepGroup, H5P_DEFAULT), H5Gclose);
  if (!group.valid()) throw InputError(fmt::format("missing group '{}'", kStepGroup), path.string());
  H5G_info_t info;
  if (H5Gget_info(group, &info) < 0) throw InputError("unreadable group Step#0 (corrupt file)", path.string());
  for (hsize_t k = 0; k < info.nlinks; ++k) {
    char name[256];
    if (H5Lget_name_by_idx(group, ".", H5_INDEX_NAME, H5_ITER_INC, k, name, sizeof name, H5P_DEFAULT) < 0)
      throw InputError("unreadable dataset name in Step#0 (corrupt file)", path.string());
    Handle dataset(H5Dopen2(group, name, H5P_DEFAULT), H5Dclose);
    if (!dataset.valid()) throw InputError(fmt::format("dataset 'Step#0/{}' is unreadable (corrupt file)", name), path.string());
    Handle space(H5Dget_space(dataset), H5Sclose);
    if (H5Sget_simple_extent_ndims(space) != 1)
      throw InputError(fmt::format("dataset 'Step#0/{}' is not one-dimensional", name), path.string());
    hsize_t n = 0;
    H5Sget_simple_extent_dims(space, &n, nullptr);
    Handle type(H5Dget_type(dataset), H5Tclose);
    const H5T_class_t type_class = H5Tget_class(type);
    const std::size_t bytes = H5Tget_size(type);
    const bool is_signed = type_class == H5T_INTEGER && H5Tget_sign(type) == H5T_SGN_2;
    // Values come from the file's storage, at most deflate's ratio (about 1000:1) larger than the
    // file: a count beyond that is corrupt and would only exhaust memory.
    std::error_code ec;
    const double most = 1100.0 * double(fs::file_size(path, ec));
    if (n > 0 && (bytes == 0 || H5Dget_storage_size(dataset) == 0 || double(n) * double(bytes) > most))
      throw InputError(fmt::format("dataset 'Step#0/{}' claims {} values, more than the file holds (corrupt file)", name, n),
                       path.string());
    if (type_class == H5T_FLOAT && bytes == 4) frame.attributes[name] = ReadDataset<float>(dataset, n, name, path);
    else if (type_class == H5T_FLOAT && bytes == 8) frame.attributes[name] = ReadDataset<double>(dataset, n, name, path);
    else if (type_class == H5T_INTEGER && bytes == 1) frame.attributes[name] = ReadDataset<std::uint8_t>(dataset, n, name, path);
    else if (type_class == H5T_INTEGER && bytes == 4 && is_signed)
      frame.attributes[name] = ReadDataset<std::int32_t>(dataset, n, name, path);
    else if (type_class == H5T_INTEGER && bytes == 4) frame.attributes[name] = ReadDataset<std::uint32_t>(dataset, n, name, path);
    else if (type_class == H5T_INTEGER && bytes == 8) frame.attributes[name] = ReadDataset<std::int64_t>(dataset, n, name, path);
    else throw InputError(fmt::format("dataset 'Step#0/{}' has an unsupported element type", name), path.string());
  }
  frame.Validate();
  return frame;
}

template <class T>
const char* TypeName() {
  if constexpr (std::is_same_v<T, float>) return "float32";
  if constexpr (std::is_same_v<T, double>) return "float64";
  if constexpr (std::is_same_v<T, std::int32_t>) return "int32";
  if constexpr (std::is_same_v<T, std::uint32_t>) return "uint32";
  if constexpr (std::is_same_v<T, std::int64_t>) return "int64";
  return "uint8";
}

}  // namespace

std::size_t ParticleFrame::size() const {
  if (attributes.empty()) return 0;
  return std::visit([](const auto& v) { return v.size(); }, attributes.begin()->second);
}

void ParticleFrame::Validate() const {
  const std::size_t n = size();
  for (const auto& [name, data] : attributes) {
    const std::size_t m = std::visit([](const auto& v) { return v.size(); }, data);
    if (m != n)
      throw InputError(fmt::format("dataset '{}' has {} values but '{}' has {}", name, m, attributes.begin()->first, n),
                       source.empty() ? "particle frame" : source);
  }
}

template <class T>
const std::vector<T>& ParticleFrame::Get(const std::string& name) const {
  const auto it = attributes.find(name);
  const std::string where = source.empty() ? "particle frame" : source;
  if (it == attributes.end()) throw InputError(fmt::format("missing dataset 'Step#0/{}'", name), where);
  const auto* values = std::get_if<std::vector<T>>(&it->second);
  if (!values) throw InputError(fmt::format("dataset 'Step#0/{}' is not {}", name, TypeName<T>()), where);
  return *values;
}

template <class T>
void ParticleFrame::SetVec3(const std::string& base, const std::vector<Vec3<T>>& values) {
  std::vector<T> c[3];
  for (auto& v : c) v.resize(values.size());
  for (std::size_t i = 0; i < values.size(); ++i)
    for (int a = 0; a < 3; ++a) c[a][i] = values[i][a];
  for (int a = 0; a < 3; ++a) Set(base + "_" + std::to_string(a), std::move(c[a]));
}

template <class T>
std::vector<Vec3<T>> ParticleFrame::GetVec3(const std::string& base) const {
  const auto& c0 = Get<T>(base + "_0");
  const auto& c1 = Get<T>(base + "_1");
  const auto& c2 = Get<T>(base + "_2");
  std::vector<Vec3<T>> out(c0.size());
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = {c0[i], c1[i], c2[i]};
  return out;
}

template <class T>
void ParticleFrame::SetPositions(const std::vector<Vec3<T>>& p) {
  std::vector<T> x(p.size()), y(p.size()), z(p.size());
  for (std::size_t i = 0; i < p.size(); ++i) x[i] = p[i].x, y[i] = p[i].y, z[i] = p[i].z;
  Set("x", std::move(x));
  Set("y", std::move(y));
  Set("z", std::move(z));
}

template <class T>
std::vector<Vec3<T>> ParticleFrame::GetPositions() const {
  // Positions may be stored in either precision; convert on read.
  auto axis = [&](const char* name) -> std::vector<T> {
    const auto it = attributes.find(name);
    if (it != attributes.end()) {
      if (const auto* f = std::get_if<std::vector<float>>(&it->second)) return {f->begin(), f->end()};
      if (const auto* d = std::get_if<std::vector<double>>(&it->second)) return {d->begin(), d->end()};
    }
    return Get<T>(name);  // throws with the right message
  };
  const auto x = axis("x"), y = axis("y"), z = axis("z");
  std::vector<Vec3<T>> out(x.size());
  for (std::size_t i = 0; i < out.size(); ++i) out[i] = {x[i], y[i], z[i]};
  return out;
}

#define RIME_INSTANTIATE(T) template const std::vector<T>& ParticleFrame::Get<T>(const std::string&) const;
RIME_INSTANTIATE(float)
RIME_INSTANTIATE(double)
RIME_INSTANTIATE(std::int32_t)
RIME_INSTANTIATE(std::uint32_t)
RIME_INSTANTIATE(std::int64_t)
RIME_INSTANTIATE(std::uint8_t)
#undef RIME_INSTANTIATE
template void ParticleFrame::SetVec3<float>(const std::string&, const std::vector<Vec3<float>>&);
template void ParticleFrame::SetVec3<double>(const std::string&, const std::vector<Vec3<double>>&);
template std::vector<Vec3<float>> ParticleFrame::GetVec3<float>(const std::string&) const;
template std::vector<Vec3<double>> ParticleFrame::GetVec3<double>(const std::string&) const;
template void ParticleFrame::SetPositions<float>(const std::vector<Vec3<float>>&);
template void ParticleFrame::SetPositions<double>(const std::vector<Vec3<double>>&);
template std::vector<Vec3<float>> ParticleFrame::GetPositions<float>() const;
template std::vector<Vec3<double>> ParticleFrame::GetPositions<double>() const;

void WriteParticleFrame(const fs::path& path, const ParticleFrame& frame, const WriteOptions& options) {
  frame.Validate();
  AtomicFile atomic(path);
  {
    Handle file(H5Fcreate(atomic.temp_path().c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file.valid()) throw IoError("cannot create file (folder missing or not writable?)", path.string());
    WriteStringAttribute(file, "format", kParticleFormatName, path);
    const double version = kParticleFormatVersion;
    WriteNumberAttribute(file, "version", H5T_NATIVE_DOUBLE, &version, path);
    WriteStringAttribute(file, "kind", frame.kind, path);
    WriteStringAttribute(file, "units", "SI (m, s, kg)", path);
    WriteNumberAttribute(file, "particle_radius", H5T_NATIVE_DOUBLE, &frame.particle_radius, path);
    WriteNumberAttribute(file, "spacing", H5T_NATIVE_DOUBLE, &frame.spacing, path);
    WriteNumberAttribute(file, "rest_density", H5T_NATIVE_DOUBLE, &frame.rest_density, path);
    WriteNumberAttribute(file, "time", H5T_NATIVE_DOUBLE, &frame.time, path);
    const double frame_number = static_cast<double>(frame.frame);
    WriteNumberAttribute(file, "frame", H5T_NATIVE_DOUBLE, &frame_number, path);
    WriteStringAttribute(file, "scene_hash", frame.scene_hash, path);
    for (const auto& [name, value] : frame.numbers) {
      if (IsReserved(name)) throw IoError("extra attribute uses a reserved name: " + name, path.string());
      WriteNumberAttribute(file, name.c_str(), H5T_NATIVE_DOUBLE, &value, path);
    }
    for (const auto& [name, value] : frame.texts) {
      if (IsReserved(name)) throw IoError("extra attribute uses a reserved name: " + name, path.string());
      WriteStringAttribute(file, name.c_str(), value, path);
    }
    Handle group(H5Gcreate2(file, kStepGroup, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
    if (!group.valid()) Check(-1, "group Step#0", path);
    WriteNumberAttribute(group, "TimeValue", H5T_NATIVE_DOUBLE, &frame.time, path);
    for (const auto& attribute : frame.attributes)  // not a structured binding: clang 14 cannot capture one
      std::visit([&](const auto& values) { WriteDataset(group, attribute.first, values, options, path); }, attribute.second);
    group.Close();
    if (H5Fflush(file, H5F_SCOPE_GLOBAL) < 0 || file.Close() < 0) Check(-1, "file contents", path);
  }
  atomic.Commit();
}

ParticleFrame ReadParticleFrame(const fs::path& path, std::string_view expected_kind) { return Read(path, expected_kind, true); }
ParticleFrame ReadParticleFrameHeader(const fs::path& path, std::string_view expected_kind) { return Read(path, expected_kind, false); }

void WriteSequenceIndex(const fs::path& index_path, const std::vector<IndexEntry>& entries) {
  AtomicFile atomic(index_path);
  {
    Handle file(H5Fcreate(atomic.temp_path().c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file.valid()) throw IoError("cannot create index file", index_path.string());
    WriteStringAttribute(file, "format", "rime.particles.index", index_path);
    const double version = kParticleFormatVersion;
    WriteNumberAttribute(file, "version", H5T_NATIVE_DOUBLE, &version, index_path);
    const fs::path base = index_path.parent_path();
    for (std::size_t k = 0; k < entries.size(); ++k) {
      const fs::path relative = entries[k].frame_file.is_absolute() && !base.empty() ? fs::relative(entries[k].frame_file, base)
                                                                                     : entries[k].frame_file.filename();
      const std::string link = fmt::format("Step#{}", k);
      Check(H5Lcreate_external(relative.c_str(), "/Step#0", file, link.c_str(), H5P_DEFAULT, H5P_DEFAULT), link, index_path);
    }
    if (file.Close() < 0) Check(-1, "index file", index_path);
  }
  atomic.Commit();
}

fs::path FramePath(const fs::path& folder, std::string_view stem, std::int64_t frame, std::string_view extension, int padding) {
  return folder / fmt::format("{}.{:0{}}.{}", stem, frame, padding, extension);
}

}  // namespace rime::io
