// The Ruffini dataset file: writing (streamed, chunked) and reading (validated), through HDF5's C API.
#include "ruffini/dataset/dataset.h"

#include <hdf5.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <limits>
#include <stdexcept>
#include <string_view>
#include <system_error>

#include "ruffini/error.h"

namespace ruffini::dataset {
namespace {

constexpr const char* kFormatName = "ruffini.dataset";
// Rows per chunk: 16384 rows of 16 doubles is 2 MiB, the 1-D columns 64-128 KiB.
constexpr std::size_t kChunkRows = 16384;

static_assert(sizeof(std::array<double, kChannels>) == kChannels * sizeof(double),
              "wavelength rows must be contiguous doubles");

// ---------------------------------------------------------------------------------------------------
// HDF5 plumbing

// Turns HDF5's automatic error printing off for the lifetime of the guard and restores it afterwards,
// so that errors reach callers only as our InputError messages.
class ErrorPrintingOff {
 public:
  ErrorPrintingOff() {
    if (H5Eget_auto2(H5E_DEFAULT, &func_, &data_) < 0) {
      func_ = nullptr;
      data_ = nullptr;
    }
    H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);
  }
  ~ErrorPrintingOff() { H5Eset_auto2(H5E_DEFAULT, func_, data_); }
  ErrorPrintingOff(const ErrorPrintingOff&) = delete;
  ErrorPrintingOff& operator=(const ErrorPrintingOff&) = delete;

 private:
  H5E_auto2_t func_ = nullptr;
  void* data_ = nullptr;
};

// An owned HDF5 identifier, closed with the matching H5*close function.
class Handle {
 public:
  using Closer = herr_t (*)(hid_t);
  Handle() = default;
  Handle(hid_t id, Closer closer) : id_(id), closer_(closer) {}
  ~Handle() { Close(); }
  Handle(Handle&& other) noexcept : id_(other.id_), closer_(other.closer_) { other.id_ = -1; }
  Handle& operator=(Handle&& other) noexcept {
    if (this != &other) {
      Close();
      id_ = other.id_;
      closer_ = other.closer_;
      other.id_ = -1;
    }
    return *this;
  }
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;

  [[nodiscard]] hid_t get() const { return id_; }
  [[nodiscard]] bool valid() const { return id_ >= 0; }
  // Returns HDF5's status (negative on failure); the handle is released either way.
  herr_t Close() {
    herr_t status = 0;
    if (id_ >= 0 && closer_ != nullptr) status = closer_(id_);
    id_ = -1;
    return status;
  }

 private:
  hid_t id_ = -1;
  Closer closer_ = nullptr;
};

// The most specific message on HDF5's error stack (the function that detected the error), or "".
std::string Hdf5Detail() {
  std::string detail;
  auto walk = [](unsigned n, const H5E_error2_t* err, void* client) -> herr_t {
    (void)n;  // walking downward, the last entry is the innermost one
    if (err != nullptr && err->desc != nullptr) *static_cast<std::string*>(client) = err->desc;
    return 0;
  };
  H5Ewalk2(H5E_DEFAULT, H5E_WALK_DOWNWARD, walk, &detail);
  H5Eclear2(H5E_DEFAULT);
  return detail;
}

[[noreturn]] void Fail(const std::string& path, const std::string& what) {
  std::string detail = Hdf5Detail();
  std::string message = path + ": " + what;
  if (!detail.empty()) message += " (HDF5: " + detail + ")";
  throw InputError(message);
}

// For identifiers (hid_t) and status codes (herr_t) alike: negative means failure.
template <typename T>
T Check(T result, const std::string& path, const std::string& what) {
  if (result < 0) Fail(path, what);
  return result;
}

Handle MakePlist(hid_t cls, const std::string& path) {
  return {Check(H5Pcreate(cls), path, "cannot create an HDF5 property list"), H5Pclose};
}

Handle MakeVarStringType(const std::string& path) {
  Handle type(Check(H5Tcopy(H5T_C_S1), path, "cannot create a string type"), H5Tclose);
  Check(H5Tset_size(type.get(), H5T_VARIABLE), path, "cannot create a string type");
  Check(H5Tset_cset(type.get(), H5T_CSET_UTF8), path, "cannot create a string type");
  return type;
}

// Variable-length UTF-8 string attribute (h5py reads it as str).
void WriteStringAttr(hid_t obj, const std::string& obj_name, const std::string& name,
                     const std::string& value, const std::string& path) {
  const std::string what = "cannot write attribute '" + name + "' on " + obj_name;
  Handle type = MakeVarStringType(path);
  Handle space(Check(H5Screate(H5S_SCALAR), path, what), H5Sclose);
  Handle attr(Check(H5Acreate2(obj, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), path,
                    what),
              H5Aclose);
  const char* cstr = value.c_str();
  Check(H5Awrite(attr.get(), type.get(), &cstr), path, what);
  Check(attr.Close(), path, what);
}

void WriteScalarAttr(hid_t obj, const std::string& obj_name, const std::string& name, hid_t file_type,
                     hid_t mem_type, const void* value, const std::string& path) {
  const std::string what = "cannot write attribute '" + name + "' on " + obj_name;
  Handle space(Check(H5Screate(H5S_SCALAR), path, what), H5Sclose);
  Handle attr(
      Check(H5Acreate2(obj, name.c_str(), file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT), path, what),
      H5Aclose);
  Check(H5Awrite(attr.get(), mem_type, value), path, what);
  Check(attr.Close(), path, what);
}

Handle CreateGroup(hid_t parent, const char* name, const std::string& full_name, const std::string& path) {
  Handle gcpl = MakePlist(H5P_GROUP_CREATE, path);
  Check(H5Pset_obj_track_times(gcpl.get(), false), path, "cannot set up group " + full_name);
  return {Check(H5Gcreate2(parent, name, H5P_DEFAULT, gcpl.get(), H5P_DEFAULT), path,
                "cannot create group " + full_name),
          H5Gclose};
}

// ---------------------------------------------------------------------------------------------------
// Columns of the layout

struct ColumnDef {
  const char* group;  // "frames" or "labels"
  const char* name;
  const char* full_name;
  hid_t file_type;  // evaluated lazily: H5T_* macros need the library initialised
  hid_t mem_type;
  std::size_t width;  // 1, or kChannels for the wavelength matrix
  std::size_t elem_size;
};

enum ColumnIndex : std::size_t {
  kColWavelength,
  kColTime,
  kColSerial,
  kColFlags,
  kColForce,
  kColTrueForce,
  kColY,
  kColR,
  kColIndentation,
  kColumnCount
};

std::array<ColumnDef, kColumnCount> Columns() {
  return {{
      {"frames", "wavelength_nm", "/frames/wavelength_nm", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, kChannels, 8},
      {"frames", "t_s", "/frames/t_s", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, 1, 8},
      {"frames", "serial", "/frames/serial", H5T_STD_U64LE, H5T_NATIVE_UINT64, 1, 8},
      {"frames", "flags", "/frames/flags", H5T_STD_U32LE, H5T_NATIVE_UINT32, 1, 4},
      {"labels", "force_n", "/labels/force_n", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, 1, 4},
      {"labels", "true_force_n", "/labels/true_force_n", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, 1, 4},
      {"labels", "y_mm", "/labels/y_mm", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, 1, 4},
      {"labels", "r_deg", "/labels/r_deg", H5T_IEEE_F32LE, H5T_NATIVE_FLOAT, 1, 4},
      {"labels", "indentation", "/labels/indentation", H5T_STD_I32LE, H5T_NATIVE_INT32, 1, 4},
  }};
}

bool IsReservedRootAttr(std::string_view name) {
  return name == "format" || name == "version" || name == "sample_rate_hz" || name == "source";
}

}  // namespace

// -----------------------------------------------------------------------------------------------------
// Dataset

void Dataset::Append(const Frame& f) {
  wavelength_nm.push_back(f.wavelength_nm);
  t_s.push_back(f.t_s);
  serial.push_back(f.serial);
  flags.push_back(f.flags);
  force_n.push_back(f.force_n);
  true_force_n.push_back(f.true_force_n);
  y_mm.push_back(f.y_mm);
  r_deg.push_back(f.r_deg);
  indentation.push_back(f.indentation);
}

// -----------------------------------------------------------------------------------------------------
// DatasetWriter

struct DatasetWriter::Impl {
  std::string path;
  int compression_level = 0;
  std::array<ColumnDef, kColumnCount> columns{};
  Handle file, frames, labels;
  std::array<Handle, kColumnCount> dsets;
  bool datasets_created = false;
  bool closed = false;
  bool failed = false;  // a flush failed: the file is incomplete, nothing more can be written

  // One chunk of buffered rows per column.
  std::vector<double> wavelength, t;
  std::vector<std::uint64_t> serial;
  std::vector<std::uint32_t> flags;
  std::vector<float> force, true_force, y, r;
  std::vector<std::int32_t> indentation;
  std::size_t pending = 0;
  std::uint64_t written = 0;

  Impl(const std::string& p, const DatasetInfo& info, int level);
  void Push(const Frame& f) {
    const std::size_t i = pending;
    std::copy(f.wavelength_nm.begin(), f.wavelength_nm.end(), wavelength.begin() + i * kChannels);
    t[i] = f.t_s;
    serial[i] = f.serial;
    flags[i] = f.flags;
    force[i] = f.force_n;
    true_force[i] = f.true_force_n;
    y[i] = f.y_mm;
    r[i] = f.r_deg;
    indentation[i] = f.indentation;
    if (++pending == kChunkRows) Flush();
  }
  void CheckWritable() const {
    if (closed) throw std::logic_error(path + ": DatasetWriter::Append after Close");
    if (failed) throw InputError(path + ": cannot append: an earlier write to this file failed");
  }
  void ReleaseHandles() {
    for (auto& d : dsets) d.Close();
    frames.Close();
    labels.Close();
    file.Close();
  }
  const void* Buffer(std::size_t c) const {
    switch (c) {
      case kColWavelength: return wavelength.data();
      case kColTime: return t.data();
      case kColSerial: return serial.data();
      case kColFlags: return flags.data();
      case kColForce: return force.data();
      case kColTrueForce: return true_force.data();
      case kColY: return y.data();
      case kColR: return r.data();
      default: return indentation.data();
    }
  }
  void CreateDatasets(std::size_t chunk_rows);
  void Flush();
  void Close();
};

DatasetWriter::Impl::Impl(const std::string& p, const DatasetInfo& info, int level)
    : path(p), compression_level(level), columns(Columns()) {
  if (level < 0 || level > 9) {
    throw InputError(path + ": compression level must be 0 (none) to 9, got " + std::to_string(level));
  }
  if (!std::isfinite(info.sample_rate_hz) || info.sample_rate_hz <= 0.0) {
    throw InputError(path + ": sample_rate_hz must be a positive number, got " + std::to_string(info.sample_rate_hz));
  }
  {
    std::vector<std::string_view> names;
    for (const auto& [name, value] : info.attributes) {
      if (name.empty()) throw InputError(path + ": extra attribute with an empty name");
      if (IsReservedRootAttr(name)) {
        throw InputError(path + ": extra attribute '" + name + "' would overwrite the layout's own attribute");
      }
      names.push_back(name);
    }
    std::sort(names.begin(), names.end());
    if (auto dup = std::adjacent_find(names.begin(), names.end()); dup != names.end()) {
      throw InputError(path + ": extra attribute '" + std::string(*dup) + "' is given twice");
    }
  }

  const std::size_t n = kChunkRows;
  wavelength.resize(n * kChannels);
  t.resize(n);
  serial.resize(n);
  flags.resize(n);
  force.resize(n);
  true_force.resize(n);
  y.resize(n);
  r.resize(n);
  indentation.resize(n);

  Handle fcpl = MakePlist(H5P_FILE_CREATE, path);
  Check(H5Pset_obj_track_times(fcpl.get(), false), path, "cannot set up the file");
  file = Handle(Check(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, fcpl.get(), H5P_DEFAULT), path,
                      "cannot create HDF5 file"),
                H5Fclose);

  const hid_t root = file.get();
  WriteStringAttr(root, "/", "format", kFormatName, path);
  const std::int32_t version = kFormatVersion;
  WriteScalarAttr(root, "/", "version", H5T_STD_I32LE, H5T_NATIVE_INT32, &version, path);
  WriteScalarAttr(root, "/", "sample_rate_hz", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE, &info.sample_rate_hz, path);
  WriteStringAttr(root, "/", "source", info.source, path);
  for (const auto& [name, value] : info.attributes) WriteStringAttr(root, "/", name, value, path);

  Handle patch = CreateGroup(root, "patch", "/patch", path);
  WriteStringAttr(patch.get(), "/patch", "name", info.patch_name, path);
  WriteScalarAttr(patch.get(), "/patch", "surface_radius_mm", H5T_IEEE_F64LE, H5T_NATIVE_DOUBLE,
                  &info.surface_radius_mm, path);
  {
    const std::string what = "cannot write /patch/reference_wavelength_nm";
    const hsize_t dims[1] = {kChannels};
    Handle space(Check(H5Screate_simple(1, dims, nullptr), path, what), H5Sclose);
    Handle dcpl = MakePlist(H5P_DATASET_CREATE, path);
    Check(H5Pset_obj_track_times(dcpl.get(), false), path, what);
    Handle dset(Check(H5Dcreate2(patch.get(), "reference_wavelength_nm", H5T_IEEE_F64LE, space.get(),
                                 H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
                      path, what),
                H5Dclose);
    Check(H5Dwrite(dset.get(), H5T_NATIVE_DOUBLE, H5S_ALL, H5S_ALL, H5P_DEFAULT,
                   info.reference_wavelength_nm.data()),
          path, what);
    Check(dset.Close(), path, what);
  }
  Check(patch.Close(), path, "cannot write group /patch");

  frames = CreateGroup(root, "frames", "/frames", path);
  labels = CreateGroup(root, "labels", "/labels", path);
}

// Datasets are created at the first flush, so a file shorter than one chunk gets a chunk of its own
// length instead of a mostly empty 16384-row one. The chunk size depends only on the input.
void DatasetWriter::Impl::CreateDatasets(std::size_t chunk_rows) {
  for (std::size_t c = 0; c < kColumnCount; ++c) {
    const ColumnDef& col = columns[c];
    const std::string what = std::string("cannot create dataset ") + col.full_name;
    const int rank = col.width == 1 ? 1 : 2;
    const hsize_t dims[2] = {0, col.width};
    const hsize_t max_dims[2] = {H5S_UNLIMITED, col.width};
    const hsize_t chunk[2] = {static_cast<hsize_t>(chunk_rows), col.width};
    Handle space(Check(H5Screate_simple(rank, dims, max_dims), path, what), H5Sclose);
    Handle dcpl = MakePlist(H5P_DATASET_CREATE, path);
    Check(H5Pset_obj_track_times(dcpl.get(), false), path, what);
    Check(H5Pset_chunk(dcpl.get(), rank, chunk), path, what);
    if (compression_level > 0) {
      Check(H5Pset_shuffle(dcpl.get()), path, what);
      Check(H5Pset_deflate(dcpl.get(), static_cast<unsigned>(compression_level)), path, what);
    }
    const hid_t group = std::string_view(col.group) == "frames" ? frames.get() : labels.get();
    dsets[c] = Handle(
        Check(H5Dcreate2(group, col.name, col.file_type, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT),
              path, what),
        H5Dclose);
  }
  datasets_created = true;
}

void DatasetWriter::Impl::Flush() {
  ErrorPrintingOff quiet;
  failed = true;  // until this flush succeeds
  if (!datasets_created) CreateDatasets(std::max<std::size_t>(pending, 1));
  if (pending == 0) {
    failed = false;
    return;
  }
  const hsize_t first = written;
  const hsize_t rows = pending;
  for (std::size_t c = 0; c < kColumnCount; ++c) {
    const ColumnDef& col = columns[c];
    const std::string what = std::string("cannot write ") + col.full_name;
    const int rank = col.width == 1 ? 1 : 2;
    const hsize_t new_dims[2] = {first + rows, col.width};
    const hsize_t start[2] = {first, 0};
    const hsize_t count[2] = {rows, col.width};
    const hid_t dset = dsets[c].get();
    Check(H5Dset_extent(dset, new_dims), path, what);
    Handle file_space(Check(H5Dget_space(dset), path, what), H5Sclose);
    Check(H5Sselect_hyperslab(file_space.get(), H5S_SELECT_SET, start, nullptr, count, nullptr), path, what);
    Handle mem_space(Check(H5Screate_simple(rank, count, nullptr), path, what), H5Sclose);
    Check(H5Dwrite(dset, col.mem_type, mem_space.get(), file_space.get(), H5P_DEFAULT, Buffer(c)), path, what);
  }
  written += pending;
  pending = 0;
  failed = false;
}

void DatasetWriter::Impl::Close() {
  if (closed) return;
  closed = true;  // a failed Close is not retried (by the destructor); the handles are released below
  ErrorPrintingOff quiet;
  try {
    if (failed) throw InputError(path + ": cannot finish the file: an earlier write to it failed");
    Flush();
    for (std::size_t c = 0; c < kColumnCount; ++c) {
      Check(dsets[c].Close(), path, std::string("cannot write ") + columns[c].full_name);
    }
    Check(frames.Close(), path, "cannot write group /frames");
    Check(labels.Close(), path, "cannot write group /labels");
    Check(file.Close(), path, "cannot close HDF5 file");
  } catch (...) {
    ReleaseHandles();
    throw;
  }
}

DatasetWriter::DatasetWriter(const std::string& path, const DatasetInfo& info, int compression_level) {
  ErrorPrintingOff quiet;
  impl_ = std::make_unique<Impl>(path, info, compression_level);
}

DatasetWriter::~DatasetWriter() {
  if (!impl_) return;
  try {
    impl_->Close();
  } catch (...) {  // NOLINT(bugprone-empty-catch): a destructor must not throw; Close() released everything
  }
}

void DatasetWriter::Append(const Frame& frame) {
  impl_->CheckWritable();
  impl_->Push(frame);
}

void DatasetWriter::Append(std::span<const Frame> frames) {
  impl_->CheckWritable();
  for (const Frame& f : frames) impl_->Push(f);
}

void DatasetWriter::Close() { impl_->Close(); }

std::uint64_t DatasetWriter::frames_written() const { return impl_->written + impl_->pending; }

// -----------------------------------------------------------------------------------------------------
// WriteDataset

void WriteDataset(const std::string& path, const Dataset& data, int compression_level) {
  const std::size_t n = data.size();
  auto check_size = [&](std::size_t size, const char* name) {
    if (size != n) {
      throw InputError(path + ": cannot write " + name + ": it has " + std::to_string(size) + " rows, expected " +
                       std::to_string(n) + " like /frames/t_s");
    }
  };
  check_size(data.wavelength_nm.size(), "/frames/wavelength_nm");
  check_size(data.serial.size(), "/frames/serial");
  check_size(data.flags.size(), "/frames/flags");
  check_size(data.force_n.size(), "/labels/force_n");
  check_size(data.true_force_n.size(), "/labels/true_force_n");
  check_size(data.y_mm.size(), "/labels/y_mm");
  check_size(data.r_deg.size(), "/labels/r_deg");
  check_size(data.indentation.size(), "/labels/indentation");

  DatasetWriter writer(path, data.info, compression_level);
  std::vector<Frame> batch(std::min<std::size_t>(n, 4096));
  for (std::size_t begin = 0; begin < n; begin += batch.size()) {
    const std::size_t count = std::min(batch.size(), n - begin);
    for (std::size_t k = 0; k < count; ++k) {
      const std::size_t i = begin + k;
      Frame& f = batch[k];
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
    writer.Append(std::span<const Frame>(batch.data(), count));
  }
  writer.Close();
}

// -----------------------------------------------------------------------------------------------------
// ReadDataset

namespace {

class Reader {
 public:
  explicit Reader(std::string path) : path_(std::move(path)) {}

  void Open() {
    std::error_code ec;
    if (!std::filesystem::exists(path_, ec)) throw InputError(path_ + ": cannot open HDF5 file: no such file");
    const hid_t file = H5Fopen(path_.c_str(), H5F_ACC_RDONLY, H5P_DEFAULT);
    if (file < 0) {
      const htri_t is_hdf5 = H5Fis_hdf5(path_.c_str());
      H5Eclear2(H5E_DEFAULT);
      throw InputError(path_ + ": cannot open HDF5 file" + (is_hdf5 == 0 ? ": not an HDF5 file" : ""));
    }
    file_ = Handle(file, H5Fclose);
  }

  [[nodiscard]] hid_t file() const { return file_.get(); }
  [[nodiscard]] const std::string& path() const { return path_; }

  [[noreturn]] void Error(const std::string& what) const {
    H5Eclear2(H5E_DEFAULT);
    throw InputError(path_ + ": " + what);
  }

  bool HasAttr(hid_t obj, const std::string& name) const {
    const htri_t exists = H5Aexists(obj, name.c_str());
    if (exists < 0) Error("cannot look up attribute '" + name + "'");
    return exists > 0;
  }

  Handle OpenAttr(hid_t obj, const std::string& obj_name, const std::string& name, const char* expected) const {
    if (!HasAttr(obj, name)) {
      Error("missing attribute '" + name + "' on " + obj_name + " (expected " + expected + ")");
    }
    Handle attr(H5Aopen(obj, name.c_str(), H5P_DEFAULT), H5Aclose);
    if (!attr.valid()) Error("cannot open attribute '" + name + "' on " + obj_name);
    Handle space(H5Aget_space(attr.get()), H5Sclose);
    if (!space.valid() || H5Sget_simple_extent_npoints(space.get()) != 1) {
      Error("attribute '" + name + "' on " + obj_name + " must hold a single value (expected " + expected + ")");
    }
    return attr;
  }

  H5T_class_t AttrClass(hid_t attr) const {
    Handle type(H5Aget_type(attr), H5Tclose);
    return type.valid() ? H5Tget_class(type.get()) : H5T_NO_CLASS;
  }

  std::string ReadStringAttr(hid_t obj, const std::string& obj_name, const std::string& name) const {
    Handle attr = OpenAttr(obj, obj_name, name, "a string");
    std::string value;
    if (!ReadString(attr.get(), value)) {
      Error("attribute '" + name + "' on " + obj_name + " must be a string");
    }
    return value;
  }

  // Reads a scalar string attribute (variable- or fixed-length); false if it is not a string.
  bool ReadString(hid_t attr, std::string& value) const {
    Handle space(H5Aget_space(attr), H5Sclose);
    if (!space.valid() || H5Sget_simple_extent_npoints(space.get()) != 1) return false;
    Handle type(H5Aget_type(attr), H5Tclose);
    if (!type.valid() || H5Tget_class(type.get()) != H5T_STRING) return false;
    const htri_t is_var = H5Tis_variable_str(type.get());
    if (is_var < 0) return false;
    if (is_var > 0) {
      Handle mem(H5Tcopy(H5T_C_S1), H5Tclose);
      if (!mem.valid() || H5Tset_size(mem.get(), H5T_VARIABLE) < 0 ||
          H5Tset_cset(mem.get(), H5Tget_cset(type.get())) < 0) {
        return false;
      }
      char* str = nullptr;
      if (H5Aread(attr, mem.get(), &str) < 0) return false;
      value = str != nullptr ? std::string(str) : std::string();
      if (str != nullptr) H5free_memory(str);
    } else {
      const std::size_t size = H5Tget_size(type.get());
      if (size == 0) return false;
      std::string buffer(size, '\0');
      if (H5Aread(attr, type.get(), buffer.data()) < 0) return false;
      value = buffer.substr(0, buffer.find('\0'));
      if (H5Tget_strpad(type.get()) == H5T_STR_SPACEPAD) {
        value.erase(value.find_last_not_of(' ') + 1);
      }
    }
    return true;
  }

  double ReadNumberAttr(hid_t obj, const std::string& obj_name, const std::string& name,
                        const char* expected) const {
    Handle attr = OpenAttr(obj, obj_name, name, expected);
    const H5T_class_t cls = AttrClass(attr.get());
    if (cls != H5T_INTEGER && cls != H5T_FLOAT) {
      Error("attribute '" + name + "' on " + obj_name + " must be a number (expected " + expected + ")");
    }
    double value = 0.0;
    if (H5Aread(attr.get(), H5T_NATIVE_DOUBLE, &value) < 0) Error("cannot read attribute '" + name + "' on " + obj_name);
    return value;
  }

  bool HasLink(const char* name) const {
    // Checks each path component, as H5Lexists requires the parents to exist.
    std::string partial;
    std::string_view rest(name);
    while (!rest.empty()) {
      if (rest.front() == '/') rest.remove_prefix(1);
      const std::size_t slash = rest.find('/');
      partial += "/";
      partial += rest.substr(0, slash);
      const htri_t exists = H5Lexists(file_.get(), partial.c_str(), H5P_DEFAULT);
      if (exists <= 0) {
        H5Eclear2(H5E_DEFAULT);
        return false;
      }
      if (slash == std::string_view::npos) break;
      rest.remove_prefix(slash);
    }
    return true;
  }

  // Opens a dataset and checks its type class and shape: [rows] or [rows, width] (rows = -1: any).
  Handle OpenDataset(const char* name, H5T_class_t cls, std::size_t width, std::int64_t rows,
                     std::size_t* rows_found) const {
    const char* type_name = cls == H5T_FLOAT ? "floating-point" : "integer";
    const std::string shape = width == 1 ? "[N]" : "[N," + std::to_string(width) + "]";
    if (!HasLink(name)) Error(std::string("missing dataset ") + name + " (expected " + type_name + " " + shape + ")");
    Handle dset(H5Dopen2(file_.get(), name, H5P_DEFAULT), H5Dclose);
    if (!dset.valid()) Error(std::string("cannot open dataset ") + name);
    Handle type(H5Dget_type(dset.get()), H5Tclose);
    if (!type.valid() || H5Tget_class(type.get()) != cls) {
      Error(std::string("dataset ") + name + " has the wrong type (expected " + type_name + ")");
    }
    Handle space(H5Dget_space(dset.get()), H5Sclose);
    const int rank = space.valid() ? H5Sget_simple_extent_ndims(space.get()) : -1;
    const int expected_rank = width == 1 ? 1 : 2;
    if (rank != expected_rank) {
      Error(std::string("dataset ") + name + " has rank " + std::to_string(rank) + ", expected " +
            std::to_string(expected_rank) + " (shape " + shape + ")");
    }
    hsize_t dims[2] = {0, 0};
    H5Sget_simple_extent_dims(space.get(), dims, nullptr);
    if (expected_rank == 2 && dims[1] != width) {
      Error(std::string("dataset ") + name + " has " + std::to_string(dims[1]) + " columns, expected " +
            std::to_string(width));
    }
    if (rows >= 0 && dims[0] != static_cast<hsize_t>(rows)) {
      Error(std::string("dataset ") + name + " has " + std::to_string(dims[0]) + " rows, expected " +
            std::to_string(rows) + " like /frames/t_s");
    }
    if (rows_found != nullptr) *rows_found = static_cast<std::size_t>(dims[0]);
    return dset;
  }

  void ReadAll(const Handle& dset, const char* name, hid_t mem_type, void* out) const {
    if (H5Dread(dset.get(), mem_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, out) < 0) {
      const std::string detail = Hdf5Detail();
      throw InputError(path_ + ": cannot read dataset " + name + (detail.empty() ? "" : " (HDF5: " + detail + ")"));
    }
  }

  template <typename T>
  void ReadColumn(const char* name, H5T_class_t cls, hid_t mem_type, std::size_t n, std::vector<T>& out) const {
    Handle dset = OpenDataset(name, cls, 1, static_cast<std::int64_t>(n), nullptr);
    out.resize(n);
    if (n > 0) ReadAll(dset, name, mem_type, out.data());
  }

 private:
  std::string path_;
  Handle file_;
};

}  // namespace

Dataset ReadDataset(const std::string& path) {
  ErrorPrintingOff quiet;
  Reader reader(path);
  reader.Open();
  const hid_t root = reader.file();
  Dataset data;
  DatasetInfo& info = data.info;

  const std::string format = reader.ReadStringAttr(root, "/", "format");
  if (format != kFormatName) {
    reader.Error("attribute 'format' is \"" + format + "\", expected \"" + kFormatName +
                 "\"; not a Ruffini dataset");
  }
  // Read as a double, so a version written as a float by another tool (MATLAB's default) still works.
  const double version = reader.ReadNumberAttr(root, "/", "version", "an int32");
  if (version != static_cast<double>(kFormatVersion)) {
    char found[64];
    const auto formatted = std::to_chars(found, found + sizeof(found), version);
    *formatted.ptr = '\0';
    reader.Error("unsupported dataset version " + std::string(found) + " (attribute 'version'), expected " +
                 std::to_string(kFormatVersion));
  }
  info.sample_rate_hz = reader.ReadNumberAttr(root, "/", "sample_rate_hz", "an f64");
  if (!std::isfinite(info.sample_rate_hz) || info.sample_rate_hz <= 0.0) {
    reader.Error("attribute 'sample_rate_hz' must be a positive number, found " +
                 std::to_string(info.sample_rate_hz));
  }
  info.source = reader.ReadStringAttr(root, "/", "source");

  // Extra root string attributes, sorted by name.
  {
    std::vector<std::string> names;
    auto collect = [](hid_t, const char* name, const H5A_info_t*, void* client) -> herr_t {
      static_cast<std::vector<std::string>*>(client)->emplace_back(name);
      return 0;
    };
    if (H5Aiterate2(root, H5_INDEX_NAME, H5_ITER_INC, nullptr, collect, &names) < 0) {
      reader.Error("cannot list the root attributes");
    }
    std::sort(names.begin(), names.end());
    for (const std::string& name : names) {
      if (IsReservedRootAttr(name)) continue;
      Handle attr(H5Aopen(root, name.c_str(), H5P_DEFAULT), H5Aclose);
      std::string value;
      if (attr.valid() && reader.ReadString(attr.get(), value)) info.attributes.emplace_back(name, value);
      H5Eclear2(H5E_DEFAULT);  // non-string attributes are not ours: skip them
    }
  }

  // /patch
  if (!reader.HasLink("/patch")) reader.Error("missing group /patch");
  {
    Handle patch(H5Gopen2(root, "patch", H5P_DEFAULT), H5Gclose);
    if (!patch.valid()) reader.Error("cannot open group /patch");
    info.patch_name = reader.ReadStringAttr(patch.get(), "/patch", "name");
    info.surface_radius_mm =
        reader.ReadNumberAttr(patch.get(), "/patch", "surface_radius_mm", "an f64");
  }
  {
    const char* name = "/patch/reference_wavelength_nm";
    std::size_t rows = 0;
    Handle dset = reader.OpenDataset(name, H5T_FLOAT, 1, -1, &rows);
    if (rows != kChannels) {
      reader.Error(std::string("dataset ") + name + " has " + std::to_string(rows) + " values, expected " +
                   std::to_string(kChannels));
    }
    reader.ReadAll(dset, name, H5T_NATIVE_DOUBLE, info.reference_wavelength_nm.data());
  }

  // Frames: N comes from /frames/t_s.
  std::size_t n = 0;
  {
    const char* name = "/frames/t_s";
    Handle dset = reader.OpenDataset(name, H5T_FLOAT, 1, -1, &n);
    data.t_s.resize(n);
    if (n > 0) reader.ReadAll(dset, name, H5T_NATIVE_DOUBLE, data.t_s.data());
  }
  {
    const char* name = "/frames/wavelength_nm";
    Handle dset = reader.OpenDataset(name, H5T_FLOAT, kChannels, static_cast<std::int64_t>(n), nullptr);
    data.wavelength_nm.resize(n);
    if (n > 0) reader.ReadAll(dset, name, H5T_NATIVE_DOUBLE, data.wavelength_nm.data()->data());
  }
  reader.ReadColumn("/frames/serial", H5T_INTEGER, H5T_NATIVE_UINT64, n, data.serial);
  if (reader.HasLink("/frames/flags")) {
    reader.ReadColumn("/frames/flags", H5T_INTEGER, H5T_NATIVE_UINT32, n, data.flags);
  } else {
    data.flags.assign(n, 0u);
  }
  reader.ReadColumn("/labels/force_n", H5T_FLOAT, H5T_NATIVE_FLOAT, n, data.force_n);
  if (reader.HasLink("/labels/true_force_n")) {
    reader.ReadColumn("/labels/true_force_n", H5T_FLOAT, H5T_NATIVE_FLOAT, n, data.true_force_n);
  } else {
    data.true_force_n.assign(n, std::numeric_limits<float>::quiet_NaN());
  }
  reader.ReadColumn("/labels/y_mm", H5T_FLOAT, H5T_NATIVE_FLOAT, n, data.y_mm);
  reader.ReadColumn("/labels/r_deg", H5T_FLOAT, H5T_NATIVE_FLOAT, n, data.r_deg);
  reader.ReadColumn("/labels/indentation", H5T_INTEGER, H5T_NATIVE_INT32, n, data.indentation);
  return data;
}

}  // namespace ruffini::dataset

namespace ruffini::dataset {

void WriteColumns(const std::string& path, const std::string& group, std::span<const Column> columns,
                  const std::vector<std::pair<std::string, std::string>>& attributes) {
  ErrorPrintingOff quiet;
  std::size_t rows = columns.empty() ? 0 : columns.front().rows;
  for (const Column& c : columns) {
    if (c.rows != rows) {
      throw InputError(path + ": column '" + c.name + "' has " + std::to_string(c.rows) + " rows, expected " + std::to_string(rows));
    }
    if (c.cols < 1) throw InputError(path + ": column '" + c.name + "' has no columns");
  }
  Handle fcpl = MakePlist(H5P_FILE_CREATE, path);
  Check(H5Pset_obj_track_times(fcpl.get(), false), path, "cannot set up the file");
  Handle file(Check(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, fcpl.get(), H5P_DEFAULT), path, "cannot create the file"),
              H5Fclose);
  for (const auto& [k, v] : attributes) WriteStringAttr(file.get(), "/", k, v, path);
  const std::string gname = "/" + group;
  Handle g = CreateGroup(file.get(), group.c_str(), gname, path);
  for (const Column& c : columns) {
    const std::string what = "cannot write " + gname + "/" + c.name;
    hid_t type = H5T_NATIVE_FLOAT;
    switch (c.type) {
      case Column::Type::kF32: type = H5T_NATIVE_FLOAT; break;
      case Column::Type::kU8: type = H5T_NATIVE_UINT8; break;
      case Column::Type::kI32: type = H5T_NATIVE_INT32; break;
    }
    const hsize_t dims[2] = {static_cast<hsize_t>(c.rows), static_cast<hsize_t>(c.cols)};
    Handle space(Check(H5Screate_simple(c.cols == 1 ? 1 : 2, dims, nullptr), path, what), H5Sclose);
    Handle dcpl = MakePlist(H5P_DATASET_CREATE, path);
    Check(H5Pset_obj_track_times(dcpl.get(), false), path, what);
    Handle ds(Check(H5Dcreate2(g.get(), c.name.c_str(), type, space.get(), H5P_DEFAULT, dcpl.get(), H5P_DEFAULT), path, what),
              H5Dclose);
    if (rows > 0) Check(H5Dwrite(ds.get(), type, H5S_ALL, H5S_ALL, H5P_DEFAULT, c.data), path, what);
    Check(ds.Close(), path, what);
  }
  Check(g.Close(), path, "cannot close " + gname);
  Check(file.Close(), path, "cannot close the file");
}

}  // namespace ruffini::dataset
