#include "core/hdf5_store.h"

#include <fcntl.h>
#include <hdf5.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <stdexcept>
#include <utility>

#include "core/error.h"
#include "core/version.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

// The C API is used with return-code checks: it keeps every failure in one place (Check) where
// it becomes an error that names the file, instead of HDF5 exceptions escaping to the user.

// Owns an HDF5 identifier; each identifier kind has its own close function.
class Id {
 public:
  Id() = default;
  Id(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  Id(Id&& o) noexcept : id_(std::exchange(o.id_, H5I_INVALID_HID)), close_(o.close_) {}
  Id& operator=(Id&& o) noexcept {
    if (this != &o) {
      Reset();
      id_ = std::exchange(o.id_, H5I_INVALID_HID);
      close_ = o.close_;
    }
    return *this;
  }
  ~Id() { Reset(); }
  hid_t get() const { return id_; }
  herr_t Reset() {
    const herr_t status = id_ >= 0 ? close_(id_) : 0;
    id_ = H5I_INVALID_HID;
    return status;
  }

 private:
  hid_t id_ = H5I_INVALID_HID;
  herr_t (*close_)(hid_t) = nullptr;
};

// Where errors go: a reader's failures are the user's input problems (InputError naming the
// file); a writer's are environment failures (disk full, permissions) and name the final path.
struct Context {
  std::string path;
  bool reading = true;

  [[noreturn]] void Fail(const std::string& message) const {
    if (reading) ThrowInput(path, 0, message);
    throw std::runtime_error(path + ": " + message);
  }
  template <typename H>
  H Check(H status, const std::string& what) const {
    if (status < 0) Fail((reading ? "cannot read " : "cannot write ") + what);
    return status;
  }
};

void SilenceHdf5Errors() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }

// Treat a filesystem that refuses locks (NFS, read-only mounts) as unlocked rather than failing
// to open; raytime files are never modified in place, so locking protects nothing here.
Id FileAccessList() {
  Id fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
#if H5_VERSION_GE(1, 10, 7)
  if (fapl.get() >= 0) H5Pset_file_locking(fapl.get(), true, true);
#endif
  return fapl;
}

std::string NowUtc() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

// Group and dataset names become HDF5 link names, where "/" would silently create nesting.
void CheckLinkName(const std::string& kind, const std::string& name) {
  if (name.empty() || name == "." || name.find('/') != std::string::npos) {
    throw std::invalid_argument("invalid " + kind + " name '" + name +
                                "' (must be non-empty, without '/')");
  }
}

template <typename T>
struct Hdf5Type;
template <>
struct Hdf5Type<float> {
  static hid_t File() { return H5T_IEEE_F32LE; }
  static hid_t Memory() { return H5T_NATIVE_FLOAT; }
  static constexpr H5T_class_t kClass = H5T_FLOAT;
};
template <>
struct Hdf5Type<double> {
  static hid_t File() { return H5T_IEEE_F64LE; }
  static hid_t Memory() { return H5T_NATIVE_DOUBLE; }
  static constexpr H5T_class_t kClass = H5T_FLOAT;
};
template <>
struct Hdf5Type<int32_t> {
  static hid_t File() { return H5T_STD_I32LE; }
  static hid_t Memory() { return H5T_NATIVE_INT32; }
  static constexpr H5T_class_t kClass = H5T_INTEGER;
};
template <>
struct Hdf5Type<uint32_t> {
  static hid_t File() { return H5T_STD_U32LE; }
  static hid_t Memory() { return H5T_NATIVE_UINT32; }
  static constexpr H5T_class_t kClass = H5T_INTEGER;
};
template <>
struct Hdf5Type<uint8_t> {
  static hid_t File() { return H5T_STD_U8LE; }
  static hid_t Memory() { return H5T_NATIVE_UINT8; }
  static constexpr H5T_class_t kClass = H5T_INTEGER;
};

Id VlenStringType() {
  Id type(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(type.get(), H5T_VARIABLE);
  H5Tset_cset(type.get(), H5T_CSET_UTF8);
  return type;
}

std::string ObjectName(hid_t loc) {
  const ssize_t n = H5Iget_name(loc, nullptr, 0);
  if (n <= 0) return "?";
  std::string name(static_cast<size_t>(n) + 1, '\0');
  H5Iget_name(loc, name.data(), name.size());
  name.resize(static_cast<size_t>(n));
  return name;
}

std::string Join(const std::string& parent, const std::string& child) {
  return parent == "/" ? "/" + child : parent + "/" + child;
}

bool HasLink(hid_t loc, const std::string& name) { return H5Lexists(loc, name.c_str(), 0) > 0; }

Id OpenGroup(const Context& c, hid_t loc, const std::string& name) {
  return Id(
      c.Check(H5Gopen2(loc, name.c_str(), H5P_DEFAULT), "group " + Join(ObjectName(loc), name)),
      H5Gclose);
}

Id CreateGroup(const Context& c, hid_t loc, const std::string& name) {
  const std::string full = Join(ObjectName(loc), name);
  if (HasLink(loc, name)) c.Fail(full + " was already written to this file");
  return Id(c.Check(H5Gcreate2(loc, name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT),
                    "group " + full),
            H5Gclose);
}

// Link names of a group's children in name order.
std::vector<std::string> ChildNames(const Context& c, hid_t group) {
  H5G_info_t info;
  c.Check(H5Gget_info(group, &info), "group " + ObjectName(group));
  std::vector<std::string> names;
  for (hsize_t i = 0; i < info.nlinks; ++i) {
    const ssize_t n = c.Check(
        H5Lget_name_by_idx(group, ".", H5_INDEX_NAME, H5_ITER_INC, i, nullptr, 0, H5P_DEFAULT),
        "link names of " + ObjectName(group));
    std::string name(static_cast<size_t>(n) + 1, '\0');
    H5Lget_name_by_idx(group, ".", H5_INDEX_NAME, H5_ITER_INC, i, name.data(), name.size(),
                       H5P_DEFAULT);
    name.resize(static_cast<size_t>(n));
    names.push_back(std::move(name));
  }
  return names;
}

// --- Writing -------------------------------------------------------------------------------------

// Zero-length dimensions are legal in a fixed-size dataspace; only the write itself is skipped
// because there is nothing to transfer (and Eigen's buffer of an empty matrix may be null).
void WriteRaw(const Context& c, hid_t loc, const std::string& name, hid_t file_type,
              hid_t memory_type, const void* data, const std::vector<hsize_t>& dims) {
  const std::string full = Join(ObjectName(loc), name);
  Id space(c.Check(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr), full),
           H5Sclose);
  Id set(c.Check(H5Dcreate2(loc, name.c_str(), file_type, space.get(), H5P_DEFAULT, H5P_DEFAULT,
                            H5P_DEFAULT),
                 full),
         H5Dclose);
  hsize_t count = 1;
  for (hsize_t d : dims) count *= d;
  if (count > 0) {
    c.Check(H5Dwrite(set.get(), memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, data), full);
  }
}

template <typename T>
void WriteArray(const Context& c, hid_t loc, const std::string& name, const T* data,
                const std::vector<hsize_t>& dims) {
  WriteRaw(c, loc, name, Hdf5Type<T>::File(), Hdf5Type<T>::Memory(), data, dims);
}

template <typename T>
void WriteArray(const Context& c, hid_t loc, const std::string& name, const std::vector<T>& v) {
  WriteArray(c, loc, name, v.data(), {v.size()});
}

// Eigen matrices here are row-major, so rows x cols maps directly onto the C-order dataset.
template <typename M>
void WriteMatrix(const Context& c, hid_t loc, const std::string& name, const M& m) {
  static_assert(M::IsRowMajor || M::ColsAtCompileTime == 1, "datasets are stored in C order");
  WriteArray(c, loc, name, m.data(),
             {static_cast<hsize_t>(m.rows()), static_cast<hsize_t>(m.cols())});
}

void WriteStrings(const Context& c, hid_t loc, const std::string& name,
                  const std::vector<std::string>& values) {
  std::vector<const char*> pointers;
  for (const std::string& v : values) pointers.push_back(v.c_str());
  const Id type = VlenStringType();
  WriteRaw(c, loc, name, type.get(), type.get(), pointers.data(), {values.size()});
}

void WriteStringScalar(const Context& c, hid_t loc, const std::string& name,
                       const std::string& value) {
  const std::string full = Join(ObjectName(loc), name);
  const Id type = VlenStringType();
  Id space(c.Check(H5Screate(H5S_SCALAR), full), H5Sclose);
  Id set(c.Check(H5Dcreate2(loc, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT,
                            H5P_DEFAULT),
                 full),
         H5Dclose);
  const char* pointer = value.c_str();
  c.Check(H5Dwrite(set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, &pointer), full);
}

void WriteAttribute(const Context& c, hid_t loc, const std::string& name, hid_t type,
                    const void* value) {
  const std::string what = "attribute " + name + " of " + ObjectName(loc);
  Id space(c.Check(H5Screate(H5S_SCALAR), what), H5Sclose);
  Id attr(c.Check(H5Acreate2(loc, name.c_str(), type, space.get(), H5P_DEFAULT, H5P_DEFAULT), what),
          H5Aclose);
  c.Check(H5Awrite(attr.get(), type, value), what);
}

void WriteStringAttribute(const Context& c, hid_t loc, const std::string& name,
                          const std::string& value) {
  const char* pointer = value.c_str();
  WriteAttribute(c, loc, name, VlenStringType().get(), &pointer);
}

void WriteIntAttribute(const Context& c, hid_t loc, const std::string& name, int value) {
  const int32_t v = value;
  WriteAttribute(c, loc, name, H5T_STD_I32LE, &v);
}

void WriteProvenance(const Context& c, hid_t loc, const Provenance& p) {
  WriteStringAttribute(c, loc, "stage", p.stage);
  WriteStringAttribute(c, loc, "options", p.options.dump());
  WriteStringAttribute(c, loc, "created_utc", p.created_utc.empty() ? NowUtc() : p.created_utc);
  WriteStringAttribute(c, loc, "raytime_version",
                       p.raytime_version.empty() ? Version() : p.raytime_version);
}

// --- Reading -------------------------------------------------------------------------------------

template <typename T>
struct Array {
  std::vector<T> data;
  std::vector<hsize_t> dims;
};

// `shape` gives the expected extent per dimension, -1 for any.
void CheckShape(const Context& c, const std::string& what, const std::vector<hsize_t>& dims,
                const std::vector<int64_t>& shape) {
  bool ok = dims.size() == shape.size();
  for (size_t i = 0; ok && i < dims.size(); ++i) {
    ok = shape[i] < 0 || dims[i] == static_cast<hsize_t>(shape[i]);
  }
  if (ok) return;
  auto format = [](auto begin, auto end) {
    std::string s = "(";
    for (auto it = begin; it != end; ++it) {
      if (it != begin) s += ", ";
      s += *it < 0 ? std::string("any") : std::to_string(*it);
    }
    return s + ")";
  };
  c.Fail(what + " has shape " + format(dims.begin(), dims.end()) + ", expected " +
         format(shape.begin(), shape.end()));
}

std::vector<hsize_t> Dims(const Context& c, hid_t set, const std::string& what) {
  Id space(c.Check(H5Dget_space(set), what), H5Sclose);
  const int rank = c.Check(H5Sget_simple_extent_ndims(space.get()), what);
  std::vector<hsize_t> dims(static_cast<size_t>(rank));
  c.Check(H5Sget_simple_extent_dims(space.get(), dims.data(), nullptr), what);
  return dims;
}

// The number of elements of a dataset, checked before anything is allocated for them. Every
// raytime writer writes all of a dataset's elements, so data that was never written (storage not
// or only partly allocated: fill values) means a foreign or damaged file; left unchecked, a small
// file could declare an extent far beyond memory.
size_t ElementCount(const Context& c, hid_t set, const std::string& what,
                    const std::vector<hsize_t>& dims) {
  hsize_t count = 1;
  for (hsize_t d : dims) {
    if (d != 0 && count > std::numeric_limits<size_t>::max() / d) c.Fail(what + " is too large");
    count *= d;
  }
  if (count == 0) return 0;
  H5D_space_status_t status;
  c.Check(H5Dget_space_status(set, &status), what);
  if (status != H5D_SPACE_STATUS_ALLOCATED) {
    c.Fail(what + " has " + std::to_string(count) +
           " elements but its data was never written (truncated or corrupt?)");
  }
  return static_cast<size_t>(count);
}

template <typename T>
Array<T> ReadArray(const Context& c, hid_t loc, const std::string& name,
                   const std::vector<int64_t>& shape) {
  const std::string what = Join(ObjectName(loc), name);
  if (!HasLink(loc, name)) c.Fail("missing dataset " + what);
  Id set(c.Check(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), what), H5Dclose);
  Id type(c.Check(H5Dget_type(set.get()), what), H5Tclose);
  if (H5Tget_class(type.get()) != Hdf5Type<T>::kClass) {
    c.Fail(what + " has the wrong element type (expected " +
           (Hdf5Type<T>::kClass == H5T_FLOAT ? "floating point" : "integer") + ")");
  }
  Array<T> out;
  out.dims = Dims(c, set.get(), what);
  CheckShape(c, what, out.dims, shape);
  const size_t count = ElementCount(c, set.get(), what, out.dims);
  out.data.resize(count);
  if (count > 0) {
    c.Check(
        H5Dread(set.get(), Hdf5Type<T>::Memory(), H5S_ALL, H5S_ALL, H5P_DEFAULT, out.data.data()),
        what);
  }
  return out;
}

template <typename M>
M ReadMatrix(const Context& c, hid_t loc, const std::string& name, int64_t rows, int64_t cols) {
  static_assert(M::IsRowMajor, "datasets are stored in C order");
  auto a = ReadArray<typename M::Scalar>(c, loc, name, {rows, cols});
  M m(static_cast<Eigen::Index>(a.dims[0]), static_cast<Eigen::Index>(a.dims[1]));
  std::copy(a.data.begin(), a.data.end(), m.data());
  return m;
}

std::vector<std::string> ReadStrings(const Context& c, hid_t loc, const std::string& name,
                                     int64_t size) {
  const std::string what = Join(ObjectName(loc), name);
  if (!HasLink(loc, name)) c.Fail("missing dataset " + what);
  Id set(c.Check(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), what), H5Dclose);
  Id file_type(c.Check(H5Dget_type(set.get()), what), H5Tclose);
  if (H5Tis_variable_str(file_type.get()) <= 0) {
    c.Fail(what + " is not a variable-length string dataset");
  }
  const std::vector<hsize_t> dims = Dims(c, set.get(), what);
  CheckShape(c, what, dims, {size});
  std::vector<char*> pointers(ElementCount(c, set.get(), what, dims), nullptr);
  std::vector<std::string> out;
  if (pointers.empty()) return out;
  const Id type = VlenStringType();
  c.Check(H5Dread(set.get(), type.get(), H5S_ALL, H5S_ALL, H5P_DEFAULT, pointers.data()), what);
  for (const char* p : pointers) out.emplace_back(p ? p : "");
  Id space(H5Dget_space(set.get()), H5Sclose);
  // H5Treclaim replaces H5Dvlen_reclaim in 1.12; Debian's 1.10 declares it but does not export it.
#if H5_VERSION_GE(1, 12, 0)
  H5Treclaim(type.get(), space.get(), H5P_DEFAULT, pointers.data());
#else
  H5Dvlen_reclaim(type.get(), space.get(), H5P_DEFAULT, pointers.data());
#endif
  return out;
}

// One scalar string from an attribute or dataset. Fixed-length strings are accepted too, so that
// the schema check gives a proper answer on files written by other tools.
std::string ReadStringValue(const Context& c, const std::string& what, hid_t file_type,
                            const std::function<herr_t(hid_t, void*)>& read) {
  if (H5Tget_class(file_type) != H5T_STRING) c.Fail(what + " is not a string");
  if (H5Tis_variable_str(file_type) > 0) {
    const Id type = VlenStringType();
    char* pointer = nullptr;
    c.Check(read(type.get(), &pointer), what);
    std::string value = pointer ? pointer : "";
    H5free_memory(pointer);
    return value;
  }
  std::string value(H5Tget_size(file_type), '\0');
  Id type(H5Tcopy(file_type), H5Tclose);
  c.Check(read(type.get(), value.data()), what);
  value.resize(std::strlen(value.c_str()));
  return value;
}

std::string ReadStringScalar(const Context& c, hid_t loc, const std::string& name) {
  const std::string what = Join(ObjectName(loc), name);
  if (!HasLink(loc, name)) c.Fail("missing dataset " + what);
  Id set(c.Check(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), what), H5Dclose);
  // H5S_ALL reads every element, and the buffer holds one string.
  Id space(c.Check(H5Dget_space(set.get()), what), H5Sclose);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) c.Fail(what + " is not a single string");
  Id type(c.Check(H5Dget_type(set.get()), what), H5Tclose);
  return ReadStringValue(c, what, type.get(), [&](hid_t memory_type, void* buf) {
    return H5Dread(set.get(), memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, buf);
  });
}

Id OpenAttribute(const Context& c, hid_t loc, const std::string& name, const std::string& what) {
  if (H5Aexists(loc, name.c_str()) <= 0) c.Fail("missing " + what);
  Id attr(c.Check(H5Aopen(loc, name.c_str(), H5P_DEFAULT), what), H5Aclose);
  Id space(c.Check(H5Aget_space(attr.get()), what), H5Sclose);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) c.Fail(what + " is not a single value");
  return attr;
}

std::string ReadStringAttribute(const Context& c, hid_t loc, const std::string& name) {
  const std::string what = "attribute '" + name + "' of " + ObjectName(loc);
  const Id attr = OpenAttribute(c, loc, name, what);
  Id type(c.Check(H5Aget_type(attr.get()), what), H5Tclose);
  return ReadStringValue(c, what, type.get(), [&](hid_t memory_type, void* buf) {
    return H5Aread(attr.get(), memory_type, buf);
  });
}

int ReadIntAttribute(const Context& c, hid_t loc, const std::string& name) {
  const std::string what = "attribute '" + name + "' of " + ObjectName(loc);
  const Id attr = OpenAttribute(c, loc, name, what);
  Id type(c.Check(H5Aget_type(attr.get()), what), H5Tclose);
  if (H5Tget_class(type.get()) != H5T_INTEGER) c.Fail(what + " is not an integer");
  int32_t value = 0;
  c.Check(H5Aread(attr.get(), H5T_NATIVE_INT32, &value), what);
  return value;
}

nlohmann::json ParseJson(const Context& c, const std::string& what, const std::string& text) {
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {  // parse_error, or out_of_range for 1e999
    c.Fail(what + " is not valid JSON: " + e.what());
  }
}

void ReadProvenance(const Context& c, hid_t loc, Provenance* p) {
  if (p == nullptr) return;
  p->stage = ReadStringAttribute(c, loc, "stage");
  p->options = ParseJson(c, "attribute 'options' of " + ObjectName(loc),
                         ReadStringAttribute(c, loc, "options"));
  p->created_utc = ReadStringAttribute(c, loc, "created_utc");
  p->raytime_version = ReadStringAttribute(c, loc, "raytime_version");
}

std::string ListOrNone(const std::vector<std::string>& names) {
  if (names.empty()) return "none";
  std::string s;
  for (const std::string& n : names) s += (s.empty() ? "" : ", ") + n;
  return s;
}

// "<image1>_<image2>" with both parts decimal, or false.
bool ParsePairName(const std::string& name, int* image1, int* image2) {
  const size_t sep = name.find('_');
  auto number = [](const std::string& s, int* out) {
    if (s.empty() || s.size() > 9 ||
        !std::all_of(s.begin(), s.end(), [](char ch) { return ch >= '0' && ch <= '9'; }))
      return false;
    *out = std::stoi(s);
    return true;
  };
  return sep != std::string::npos && number(name.substr(0, sep), image1) &&
         number(name.substr(sep + 1), image2);
}

std::string TemporarySibling(const std::string& path) {
  // The counter keeps two writers of one process (parallel stages) from sharing a name.
  static std::atomic<int> counter{0};
  const fs::path p(path);
  return (p.parent_path() / ("." + p.filename().string() + ".tmp." + std::to_string(getpid()) +
                             "." + std::to_string(counter++)))
      .string();
}

}  // namespace

// --- Hdf5Writer ----------------------------------------------------------------------------------

struct Hdf5Writer::Impl {
  Context context;
  std::string temporary;
  Id file;
  bool committed = false;
  int num_images = -1;  // known once WriteImages ran; used to check features and matches

  hid_t Root() const {
    if (committed) throw std::logic_error("Hdf5Writer used after Commit() for " + context.path);
    return file.get();
  }
  Id OpenOrCreate(const std::string& name) {
    if (HasLink(Root(), name)) return OpenGroup(context, Root(), name);
    return CreateGroup(context, Root(), name);
  }
};

Hdf5Writer::Hdf5Writer(const std::string& path) : impl_(std::make_unique<Impl>()) {
  SilenceHdf5Errors();
  impl_->context = Context{path, false};
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent);
  impl_->temporary = TemporarySibling(path);
  const Id fapl = FileAccessList();
  impl_->file =
      Id(H5Fcreate(impl_->temporary.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get()), H5Fclose);
  if (impl_->file.get() < 0) impl_->context.Fail("cannot create " + impl_->temporary);
  try {
    WriteStringAttribute(impl_->context, impl_->file.get(), "schema", "raytime");
    WriteIntAttribute(impl_->context, impl_->file.get(), "schema_version", kHdf5SchemaVersion);
  } catch (...) {
    // The destructor does not run for a throwing constructor.
    impl_->file.Reset();
    std::error_code ignored;
    fs::remove(impl_->temporary, ignored);
    throw;
  }
}

Hdf5Writer::~Hdf5Writer() {
  if (impl_->committed) return;
  impl_->file.Reset();
  std::error_code ignored;
  fs::remove(impl_->temporary, ignored);
}

void Hdf5Writer::WriteImages(const ImageSet& images) {
  const Context& c = impl_->context;
  const int num_cameras = static_cast<int>(images.cameras.size());
  std::vector<std::string> names;
  std::vector<int32_t> width, height, camera_index;
  for (const ImageInfo& image : images.images) {
    if (image.camera_index < 0 || image.camera_index >= num_cameras) {
      throw std::invalid_argument("image " + image.name + " has camera index " +
                                  std::to_string(image.camera_index) + " but there are " +
                                  std::to_string(num_cameras) + " cameras");
    }
    names.push_back(image.name);
    width.push_back(image.width);
    height.push_back(image.height);
    camera_index.push_back(image.camera_index);
  }
  {
    const Id group = CreateGroup(c, impl_->Root(), "images");
    WriteStrings(c, group.get(), "names", names);
    WriteArray(c, group.get(), "width", width);
    WriteArray(c, group.get(), "height", height);
    WriteArray(c, group.get(), "camera_index", camera_index);
    WriteStringAttribute(c, group.get(), "image_root", images.image_root);
  }
  Eigen::Matrix<double, Eigen::Dynamic, kNumIntrinsics, Eigen::RowMajor> params(num_cameras,
                                                                                kNumIntrinsics);
  std::vector<int32_t> camera_width, camera_height;
  for (int i = 0; i < num_cameras; ++i) {
    const CameraIntrinsics& camera = images.cameras[static_cast<size_t>(i)];
    for (int k = 0; k < kNumIntrinsics; ++k) params(i, k) = camera.params[static_cast<size_t>(k)];
    camera_width.push_back(camera.width);
    camera_height.push_back(camera.height);
  }
  const Id group = CreateGroup(c, impl_->Root(), "cameras");
  WriteMatrix(c, group.get(), "params", params);
  WriteArray(c, group.get(), "width", camera_width);
  WriteArray(c, group.get(), "height", camera_height);
  impl_->num_images = static_cast<int>(images.images.size());
}

void Hdf5Writer::WritePoseSet(const std::string& name, const PoseSet& poses, PoseRole role,
                              const Provenance& provenance) {
  CheckLinkName("pose set", name);
  const Context& c = impl_->context;
  const Id parent = impl_->OpenOrCreate("poses");
  const Id group = CreateGroup(c, parent.get(), name);
  std::vector<std::string> names;
  Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor> rotation(poses.size(), 4);
  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> centre(poses.size(), 3);
  for (const auto& [image, world_from_cam] : poses.world_from_cam) {
    const Eigen::Index row = static_cast<Eigen::Index>(names.size());
    const Eigen::Quaterniond& q = world_from_cam.rotation;
    rotation.row(row) << q.w(), q.x(), q.y(), q.z();
    centre.row(row) = world_from_cam.translation.transpose();
    names.push_back(image);
  }
  WriteStrings(c, group.get(), "names", names);
  WriteMatrix(c, group.get(), "rotation_wxyz", rotation);
  WriteMatrix(c, group.get(), "centre", centre);
  WriteStringAttribute(c, group.get(), "role", PoseRoleName(role));
  WriteProvenance(c, group.get(), provenance);
}

void Hdf5Writer::WriteFeatures(const std::vector<ImageFeatures>& features,
                               const Provenance& provenance) {
  const Context& c = impl_->context;
  if (impl_->num_images >= 0 && static_cast<int>(features.size()) != impl_->num_images) {
    throw std::invalid_argument("features for " + std::to_string(features.size()) +
                                " images, but the file lists " + std::to_string(impl_->num_images) +
                                " images");
  }
  const Id group = CreateGroup(c, impl_->Root(), "features");
  WriteProvenance(c, group.get(), provenance);
  for (size_t i = 0; i < features.size(); ++i) {
    const ImageFeatures& f = features[i];
    if (f.descriptors.rows() != 0 && f.descriptors.rows() != f.keypoints.rows()) {
      throw std::invalid_argument("image " + std::to_string(i) + " has " +
                                  std::to_string(f.keypoints.rows()) + " keypoints but " +
                                  std::to_string(f.descriptors.rows()) + " descriptors");
    }
    const Id image = CreateGroup(c, group.get(), std::to_string(i));
    WriteMatrix(c, image.get(), "keypoints", f.keypoints);
    WriteMatrix(c, image.get(), "descriptors", f.descriptors);
  }
}

void Hdf5Writer::WriteMatches(const std::vector<PairMatches>& pairs, const Provenance& provenance) {
  const Context& c = impl_->context;
  const Id group = CreateGroup(c, impl_->Root(), "matches");
  WriteProvenance(c, group.get(), provenance);
  for (const PairMatches& pair : pairs) {
    const std::string name = std::to_string(pair.image1) + "_" + std::to_string(pair.image2);
    if (pair.image1 < 0 || pair.image1 >= pair.image2 ||
        (impl_->num_images >= 0 && pair.image2 >= impl_->num_images)) {
      throw std::invalid_argument("invalid image pair " + name +
                                  " (need 0 <= image1 < image2 < number of images)");
    }
    const Id g = CreateGroup(c, group.get(), name);
    const TwoViewGeometry& geometry = pair.geometry;
    WriteMatrix(c, g.get(), "matches", pair.matches);
    WriteMatrix(c, g.get(), "inlier_matches", geometry.inlier_matches);
    // Eigen's Matrix3d is column-major; the dataset is row-major like every other one.
    using RowMatrix3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
    WriteMatrix(c, g.get(), "E", RowMatrix3d(geometry.E));
    WriteMatrix(c, g.get(), "F", RowMatrix3d(geometry.F));
    WriteMatrix(c, g.get(), "H", RowMatrix3d(geometry.H));
    const Eigen::Quaterniond& q = geometry.cam2_from_cam1.rotation;
    const Eigen::Vector3d& t = geometry.cam2_from_cam1.translation;
    const std::vector<double> pose = {q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z()};
    WriteArray(c, g.get(), "cam2_from_cam1_wxyz_t", pose);
    WriteIntAttribute(c, g.get(), "config", static_cast<int>(geometry.config));
  }
}

void Hdf5Writer::WriteJson(const std::string& name, const nlohmann::json& value) {
  CheckLinkName("JSON document", name);
  const Context& c = impl_->context;
  const Id parent = impl_->OpenOrCreate("json");
  if (HasLink(parent.get(), name)) c.Fail("/json/" + name + " was already written to this file");
  WriteStringScalar(c, parent.get(), name, value.dump());
}

void Hdf5Writer::Commit() {
  impl_->Root();  // throws when committed twice
  impl_->committed = true;
  const Context& c = impl_->context;
  try {
    if (impl_->file.Reset() < 0) c.Fail("cannot finish writing " + impl_->temporary);
    // Flush to disk before the rename so a crash cannot leave an empty file under the final name.
    const int fd = ::open(impl_->temporary.c_str(), O_RDONLY);
    if (fd < 0 || ::fsync(fd) != 0) {
      if (fd >= 0) ::close(fd);
      c.Fail("cannot sync " + impl_->temporary);
    }
    ::close(fd);
    fs::rename(impl_->temporary, c.path);
  } catch (...) {
    std::error_code ignored;
    fs::remove(impl_->temporary, ignored);
    throw;
  }
}

// --- Hdf5Reader ----------------------------------------------------------------------------------

struct Hdf5Reader::Impl {
  Context context;
  Id file;
  int schema_version = 0;

  // The named top-level group, or an error listing what the file holds instead.
  Id Group(const std::string& name, const std::string& description) const {
    if (!HasLink(file.get(), name)) {
      ThrowInputNoGroup(description + " (/" + name + ")");
    }
    return OpenGroup(context, file.get(), name);
  }
  [[noreturn]] void ThrowInputNoGroup(const std::string& what) const {
    throw InputError("file " + context.path + " has no " + what +
                     " (it has: " + ListOrNone(ChildNames(context, file.get())) + ")");
  }
};

Hdf5Reader::Hdf5Reader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  SilenceHdf5Errors();
  Context& c = impl_->context;
  c = Context{path, true};
  std::error_code error;
  if (!fs::is_regular_file(path, error) || !std::ifstream(path, std::ios::binary)) {
    c.Fail("cannot open (no such file, or not readable)");
  }
  const std::string unreadable = "is not a readable HDF5 file (truncated or corrupt?)";
  if (H5Fis_hdf5(path.c_str()) <= 0) c.Fail(unreadable);
  const Id fapl = FileAccessList();
  impl_->file = Id(H5Fopen(path.c_str(), H5F_ACC_RDONLY, fapl.get()), H5Fclose);
  if (impl_->file.get() < 0) c.Fail(unreadable);

  const hid_t root = impl_->file.get();
  if (H5Aexists(root, "schema") <= 0) {
    c.Fail("not a raytime file (no root attribute 'schema'; expected schema \"raytime\")");
  }
  const std::string schema = ReadStringAttribute(c, root, "schema");
  if (schema != "raytime") {
    c.Fail("not a raytime file (root attribute schema is \"" + schema +
           "\", expected \"raytime\")");
  }
  if (H5Aexists(root, "schema_version") <= 0) c.Fail("no root attribute 'schema_version'");
  impl_->schema_version = ReadIntAttribute(c, root, "schema_version");
  if (impl_->schema_version != kHdf5SchemaVersion) {
    c.Fail("unsupported schema_version " + std::to_string(impl_->schema_version) +
           " (this build of raytime " + Version() + " reads schema_version " +
           std::to_string(kHdf5SchemaVersion) + "; " +
           (impl_->schema_version > kHdf5SchemaVersion ? "the file was written by a newer raytime)"
                                                       : "re-run the stage that wrote it)"));
  }
}

Hdf5Reader::~Hdf5Reader() = default;

const std::string& Hdf5Reader::path() const { return impl_->context.path; }
int Hdf5Reader::schema_version() const { return impl_->schema_version; }

bool Hdf5Reader::HasImages() const {
  return HasLink(impl_->file.get(), "images") && HasLink(impl_->file.get(), "cameras");
}

ImageSet Hdf5Reader::ReadImages() const {
  const Context& c = impl_->context;
  ImageSet out;
  const Id cameras = impl_->Group("cameras", "camera list");
  const auto params = ReadArray<double>(c, cameras.get(), "params", {-1, kNumIntrinsics});
  const int64_t num_cameras = static_cast<int64_t>(params.dims[0]);
  const auto camera_width = ReadArray<int32_t>(c, cameras.get(), "width", {num_cameras});
  const auto camera_height = ReadArray<int32_t>(c, cameras.get(), "height", {num_cameras});
  for (int64_t i = 0; i < num_cameras; ++i) {
    CameraIntrinsics camera;
    camera.width = camera_width.data[i];
    camera.height = camera_height.data[i];
    std::copy_n(params.data.begin() + i * kNumIntrinsics, kNumIntrinsics, camera.params.begin());
    out.cameras.push_back(camera);
  }

  const Id images = impl_->Group("images", "image list");
  const std::vector<std::string> names = ReadStrings(c, images.get(), "names", -1);
  const int64_t n = static_cast<int64_t>(names.size());
  const auto width = ReadArray<int32_t>(c, images.get(), "width", {n});
  const auto height = ReadArray<int32_t>(c, images.get(), "height", {n});
  const auto camera_index = ReadArray<int32_t>(c, images.get(), "camera_index", {n});
  out.image_root = ReadStringAttribute(c, images.get(), "image_root");
  for (int64_t i = 0; i < n; ++i) {
    if (camera_index.data[i] < 0 || camera_index.data[i] >= num_cameras) {
      c.Fail("image " + names[i] + " refers to camera " + std::to_string(camera_index.data[i]) +
             " but the file has " + std::to_string(num_cameras) + " cameras");
    }
    out.images.push_back({names[i], width.data[i], height.data[i], camera_index.data[i]});
  }
  return out;
}

std::vector<std::string> Hdf5Reader::PoseSetNames() const {
  if (!HasLink(impl_->file.get(), "poses")) return {};
  const Id poses = OpenGroup(impl_->context, impl_->file.get(), "poses");
  return ChildNames(impl_->context, poses.get());
}

bool Hdf5Reader::HasPoseSet(const std::string& name) const {
  const std::vector<std::string> names = PoseSetNames();
  return std::find(names.begin(), names.end(), name) != names.end();
}

PoseSet Hdf5Reader::ReadPoseSet(const std::string& name, PoseRole* role,
                                Provenance* provenance) const {
  const Context& c = impl_->context;
  if (!HasPoseSet(name)) {
    throw InputError("file " + c.path + " has no pose set '" + name +
                     "' (it has: " + ListOrNone(PoseSetNames()) + ")");
  }
  const Id poses = OpenGroup(c, impl_->file.get(), "poses");
  const Id group = OpenGroup(c, poses.get(), name);
  const std::vector<std::string> names = ReadStrings(c, group.get(), "names", -1);
  const int64_t n = static_cast<int64_t>(names.size());
  const auto rotation = ReadArray<double>(c, group.get(), "rotation_wxyz", {n, 4});
  const auto centre = ReadArray<double>(c, group.get(), "centre", {n, 3});
  PoseSet out;
  for (size_t i = 0; i < names.size(); ++i) {
    const double* q = &rotation.data[4 * i];
    const double* t = &centre.data[3 * i];
    const Rigid3 pose(Eigen::Quaterniond(q[0], q[1], q[2], q[3]),
                      Eigen::Vector3d(t[0], t[1], t[2]));
    if (!out.world_from_cam.emplace(names[i], pose).second) {
      c.Fail("pose set '" + name + "' lists image " + names[i] + " twice");
    }
  }
  if (role != nullptr) {
    const std::string role_name = ReadStringAttribute(c, group.get(), "role");
    try {
      *role = PoseRoleFromName(role_name);
    } catch (const InputError& e) {
      c.Fail(std::string("pose set '") + name + "': " + e.what());
    }
  }
  ReadProvenance(c, group.get(), provenance);
  return out;
}

bool Hdf5Reader::HasFeatures() const { return HasLink(impl_->file.get(), "features"); }

std::vector<ImageFeatures> Hdf5Reader::ReadFeatures(Provenance* provenance) const {
  const Context& c = impl_->context;
  const Id group = impl_->Group("features", "features");
  ReadProvenance(c, group.get(), provenance);
  const size_t n = ChildNames(c, group.get()).size();
  std::vector<ImageFeatures> out(n);
  for (size_t i = 0; i < n; ++i) {
    const std::string name = std::to_string(i);
    if (!HasLink(group.get(), name)) {
      c.Fail("/features has " + std::to_string(n) + " entries but no /features/" + name);
    }
    const Id image = OpenGroup(c, group.get(), name);
    out[i].keypoints = ReadMatrix<decltype(out[i].keypoints)>(c, image.get(), "keypoints", -1, 4);
    out[i].descriptors =
        ReadMatrix<decltype(out[i].descriptors)>(c, image.get(), "descriptors", -1, -1);
  }
  return out;
}

bool Hdf5Reader::HasMatches() const { return HasLink(impl_->file.get(), "matches"); }

std::vector<PairMatches> Hdf5Reader::ReadMatches(Provenance* provenance) const {
  const Context& c = impl_->context;
  const Id group = impl_->Group("matches", "matches");
  ReadProvenance(c, group.get(), provenance);
  std::vector<PairMatches> out;
  for (const std::string& name : ChildNames(c, group.get())) {
    PairMatches pair;
    if (!ParsePairName(name, &pair.image1, &pair.image2)) {
      c.Fail("unexpected entry /matches/" + name + " (expected <image1>_<image2>)");
    }
    const Id g = OpenGroup(c, group.get(), name);
    TwoViewGeometry& geometry = pair.geometry;
    pair.matches = ReadMatrix<decltype(pair.matches)>(c, g.get(), "matches", -1, 2);
    geometry.inlier_matches =
        ReadMatrix<decltype(geometry.inlier_matches)>(c, g.get(), "inlier_matches", -1, 2);
    using RowMatrix3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
    geometry.E = ReadMatrix<RowMatrix3d>(c, g.get(), "E", 3, 3);
    geometry.F = ReadMatrix<RowMatrix3d>(c, g.get(), "F", 3, 3);
    geometry.H = ReadMatrix<RowMatrix3d>(c, g.get(), "H", 3, 3);
    const auto pose = ReadArray<double>(c, g.get(), "cam2_from_cam1_wxyz_t", {7}).data;
    geometry.cam2_from_cam1 = Rigid3(Eigen::Quaterniond(pose[0], pose[1], pose[2], pose[3]),
                                     Eigen::Vector3d(pose[4], pose[5], pose[6]));
    const int config = ReadIntAttribute(c, g.get(), "config");
    if (config < 0 || config > static_cast<int>(TwoViewConfig::kMultiple)) {
      c.Fail("/matches/" + name + " has unknown config " + std::to_string(config));
    }
    geometry.config = static_cast<TwoViewConfig>(config);
    out.push_back(std::move(pair));
  }
  std::sort(out.begin(), out.end(), [](const PairMatches& a, const PairMatches& b) {
    return std::make_pair(a.image1, a.image2) < std::make_pair(b.image1, b.image2);
  });
  return out;
}

bool Hdf5Reader::HasJson(const std::string& name) const {
  if (!HasLink(impl_->file.get(), "json")) return false;
  const Id group = OpenGroup(impl_->context, impl_->file.get(), "json");
  return HasLink(group.get(), name);
}

nlohmann::json Hdf5Reader::ReadJson(const std::string& name) const {
  const Context& c = impl_->context;
  if (!HasJson(name)) {
    std::vector<std::string> names;
    if (HasLink(impl_->file.get(), "json")) {
      names = ChildNames(c, OpenGroup(c, impl_->file.get(), "json").get());
    }
    throw InputError("file " + c.path + " has no JSON document '" + name +
                     "' (it has: " + ListOrNone(names) + ")");
  }
  const Id group = OpenGroup(c, impl_->file.get(), "json");
  return ParseJson(c, "/json/" + name, ReadStringScalar(c, group.get(), name));
}

}  // namespace raytime
