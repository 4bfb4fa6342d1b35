// Tests of the dataset file (write, read, validate, layout, determinism) and the CSV importer.
#include <gtest/gtest.h>
#include <hdf5.h>
#include <unistd.h>

#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <limits>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "ruffini/dataset/csv_import.h"
#include "ruffini/dataset/dataset.h"
#include "ruffini/error.h"

namespace ruffini::dataset {
namespace {

namespace fs = std::filesystem;
constexpr float kNaNf = std::numeric_limits<float>::quiet_NaN();
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// A fresh folder per test, removed afterwards.
class DatasetTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    dir_ = fs::path(::testing::TempDir()) /
           (std::to_string(::getpid()) + "_ruffini_dataset_" + info->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }
  [[nodiscard]] std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
};

DatasetInfo MakeInfo() {
  DatasetInfo info;
  info.sample_rate_hz = 250.0;
  info.source = "twin: scene=press, seed=7, effects=noise";
  info.patch_name = "finger-16";
  info.surface_radius_mm = 12.5;
  for (std::size_t k = 0; k < kChannels; ++k) info.reference_wavelength_nm[k] = 1530.0 + 2.5 * static_cast<double>(k);
  info.attributes = {{"alpha", "first"}, {"config", "noise: 0.1\nseed: 7"}};  // sorted by name
  return info;
}

// Random-ish but reproducible frames, with NaN peaks and labels and indentation runs.
Dataset MakeData(std::size_t n, std::uint64_t seed = 42) {
  Dataset data;
  data.info = MakeInfo();
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::uniform_real_distribution<float> force(0.0f, 5.0f);
  for (std::size_t i = 0; i < n; ++i) {
    Frame f;
    for (std::size_t k = 0; k < kChannels; ++k) {
      f.wavelength_nm[k] = data.info.reference_wavelength_nm[k] + noise(rng);
    }
    if (i % 97 == 3) f.wavelength_nm[i % kChannels] = kNaN;
    f.t_s = static_cast<double>(i) / 250.0;
    f.serial = 1000 + i + (i > n / 2 ? 1 : 0);  // one lost sample
    f.flags = static_cast<std::uint32_t>(i % 5 == 0 ? kFlagSaturated | kFlagPeakMissing : kFlagNone);
    f.force_n = force(rng);
    f.true_force_n = i % 11 == 0 ? kNaNf : force(rng);
    const bool inside = (i / 50) % 2 == 1;
    f.y_mm = inside ? static_cast<float>(i % 50) * 0.1f : kNaNf;
    f.r_deg = inside ? 30.0f : kNaNf;
    f.indentation = inside ? static_cast<std::int32_t>(i / 100) : -1;
    data.Append(f);
  }
  return data;
}

template <typename T>
bool SameBits(const std::vector<T>& a, const std::vector<T>& b) {
  return a.size() == b.size() && (a.empty() || std::memcmp(a.data(), b.data(), a.size() * sizeof(T)) == 0);
}

void ExpectEqual(const Dataset& a, const Dataset& b) {
  EXPECT_EQ(a.info.sample_rate_hz, b.info.sample_rate_hz);
  EXPECT_EQ(a.info.source, b.info.source);
  EXPECT_EQ(a.info.patch_name, b.info.patch_name);
  EXPECT_EQ(a.info.surface_radius_mm, b.info.surface_radius_mm);
  EXPECT_EQ(a.info.reference_wavelength_nm, b.info.reference_wavelength_nm);
  EXPECT_EQ(a.info.attributes, b.info.attributes);
  ASSERT_EQ(a.size(), b.size());
  // Bitwise, so NaN positions count too.
  EXPECT_TRUE(SameBits(a.wavelength_nm, b.wavelength_nm));
  EXPECT_TRUE(SameBits(a.t_s, b.t_s));
  EXPECT_TRUE(SameBits(a.serial, b.serial));
  EXPECT_TRUE(SameBits(a.flags, b.flags));
  EXPECT_TRUE(SameBits(a.force_n, b.force_n));
  EXPECT_TRUE(SameBits(a.true_force_n, b.true_force_n));
  EXPECT_TRUE(SameBits(a.y_mm, b.y_mm));
  EXPECT_TRUE(SameBits(a.r_deg, b.r_deg));
  EXPECT_TRUE(SameBits(a.indentation, b.indentation));
}

std::string ReadBytes(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// The message of the InputError that f throws ("" and a test failure if it throws none).
std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  ADD_FAILURE() << "no InputError thrown";
  return {};
}

// ---- Raw HDF5 helpers for inspecting and corrupting files -------------------------------------------

struct H5File {
  explicit H5File(const std::string& path, bool write = false)
      : id(H5Fopen(path.c_str(), write ? H5F_ACC_RDWR : H5F_ACC_RDONLY, H5P_DEFAULT)) {}
  ~H5File() {
    if (id >= 0) H5Fclose(id);
  }
  H5File(const H5File&) = delete;
  H5File& operator=(const H5File&) = delete;
  hid_t id;
};

struct TypeInfo {
  H5T_class_t cls = H5T_NO_CLASS;
  std::size_t size = 0;
  H5T_sign_t sign = H5T_SGN_ERROR;
  H5T_order_t order = H5T_ORDER_ERROR;
  std::vector<hsize_t> dims, max_dims;
  bool chunked = false;
  bool track_times = true;
  int filters = 0;
};

TypeInfo InspectDataset(hid_t file, const char* name) {
  TypeInfo info;
  const hid_t dset = H5Dopen2(file, name, H5P_DEFAULT);
  if (dset < 0) return info;
  const hid_t type = H5Dget_type(dset);
  info.cls = H5Tget_class(type);
  info.size = H5Tget_size(type);
  info.order = H5Tget_order(type);
  if (info.cls == H5T_INTEGER) info.sign = H5Tget_sign(type);
  H5Tclose(type);
  const hid_t space = H5Dget_space(dset);
  const int rank = H5Sget_simple_extent_ndims(space);
  info.dims.resize(static_cast<std::size_t>(rank));
  info.max_dims.resize(static_cast<std::size_t>(rank));
  H5Sget_simple_extent_dims(space, info.dims.data(), info.max_dims.data());
  H5Sclose(space);
  const hid_t dcpl = H5Dget_create_plist(dset);
  info.chunked = H5Pget_layout(dcpl) == H5D_CHUNKED;
  // Object header times are 0 when the object was created without time tracking.
  H5O_info_t oinfo;
  if (H5Oget_info_by_name2(file, name, &oinfo, H5O_INFO_TIME, H5P_DEFAULT) >= 0) {
    info.track_times = oinfo.atime != 0 || oinfo.mtime != 0 || oinfo.ctime != 0 || oinfo.btime != 0;
  }
  info.filters = H5Pget_nfilters(dcpl);
  H5Pclose(dcpl);
  H5Dclose(dset);
  return info;
}

void ReplaceAttrInt(const std::string& path, const char* name, std::int32_t value) {
  H5File f(path, true);
  ASSERT_GE(f.id, 0);
  H5Adelete(f.id, name);
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t attr = H5Acreate2(f.id, name, H5T_STD_I32LE, space, H5P_DEFAULT, H5P_DEFAULT);
  H5Awrite(attr, H5T_NATIVE_INT32, &value);
  H5Aclose(attr);
  H5Sclose(space);
}

void ReplaceAttrString(const std::string& path, const char* name, const char* value) {
  H5File f(path, true);
  ASSERT_GE(f.id, 0);
  H5Adelete(f.id, name);
  const hid_t type = H5Tcopy(H5T_C_S1);
  H5Tset_size(type, std::strlen(value) + 1);  // fixed-length this time: the reader takes both
  const hid_t space = H5Screate(H5S_SCALAR);
  const hid_t attr = H5Acreate2(f.id, name, type, space, H5P_DEFAULT, H5P_DEFAULT);
  H5Awrite(attr, type, value);
  H5Aclose(attr);
  H5Sclose(space);
  H5Tclose(type);
}

void DeleteLink(const std::string& path, const char* name) {
  H5File f(path, true);
  ASSERT_GE(f.id, 0);
  ASSERT_GE(H5Ldelete(f.id, name, H5P_DEFAULT), 0);
}

// Replaces a dataset by a float one of the given shape.
void ReplaceDataset(const std::string& path, const char* name, std::vector<hsize_t> dims) {
  DeleteLink(path, name);
  H5File f(path, true);
  ASSERT_GE(f.id, 0);
  const hid_t space = H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr);
  const hid_t dset = H5Dcreate2(f.id, name, H5T_IEEE_F32LE, space, H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT);
  ASSERT_GE(dset, 0);
  H5Dclose(dset);
  H5Sclose(space);
}

// ---- Dataset file ----------------------------------------------------------------------------------

TEST_F(DatasetTest, RoundTripAcrossSeveralChunks) {
  const Dataset data = MakeData(40000);  // two full 16384-row chunks and a partial one
  const std::string path = Path("a.h5");
  WriteDataset(path, data);
  ExpectEqual(data, ReadDataset(path));
}

TEST_F(DatasetTest, RoundTripSmallAndEmpty) {
  for (std::size_t n : {std::size_t{0}, std::size_t{1}, std::size_t{7}, std::size_t{16384}}) {
    const Dataset data = MakeData(n);
    const std::string path = Path(std::to_string(n) + "_frames.h5");
    WriteDataset(path, data);
    SCOPED_TRACE(n);
    ExpectEqual(data, ReadDataset(path));
  }
}

TEST_F(DatasetTest, StreamingWriterAppendsOneByOneAndInSpans) {
  const Dataset data = MakeData(20000);
  const std::string path = Path("s.h5");
  {
    DatasetWriter writer(path, data.info);
    std::vector<Frame> frames(data.size());
    for (std::size_t i = 0; i < data.size(); ++i) {
      Frame& f = frames[i];
      f.wavelength_nm = data.wavelength_nm[i];
      f.t_s = data.t_s[i];
      f.serial = data.serial[i];
      f.flags = data.flags[i];
      f.force_n = data.force_n[i];
      f.true_force_n = data.true_force_n[i];
      f.y_mm = data.y_mm[i];
      f.r_deg = data.r_deg[i];
      f.indentation = data.indentation[i];
    }
    for (std::size_t i = 0; i < 100; ++i) writer.Append(frames[i]);
    writer.Append(std::span<const Frame>(frames).subspan(100));
    EXPECT_EQ(writer.frames_written(), data.size());
    // No Close(): the destructor flushes.
  }
  ExpectEqual(data, ReadDataset(path));
  // Same bytes as the whole-dataset writer.
  WriteDataset(Path("w.h5"), data);
  EXPECT_EQ(ReadBytes(path), ReadBytes(Path("w.h5")));
}

TEST_F(DatasetTest, LayoutHasTheDocumentedTypes) {
  const Dataset data = MakeData(300);
  const std::string path = Path("layout.h5");
  WriteDataset(path, data);
  H5File f(path);
  ASSERT_GE(f.id, 0);

  const TypeInfo wl = InspectDataset(f.id, "/frames/wavelength_nm");
  EXPECT_EQ(wl.cls, H5T_FLOAT);
  EXPECT_EQ(wl.size, 8u);
  EXPECT_EQ(wl.dims, (std::vector<hsize_t>{300, 16}));
  EXPECT_EQ(wl.max_dims, (std::vector<hsize_t>{H5S_UNLIMITED, 16}));
  EXPECT_TRUE(wl.chunked);
  EXPECT_FALSE(wl.track_times);
  EXPECT_EQ(wl.filters, 0);

  const TypeInfo t = InspectDataset(f.id, "/frames/t_s");
  EXPECT_EQ(t.cls, H5T_FLOAT);
  EXPECT_EQ(t.size, 8u);
  EXPECT_EQ(t.dims, (std::vector<hsize_t>{300}));

  const TypeInfo serial = InspectDataset(f.id, "/frames/serial");
  EXPECT_EQ(serial.cls, H5T_INTEGER);
  EXPECT_EQ(serial.size, 8u);
  EXPECT_EQ(serial.sign, H5T_SGN_NONE);
  EXPECT_EQ(serial.order, H5T_ORDER_LE);

  const TypeInfo flags = InspectDataset(f.id, "/frames/flags");
  EXPECT_EQ(flags.cls, H5T_INTEGER);
  EXPECT_EQ(flags.size, 4u);
  EXPECT_EQ(flags.sign, H5T_SGN_NONE);

  for (const char* name : {"/labels/force_n", "/labels/true_force_n", "/labels/y_mm", "/labels/r_deg"}) {
    SCOPED_TRACE(name);
    const TypeInfo label = InspectDataset(f.id, name);
    EXPECT_EQ(label.cls, H5T_FLOAT);
    EXPECT_EQ(label.size, 4u);
    EXPECT_EQ(label.dims, (std::vector<hsize_t>{300}));
    EXPECT_FALSE(label.track_times);
  }
  const TypeInfo ind = InspectDataset(f.id, "/labels/indentation");
  EXPECT_EQ(ind.cls, H5T_INTEGER);
  EXPECT_EQ(ind.size, 4u);
  EXPECT_EQ(ind.sign, H5T_SGN_2);

  const TypeInfo ref = InspectDataset(f.id, "/patch/reference_wavelength_nm");
  EXPECT_EQ(ref.cls, H5T_FLOAT);
  EXPECT_EQ(ref.size, 8u);
  EXPECT_EQ(ref.dims, (std::vector<hsize_t>{16}));

  // Root attributes: format is a variable-length UTF-8 string (h5py reads it as str), version an int32.
  {
    const hid_t attr = H5Aopen(f.id, "format", H5P_DEFAULT);
    ASSERT_GE(attr, 0);
    const hid_t type = H5Aget_type(attr);
    EXPECT_EQ(H5Tget_class(type), H5T_STRING);
    EXPECT_GT(H5Tis_variable_str(type), 0);
    EXPECT_EQ(H5Tget_cset(type), H5T_CSET_UTF8);
    char* value = nullptr;
    ASSERT_GE(H5Aread(attr, type, &value), 0);
    EXPECT_STREQ(value, "ruffini.dataset");
    H5free_memory(value);
    H5Tclose(type);
    H5Aclose(attr);
  }
  {
    const hid_t attr = H5Aopen(f.id, "version", H5P_DEFAULT);
    ASSERT_GE(attr, 0);
    const hid_t type = H5Aget_type(attr);
    EXPECT_EQ(H5Tget_class(type), H5T_INTEGER);
    EXPECT_EQ(H5Tget_size(type), 4u);
    EXPECT_EQ(H5Tget_sign(type), H5T_SGN_2);
    std::int32_t version = 0;
    ASSERT_GE(H5Aread(attr, H5T_NATIVE_INT32, &version), 0);
    EXPECT_EQ(version, 1);
    H5Tclose(type);
    H5Aclose(attr);
  }
  for (const char* name : {"sample_rate_hz", "source", "alpha", "config"}) {
    EXPECT_GT(H5Aexists(f.id, name), 0) << name;
  }
  const hid_t patch = H5Gopen2(f.id, "patch", H5P_DEFAULT);
  ASSERT_GE(patch, 0);
  EXPECT_GT(H5Aexists(patch, "name"), 0);
  EXPECT_GT(H5Aexists(patch, "surface_radius_mm"), 0);
  H5Gclose(patch);
  for (const char* group : {"/", "/frames", "/labels", "/patch"}) {
    H5O_info_t oinfo;
    ASSERT_GE(H5Oget_info_by_name2(f.id, group, &oinfo, H5O_INFO_TIME, H5P_DEFAULT), 0) << group;
    EXPECT_EQ(oinfo.ctime, 0) << group;
    EXPECT_EQ(oinfo.mtime, 0) << group;
  }
}

TEST_F(DatasetTest, SameInputGivesBitIdenticalFiles) {
  for (int level : {0, 1}) {
    SCOPED_TRACE(level);
    const Dataset data = MakeData(20000);
    const std::string a = Path(std::to_string(level) + "a.h5");
    const std::string b = Path(std::to_string(level) + "b.h5");
    WriteDataset(a, data, level);
    {
      std::vector<std::string> churn(1000, std::string(333, 'x'));  // stir the heap between the writes
    }
    const Dataset copy = MakeData(20000);
    WriteDataset(b, copy, level);
    const std::string bytes_a = ReadBytes(a);
    ASSERT_FALSE(bytes_a.empty());
    EXPECT_TRUE(bytes_a == ReadBytes(b));
  }
}

TEST_F(DatasetTest, CompressionRoundTripsAndShrinks) {
  Dataset data = MakeData(30000);
  // Realistic wavelengths are quantized (interrogator resolution ~0.1 pm), which compresses.
  for (auto& row : data.wavelength_nm) {
    for (double& w : row) {
      if (!std::isnan(w)) w = std::round(w * 1e4) / 1e4;
    }
  }
  const std::string plain = Path("plain.h5");
  const std::string packed = Path("packed.h5");
  WriteDataset(plain, data, 0);
  WriteDataset(packed, data, 6);
  ExpectEqual(data, ReadDataset(packed));
  EXPECT_LT(fs::file_size(packed), fs::file_size(plain));
  H5File f(packed);
  EXPECT_EQ(InspectDataset(f.id, "/frames/wavelength_nm").filters, 2);  // shuffle + deflate
  EXPECT_EQ(InspectDataset(f.id, "/labels/indentation").filters, 2);
}

TEST_F(DatasetTest, OptionalColumnsAreFilledWhenAbsent) {
  const Dataset data = MakeData(10);
  const std::string path = Path("other_tool.h5");
  WriteDataset(path, data);
  DeleteLink(path, "/frames/flags");
  DeleteLink(path, "/labels/true_force_n");
  const Dataset read = ReadDataset(path);
  ASSERT_EQ(read.size(), 10u);
  EXPECT_EQ(read.flags, std::vector<std::uint32_t>(10, 0u));
  ASSERT_EQ(read.true_force_n.size(), 10u);
  for (float v : read.true_force_n) EXPECT_TRUE(std::isnan(v));
  EXPECT_TRUE(SameBits(read.force_n, data.force_n));
}

TEST_F(DatasetTest, ReaderAcceptsFixedLengthStrings) {
  const std::string path = Path("fixed.h5");
  WriteDataset(path, MakeData(5));
  ReplaceAttrString(path, "format", "ruffini.dataset");
  {
    H5File f(path, true);
    const hid_t type = H5Tcopy(H5T_C_S1);
    H5Tset_size(type, 8);
    H5Tset_strpad(type, H5T_STR_SPACEPAD);
    const hid_t space = H5Screate(H5S_SCALAR);
    const hid_t attr = H5Acreate2(f.id, "zeta", type, space, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(attr, type, "last    ");
    H5Aclose(attr);
    H5Sclose(space);
    H5Tclose(type);
  }
  const Dataset read = ReadDataset(path);
  ASSERT_EQ(read.info.attributes.size(), 3u);
  EXPECT_EQ(read.info.attributes.back(), (std::pair<std::string, std::string>{"zeta", "last"}));
}

TEST_F(DatasetTest, RejectsBrokenFiles) {
  const Dataset data = MakeData(50);
  int case_no = 0;
  // Writes a good file, breaks it, and returns ReadDataset's message.
  auto broken = [&](const std::function<void(const std::string&)>& damage) {
    const std::string path = Path(std::to_string(case_no++) + "_broken.h5");
    WriteDataset(path, data);
    damage(path);
    const std::string message = ErrorOf([&] { (void)ReadDataset(path); });
    EXPECT_NE(message.find(path), std::string::npos) << message;
    return message;
  };
  std::string m;

  m = broken([](const std::string& p) { ReplaceAttrString(p, "format", "something.else"); });
  EXPECT_NE(m.find("'format'"), std::string::npos) << m;
  EXPECT_NE(m.find("ruffini.dataset"), std::string::npos) << m;

  m = broken([](const std::string& p) { H5File f(p, true); H5Adelete(f.id, "format"); });
  EXPECT_NE(m.find("missing attribute 'format'"), std::string::npos) << m;

  m = broken([](const std::string& p) { ReplaceAttrInt(p, "version", 2); });
  EXPECT_NE(m.find("version 2"), std::string::npos) << m;
  EXPECT_NE(m.find("expected 1"), std::string::npos) << m;

  m = broken([](const std::string& p) { DeleteLink(p, "/labels/y_mm"); });
  EXPECT_NE(m.find("missing dataset /labels/y_mm"), std::string::npos) << m;

  m = broken([](const std::string& p) { DeleteLink(p, "/frames/wavelength_nm"); });
  EXPECT_NE(m.find("/frames/wavelength_nm"), std::string::npos) << m;

  m = broken([](const std::string& p) { DeleteLink(p, "/labels"); });
  EXPECT_NE(m.find("/labels/force_n"), std::string::npos) << m;

  m = broken([](const std::string& p) { ReplaceDataset(p, "/labels/force_n", {49}); });
  EXPECT_NE(m.find("/labels/force_n has 49 rows, expected 50"), std::string::npos) << m;

  m = broken([](const std::string& p) { ReplaceDataset(p, "/frames/wavelength_nm", {50, 15}); });
  EXPECT_NE(m.find("/frames/wavelength_nm has 15 columns, expected 16"), std::string::npos) << m;

  m = broken([](const std::string& p) { ReplaceDataset(p, "/frames/t_s", {50, 2}); });
  EXPECT_NE(m.find("/frames/t_s has rank 2"), std::string::npos) << m;

  m = broken([](const std::string& p) { ReplaceDataset(p, "/labels/indentation", {50}); });
  EXPECT_NE(m.find("/labels/indentation has the wrong type"), std::string::npos) << m;

  m = broken([](const std::string& p) { ReplaceDataset(p, "/patch/reference_wavelength_nm", {15}); });
  EXPECT_NE(m.find("/patch/reference_wavelength_nm"), std::string::npos) << m;

  m = broken([](const std::string& p) { H5File f(p, true); H5Adelete(f.id, "sample_rate_hz"); });
  EXPECT_NE(m.find("'sample_rate_hz'"), std::string::npos) << m;
}

TEST_F(DatasetTest, RejectsMissingAndNonHdf5Files) {
  const std::string missing = Path("missing.h5");
  EXPECT_NE(ErrorOf([&] { (void)ReadDataset(missing); }).find(missing + ": cannot open HDF5 file"),
            std::string::npos);
  const std::string text = Path("text.h5");
  std::ofstream(text) << "not hdf5\n";
  EXPECT_NE(ErrorOf([&] { (void)ReadDataset(text); }).find(text + ": cannot open HDF5 file"), std::string::npos);
}

TEST_F(DatasetTest, WriterErrorsNameThePath) {
  const std::string bad = Path("no/such/folder/x.h5");
  const std::string m = ErrorOf([&] { DatasetWriter writer(bad, MakeInfo()); });
  EXPECT_EQ(m.rfind(bad + ": cannot create HDF5 file", 0), 0u) << m;

  DatasetInfo info = MakeInfo();
  info.attributes.emplace_back("version", "2");
  EXPECT_NE(ErrorOf([&] { DatasetWriter writer(Path("r.h5"), info); }).find("'version'"), std::string::npos);
  info.attributes = {{"a", "1"}, {"a", "2"}};
  EXPECT_NE(ErrorOf([&] { DatasetWriter writer(Path("d.h5"), info); }).find("'a' is given twice"),
            std::string::npos);
  EXPECT_NE(ErrorOf([&] { DatasetWriter writer(Path("c.h5"), MakeInfo(), 10); }).find("compression level"),
            std::string::npos);

  Dataset ragged = MakeData(10);
  ragged.force_n.pop_back();
  EXPECT_NE(ErrorOf([&] { WriteDataset(Path("ragged.h5"), ragged); }).find("/labels/force_n"), std::string::npos);
}

TEST_F(DatasetTest, CloseIsIdempotentAndWriterTruncates) {
  const std::string path = Path("t.h5");
  WriteDataset(path, MakeData(100));
  DatasetWriter writer(path, MakeInfo());
  Frame f;
  f.t_s = 1.0;
  writer.Append(f);
  writer.Close();
  writer.Close();
  const Dataset read = ReadDataset(path);
  ASSERT_EQ(read.size(), 1u);
  EXPECT_EQ(read.t_s[0], 1.0);
  EXPECT_EQ(read.indentation[0], -1);
}

TEST_F(DatasetTest, ReaderToleratesOtherToolsConventions) {
  const std::string path = Path("matlab.h5");
  WriteDataset(path, MakeData(3));
  {
    H5File f(path, true);
    ASSERT_GE(f.id, 0);
    // MATLAB writes numbers as doubles.
    H5Adelete(f.id, "version");
    const hid_t scalar = H5Screate(H5S_SCALAR);
    const double one = 1.0;
    hid_t attr = H5Acreate2(f.id, "version", H5T_IEEE_F64LE, scalar, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(attr, H5T_NATIVE_DOUBLE, &one);
    H5Aclose(attr);
    // Non-string and multi-valued extra attributes are not ours: skipped.
    const std::int32_t answer = 42;
    attr = H5Acreate2(f.id, "answer", H5T_STD_I32LE, scalar, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(attr, H5T_NATIVE_INT32, &answer);
    H5Aclose(attr);
    const hsize_t two = 2;
    const hid_t pair = H5Screate_simple(1, &two, nullptr);
    const hid_t str = H5Tcopy(H5T_C_S1);
    H5Tset_size(str, H5T_VARIABLE);
    const char* values[2] = {"x", "y"};
    attr = H5Acreate2(f.id, "pair", str, pair, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(attr, str, values);
    H5Aclose(attr);
    H5Tclose(str);
    H5Sclose(pair);
    H5Sclose(scalar);
  }
  const Dataset read = ReadDataset(path);
  EXPECT_EQ(read.info.attributes, MakeInfo().attributes);
  EXPECT_EQ(read.size(), 3u);

  {
    H5File f(path, true);
    H5Adelete(f.id, "version");
    const hid_t scalar = H5Screate(H5S_SCALAR);
    const double v = 2.5;
    const hid_t attr = H5Acreate2(f.id, "version", H5T_IEEE_F64LE, scalar, H5P_DEFAULT, H5P_DEFAULT);
    H5Awrite(attr, H5T_NATIVE_DOUBLE, &v);
    H5Aclose(attr);
    H5Sclose(scalar);
  }
  EXPECT_NE(ErrorOf([&] { (void)ReadDataset(path); }).find("version 2.5"), std::string::npos);
}

TEST_F(DatasetTest, WriterRejectsBadSampleRateAndAppendAfterClose) {
  DatasetInfo info = MakeInfo();
  info.sample_rate_hz = 0.0;
  EXPECT_NE(ErrorOf([&] { DatasetWriter writer(Path("z.h5"), info); }).find("sample_rate_hz"), std::string::npos);
  DatasetWriter writer(Path("ok.h5"), MakeInfo());
  writer.Close();
  EXPECT_THROW(writer.Append(Frame{}), std::logic_error);
}

// ---- CSV import ------------------------------------------------------------------------------------

CsvImportOptions MakeOptions() {
  CsvImportOptions options;
  options.patch_name = "finger-16";
  options.surface_radius_mm = 12.5;
  for (std::size_t k = 0; k < kChannels; ++k) options.reference_wavelength_nm[k] = 1530.0 + static_cast<double>(k);
  return options;
}

// "t, w1..w16[, extra...]" with wavelengths 1530 + k + i/1000.
std::string CsvRow(double t, int i, const std::string& extra = "") {
  std::ostringstream row;
  row << t;
  for (int k = 0; k < 16; ++k) row << "," << 1530 + k << "." << 100 + i;
  if (!extra.empty()) row << "," << extra;
  return row.str();
}

class CsvTest : public DatasetTest {
 protected:
  std::string Write(const std::string& text) {
    const std::string path = Path("rec.csv");
    std::ofstream(path, std::ios::binary) << text;
    return path;
  }
};

TEST_F(CsvTest, Imports17ColumnsWithHeader) {
  std::string text = "t_s,w1,w2,w3,w4,w5,w6,w7,w8,w9,w10,w11,w12,w13,w14,w15,w16\n";
  for (int i = 0; i < 5; ++i) text += CsvRow(0.01 * i, i) + "\n";
  const Dataset data = ImportCsv(Write(text), MakeOptions());
  ASSERT_EQ(data.size(), 5u);
  EXPECT_NEAR(data.info.sample_rate_hz, 100.0, 1e-9);
  EXPECT_EQ(data.info.source, "recording");
  EXPECT_EQ(data.info.patch_name, "finger-16");
  EXPECT_EQ(data.info.surface_radius_mm, 12.5);
  EXPECT_EQ(data.info.reference_wavelength_nm, MakeOptions().reference_wavelength_nm);
  EXPECT_DOUBLE_EQ(data.t_s[3], 0.03);
  EXPECT_DOUBLE_EQ(data.wavelength_nm[2][0], 1530.102);
  EXPECT_DOUBLE_EQ(data.wavelength_nm[4][15], 1545.104);
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_EQ(data.serial[i], i);
    EXPECT_EQ(data.flags[i], 0u);
    EXPECT_TRUE(std::isnan(data.force_n[i]));
    EXPECT_TRUE(std::isnan(data.true_force_n[i]));
    EXPECT_TRUE(std::isnan(data.y_mm[i]));
    EXPECT_TRUE(std::isnan(data.r_deg[i]));
    EXPECT_EQ(data.indentation[i], -1);
  }
}

TEST_F(CsvTest, Imports20ColumnsWithSpacesCrlfEmptyCellsAndTrailingBlankLines) {
  std::string text;
  // Rows 0-1 outside, 2-3 indentation 0, 4 outside, 5-6 indentation 1. Time steps 0.01 except one 0.05.
  const char* labels[] = {"0.5, , ",   "0.6,,",        " 1.5 , 2.0 , 45", "2.5,2.5,45", ",,",
                          "3,1e0,-30", "3.5, 1.5,-30"};
  const double times[] = {0.0, 0.01, 0.02, 0.03, 0.08, 0.09, 0.10};
  for (int i = 0; i < 7; ++i) text.append(" ").append(CsvRow(times[i], i, labels[i])).append(" \r\n");
  text.replace(text.find(",1533.102"), 9, ",  ");  // an empty wavelength cell: peak missing
  text += "\r\n  \n\n";
  const Dataset data = ImportCsv(Write(text), MakeOptions());
  ASSERT_EQ(data.size(), 7u);
  EXPECT_NEAR(data.info.sample_rate_hz, 100.0, 1e-6);  // median step 0.01
  EXPECT_TRUE(std::isnan(data.wavelength_nm[2][3]));
  EXPECT_DOUBLE_EQ(data.wavelength_nm[2][4], 1534.102);
  EXPECT_EQ(data.force_n[0], 0.5f);
  EXPECT_TRUE(std::isnan(data.force_n[4]));
  EXPECT_EQ(data.force_n[2], 1.5f);
  EXPECT_TRUE(std::isnan(data.y_mm[0]));
  EXPECT_EQ(data.y_mm[5], 1.0f);
  EXPECT_EQ(data.r_deg[6], -30.0f);
  EXPECT_EQ(data.indentation, (std::vector<std::int32_t>{-1, -1, 0, 0, -1, 1, 1}));
}

TEST_F(CsvTest, Imports18ColumnsAndRoundTripsThroughHdf5) {
  std::string text;
  for (int i = 0; i < 4; ++i) text += CsvRow(1.0 + 0.004 * i, i, std::to_string(i)) + "\n";
  const Dataset data = ImportCsv(Write(text), MakeOptions());
  ASSERT_EQ(data.size(), 4u);
  EXPECT_NEAR(data.info.sample_rate_hz, 250.0, 1e-6);
  EXPECT_EQ(data.force_n[3], 3.0f);
  const std::string h5 = Path("rec.h5");
  WriteDataset(h5, data);
  ExpectEqual(data, ReadDataset(h5));
}

TEST_F(CsvTest, WrongColumnCountNamesTheLine) {
  const std::string row = CsvRow(0.0, 0);
  std::string text = "time,peaks...\n";
  text.append(row.substr(0, row.find(",1544"))).append("\n");  // 15 columns
  std::string path = Write(text);
  EXPECT_EQ(ErrorOf([&] { (void)ImportCsv(path, MakeOptions()); }),
            path + ":2: expected 17, 18 or 20 columns, found 15");

  text = "";
  for (int i = 0; i < 8; ++i) text += CsvRow(0.01 * i, i, "1,2,3") + "\n";
  text += CsvRow(0.08, 8, "1,2") + "\n";  // line 9: 19 columns
  path = Write(text);
  EXPECT_EQ(ErrorOf([&] { (void)ImportCsv(path, MakeOptions()); }),
            path + ":9: expected 20 columns like line 1, found 19");

  text = "h\n";
  text.append(CsvRow(0.0, 0)).append("\n\n").append(CsvRow(0.01, 1)).append("\n");
  path = Write(text);
  EXPECT_NE(ErrorOf([&] { (void)ImportCsv(path, MakeOptions()); }).find(path + ":3: blank line"), std::string::npos);
}

TEST_F(CsvTest, NonNumericCellNamesLineAndColumn) {
  std::string text = "t,w\n";
  for (int i = 0; i < 10; ++i) text += CsvRow(0.01 * i, i) + "\n";
  std::string bad = CsvRow(0.1, 10);
  bad.replace(bad.find("1533.110"), 8, "x1.2");  // the 5th column
  text += bad + "\n";
  const std::string path = Write(text);
  EXPECT_EQ(ErrorOf([&] { (void)ImportCsv(path, MakeOptions()); }), path + ":12: column 5 ('x1.2') is not a number");

  const std::string path2 = Write(CsvRow(0.0, 0, "2.5") + "\n" + CsvRow(0.01, 1, "1.0.0") + "\n");
  EXPECT_EQ(ErrorOf([&] { (void)ImportCsv(path2, MakeOptions()); }), path2 + ":2: column 18 ('1.0.0') is not a number");
}

TEST_F(CsvTest, TimeMustBeFiniteAndStrictlyIncreasing) {
  std::string text = CsvRow(0.0, 0) + "\n" + CsvRow(0.01, 1) + "\n" + CsvRow(0.01, 2) + "\n";
  std::string path = Write(text);
  std::string m = ErrorOf([&] { (void)ImportCsv(path, MakeOptions()); });
  EXPECT_EQ(m.rfind(path + ":3: time 0.01 s is not after 0.01 s on line 2", 0), 0u) << m;

  path = Write(CsvRow(0.0, 0) + "\n" + CsvRow(0.02, 1) + "\n" + CsvRow(0.01, 2) + "\n");
  m = ErrorOf([&] { (void)ImportCsv(path, MakeOptions()); });
  EXPECT_NE(m.find(":3: time 0.01 s is not after 0.02 s"), std::string::npos) << m;

  std::string row = CsvRow(0.0, 1);
  path = Write(CsvRow(0.0, 0) + "\nnan" + row.substr(row.find(',')) + "\n");
  m = ErrorOf([&] { (void)ImportCsv(path, MakeOptions()); });
  EXPECT_EQ(m, path + ":2: column 1 (time) must be finite, found 'nan'");

  path = Write(CsvRow(0.0, 0) + "\n");
  m = ErrorOf([&] { (void)ImportCsv(path, MakeOptions()); });
  EXPECT_NE(m.find("at least 2 data rows"), std::string::npos) << m;

  m = ErrorOf([&] { (void)ImportCsv(Path("absent.csv"), MakeOptions()); });
  EXPECT_EQ(m, Path("absent.csv") + ": cannot open CSV file");
}

}  // namespace
}  // namespace ruffini::dataset
