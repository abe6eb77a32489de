// Particle frames: bit-exact round trips and clear, distinct errors for bad files.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <limits>
#include <random>

#include "rime/core/error.h"
#include "rime/io/particles.h"
#include "rime/test/temp_folder.h"

namespace fs = std::filesystem;

namespace rime::io {
namespace {

class ParticleFiles : public ::testing::Test {
 protected:
  static ParticleFrame Sample(std::size_t n) {
    std::mt19937 rng(11);
    std::uniform_real_distribution<float> u(-1, 1);
    ParticleFrame f;
    f.time = 0.123456789012345;
    f.frame = 17;
    f.spacing = 0.02;
    f.particle_radius = 0.01;
    f.scene_hash = "abcdef0123456789";
    f.numbers["ice_count"] = 42;
    f.texts["mesh_hash"] = "0011";
    std::vector<Vec3f> p(n), v(n);
    for (std::size_t i = 0; i < n; ++i) {
      p[i] = {u(rng), u(rng), u(rng)};
      v[i] = {u(rng), u(rng), std::numeric_limits<float>::denorm_min() * i};
    }
    f.SetPositions(p);
    f.SetVec3("v", v);
    std::vector<double> pressure(n);
    std::vector<std::uint8_t> phase(n);
    std::vector<std::int64_t> id(n);
    std::vector<std::uint32_t> object(n);
    std::vector<std::int32_t> kind(n);
    for (std::size_t i = 0; i < n; ++i) {
      pressure[i] = std::sqrt(double(i)) * 1e3;
      phase[i] = i % 3;
      id[i] = std::int64_t(i) * 1000000007LL;
      object[i] = i % 5;
      kind[i] = -int(i);
    }
    f.Set("pressure", pressure);
    f.Set("phase", phase);
    f.Set("id", id);
    f.Set("object_id", object);
    f.Set("kind", kind);
    return f;
  }

  rime::test::TempFolder temp_{"io"};
  fs::path dir_ = temp_.path();
};

TEST_F(ParticleFiles, RoundTripsEveryAttributeBitExactly) {
  for (std::size_t n : {0, 1, 1000, 70000}) {
    const ParticleFrame out = Sample(n);
    const fs::path path = dir_ / "f.h5part";
    WriteParticleFrame(path, out);
    const ParticleFrame in = ReadParticleFrame(path);
    EXPECT_EQ(in.size(), n);
    EXPECT_EQ(in.time, out.time);
    EXPECT_EQ(in.frame, out.frame);
    EXPECT_EQ(in.spacing, out.spacing);
    EXPECT_EQ(in.scene_hash, out.scene_hash);
    EXPECT_EQ(in.numbers, out.numbers);
    EXPECT_EQ(in.texts, out.texts);
    ASSERT_EQ(in.attributes.size(), out.attributes.size());
    for (const auto& [name, data] : out.attributes) {
      ASSERT_TRUE(in.Has(name)) << name;
      EXPECT_TRUE(in.attributes.at(name) == data) << name << " differs after the round trip (n=" << n << ")";
    }
    EXPECT_EQ(in.GetVec3<float>("v"), out.GetVec3<float>("v"));
  }
}

TEST_F(ParticleFiles, H5PartLayout) {
  const fs::path path = dir_ / "f.h5part";
  WriteParticleFrame(path, Sample(10));
  const hid_t file = H5Fopen(path.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  EXPECT_GT(H5Lexists(file, "Step#0", H5P_DEFAULT), 0);
  EXPECT_GT(H5Lexists(file, "Step#0/x", H5P_DEFAULT), 0);
  EXPECT_GT(H5Lexists(file, "Step#0/v_2", H5P_DEFAULT), 0);
  const hid_t group = H5Gopen2(file, "Step#0", H5P_DEFAULT);
  const hid_t attr = H5Aopen(group, "TimeValue", H5P_DEFAULT);
  const hid_t type = H5Aget_type(attr);
  EXPECT_EQ(H5Tget_class(type), H5T_FLOAT);
  EXPECT_EQ(H5Tget_size(type), 8u) << "ParaView ignores a float32 TimeValue";
  H5Tclose(type);
  H5Aclose(attr);
  H5Gclose(group);
  H5Fclose(file);
}

TEST_F(ParticleFiles, SequenceIndexLinksFrames) {
  std::vector<IndexEntry> entries;
  for (int k = 0; k < 3; ++k) {
    ParticleFrame f = Sample(5);
    f.frame = k;
    f.time = k / 24.0;
    const fs::path path = FramePath(dir_, "particles", k, "h5part");
    WriteParticleFrame(path, f);
    entries.push_back({path, f.time});
  }
  EXPECT_EQ(entries[1].frame_file.filename(), "particles.0001.h5part");
  WriteSequenceIndex(dir_ / "particles.h5part", entries);
  const hid_t file = H5Fopen((dir_ / "particles.h5part").c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
  ASSERT_GE(file, 0);
  // Follow the external link to frame 2 and read its time.
  const hid_t group = H5Gopen2(file, "Step#2", H5P_DEFAULT);
  ASSERT_GE(group, 0) << "external link not resolvable";
  double time = -1;
  const hid_t attr = H5Aopen(group, "TimeValue", H5P_DEFAULT);
  H5Aread(attr, H5T_NATIVE_DOUBLE, &time);
  EXPECT_DOUBLE_EQ(time, 2 / 24.0);
  H5Aclose(attr);
  H5Gclose(group);
  H5Fclose(file);
}

std::string ErrorOf(const fs::path& path, std::string_view kind = {}) {
  try {
    ReadParticleFrame(path, kind);
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kBadInput);
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << "error must name the file: " << e.what();
    return e.message();
  }
  ADD_FAILURE() << "no error for " << path;
  return {};
}

TEST_F(ParticleFiles, BadFilesGiveDistinctClearErrors) {
  const fs::path good = dir_ / "good.h5part";
  WriteParticleFrame(good, Sample(20000));

  const std::string missing = ErrorOf(dir_ / "nope.h5part");
  EXPECT_NE(missing.find("not found"), std::string::npos) << missing;

  const fs::path truncated = dir_ / "truncated.h5part";
  fs::copy_file(good, truncated);
  fs::resize_file(truncated, fs::file_size(good) / 2);
  const std::string trunc = ErrorOf(truncated);
  EXPECT_NE(trunc.find("truncated"), std::string::npos) << trunc;

  const fs::path text = dir_ / "text.h5part";
  std::ofstream(text) << "hello";
  const std::string not_hdf5 = ErrorOf(text);

  ParticleFrame wrong = Sample(3);
  const fs::path wrong_format = dir_ / "wrong_format.h5part";
  WriteParticleFrame(wrong_format, wrong);
  {  // rewrite the format attribute
    const hid_t f = H5Fopen(wrong_format.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    H5Adelete(f, "format");
    const hid_t t = H5Tcopy(H5T_C_S1);
    H5Tset_size(t, 9);
    const hid_t s = H5Screate(H5S_SCALAR);
    const hid_t a = H5Acreate2(f, "format", t, s, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(a, t, "other.fmt");
    H5Aclose(a), H5Sclose(s), H5Tclose(t), H5Fclose(f);
  }
  const std::string format = ErrorOf(wrong_format);
  EXPECT_NE(format.find("wrong format 'other.fmt'"), std::string::npos) << format;

  const fs::path newer = dir_ / "newer.h5part";
  WriteParticleFrame(newer, wrong);
  {
    const hid_t f = H5Fopen(newer.c_str(), H5F_ACC_RDWR, H5P_DEFAULT);
    const hid_t a = H5Aopen(f, "version", H5P_DEFAULT);
    const double v = 99;
    H5Awrite(a, H5T_NATIVE_DOUBLE, &v);
    H5Aclose(a), H5Fclose(f);
  }
  const std::string version = ErrorOf(newer);
  EXPECT_NE(version.find("version 99"), std::string::npos) << version;

  const std::string kind = ErrorOf(good, "boundary");
  EXPECT_NE(kind.find("expected 'boundary'"), std::string::npos) << kind;

  // Missing dataset: the reader loads; asking for it names it.
  const ParticleFrame f = ReadParticleFrame(good);
  try {
    f.Get<float>("density");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("missing dataset 'Step#0/density'"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(good.string()), std::string::npos);
  }
  const std::set<std::string> all{missing, trunc, not_hdf5, format, version, kind};
  EXPECT_EQ(all.size(), 6u) << "every failure mode must have its own message";
}

TEST_F(ParticleFiles, UnwritableFolderIsAnIoError) {
  try {
    WriteParticleFrame("/proc/rime_cannot_write_here/f.h5part", Sample(3));
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ExitCode::kIo);
  }
}

}  // namespace
}  // namespace rime::io
