// Generic HDF5 plumbing under the raytime schema (hdf5_store.h): owned identifiers, files opened
// and created with errors that name the file, groups, and typed datasets and attributes. Nothing
// here knows raytime's groups; the schema lives in hdf5_store.cc.
//
// The C API is used with return-code checks: it keeps every failure in one place
// (Context::Check) where it becomes an error that names the file, instead of HDF5 exceptions or
// its error stack printing escaping to the user.
#pragma once

#include <hdf5.h>

#include <Eigen/Core>
#include <algorithm>
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace raytime::hdf5 {

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

  [[noreturn]] void Fail(const std::string& message) const;
  template <typename H>
  H Check(H status, const std::string& what) const {
    if (status < 0) Fail((reading ? "cannot read " : "cannot write ") + what);
    return status;
  }
};

// --- Files ---------------------------------------------------------------------------------------

// Opens c.path read-only; a missing, unreadable or non-HDF5 file fails through `c`.
Id OpenFile(const Context& c);
// Creates (truncates) `path`; failures go through `c`, which may name another path (a writer's
// temporary file is reported under its final name).
Id CreateFile(const Context& c, const std::string& path);

// --- Groups and names ----------------------------------------------------------------------------

// Group and dataset names become HDF5 link names, where "/" would silently create nesting;
// throws std::invalid_argument naming `kind` for such a name.
void CheckLinkName(const std::string& kind, const std::string& name);
// Full HDF5 path of an open object, "?" when unknown.
std::string ObjectName(hid_t loc);
// HDF5 path of `child` below `parent`.
std::string Join(const std::string& parent, const std::string& child);
bool HasLink(hid_t loc, const std::string& name);
bool HasAttribute(hid_t loc, const std::string& name);
Id OpenGroup(const Context& c, hid_t loc, const std::string& name);
// Fails when `name` exists already.
Id CreateGroup(const Context& c, hid_t loc, const std::string& name);
// Link names of a group's children in name order.
std::vector<std::string> ChildNames(const Context& c, hid_t group);

// --- Element types -------------------------------------------------------------------------------

// File types are little-endian with fixed widths whatever the host (docs/hdf5_schema.md).
template <typename T>
struct ElementType;
template <>
struct ElementType<float> {
  static hid_t File() { return H5T_IEEE_F32LE; }
  static hid_t Memory() { return H5T_NATIVE_FLOAT; }
  static constexpr H5T_class_t kClass = H5T_FLOAT;
};
template <>
struct ElementType<double> {
  static hid_t File() { return H5T_IEEE_F64LE; }
  static hid_t Memory() { return H5T_NATIVE_DOUBLE; }
  static constexpr H5T_class_t kClass = H5T_FLOAT;
};
template <>
struct ElementType<int32_t> {
  static hid_t File() { return H5T_STD_I32LE; }
  static hid_t Memory() { return H5T_NATIVE_INT32; }
  static constexpr H5T_class_t kClass = H5T_INTEGER;
};
template <>
struct ElementType<uint32_t> {
  static hid_t File() { return H5T_STD_U32LE; }
  static hid_t Memory() { return H5T_NATIVE_UINT32; }
  static constexpr H5T_class_t kClass = H5T_INTEGER;
};
template <>
struct ElementType<uint8_t> {
  static hid_t File() { return H5T_STD_U8LE; }
  static hid_t Memory() { return H5T_NATIVE_UINT8; }
  static constexpr H5T_class_t kClass = H5T_INTEGER;
};

// --- Writing -------------------------------------------------------------------------------------

// A dataset of shape `dims` from `data` in `memory_type`. Zero-length dimensions are legal; only
// the transfer is skipped (Eigen's buffer of an empty matrix may be null).
void WriteRaw(const Context& c, hid_t loc, const std::string& name, hid_t file_type,
              hid_t memory_type, const void* data, const std::vector<hsize_t>& dims);

template <typename T>
void WriteArray(const Context& c, hid_t loc, const std::string& name, const T* data,
                const std::vector<hsize_t>& dims) {
  WriteRaw(c, loc, name, ElementType<T>::File(), ElementType<T>::Memory(), data, dims);
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

// Variable-length UTF-8 strings, as a 1-D dataset or a scalar one.
void WriteStrings(const Context& c, hid_t loc, const std::string& name,
                  const std::vector<std::string>& values);
void WriteStringScalar(const Context& c, hid_t loc, const std::string& name,
                       const std::string& value);

void WriteStringAttribute(const Context& c, hid_t loc, const std::string& name,
                          const std::string& value);
void WriteIntAttribute(const Context& c, hid_t loc, const std::string& name, int value);

// --- Reading -------------------------------------------------------------------------------------

template <typename T>
struct Array {
  std::vector<T> data;  // C order
  std::vector<hsize_t> dims;
};

// Fails unless `dims` matches `shape`: the expected extent per dimension, -1 for any.
void CheckShape(const Context& c, const std::string& what, const std::vector<hsize_t>& dims,
                const std::vector<int64_t>& shape);
std::vector<hsize_t> Dims(const Context& c, hid_t set, const std::string& what);
// The number of elements of a dataset of extent `dims`, checked before anything is allocated for
// them: fails when the count overflows size_t or when a non-empty dataset's data was never written
// (storage not or only partly allocated: fill values). Every raytime writer writes all of a
// dataset's elements, so that means a foreign or damaged file; left unchecked, a small file could
// declare an extent far beyond memory.
size_t ElementCount(const Context& c, hid_t set, const std::string& what,
                    const std::vector<hsize_t>& dims);

// A numeric dataset of `shape` (CheckShape); fails when missing or of another element class.
template <typename T>
Array<T> ReadArray(const Context& c, hid_t loc, const std::string& name,
                   const std::vector<int64_t>& shape) {
  const std::string what = Join(ObjectName(loc), name);
  if (!HasLink(loc, name)) c.Fail("missing dataset " + what);
  Id set(c.Check(H5Dopen2(loc, name.c_str(), H5P_DEFAULT), what), H5Dclose);
  Id type(c.Check(H5Dget_type(set.get()), what), H5Tclose);
  if (H5Tget_class(type.get()) != ElementType<T>::kClass) {
    c.Fail(what + " has the wrong element type (expected " +
           (ElementType<T>::kClass == H5T_FLOAT ? "floating point" : "integer") + ")");
  }
  Array<T> out;
  out.dims = Dims(c, set.get(), what);
  CheckShape(c, what, out.dims, shape);
  const size_t count = ElementCount(c, set.get(), what, out.dims);
  out.data.resize(count);
  if (count > 0) {
    c.Check(H5Dread(set.get(), ElementType<T>::Memory(), H5S_ALL, H5S_ALL, H5P_DEFAULT,
                    out.data.data()),
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

// A 1-D variable-length string dataset of `size` entries (-1: any).
std::vector<std::string> ReadStrings(const Context& c, hid_t loc, const std::string& name,
                                     int64_t size);
// Scalar strings; fixed-length ones are accepted too, so that checks on files written by other
// tools give a proper answer.
std::string ReadStringScalar(const Context& c, hid_t loc, const std::string& name);
std::string ReadStringAttribute(const Context& c, hid_t loc, const std::string& name);
int ReadIntAttribute(const Context& c, hid_t loc, const std::string& name);

}  // namespace raytime::hdf5
