#include "core/hdf5_io.h"

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <stdexcept>

#include "core/atomic_file.h"
#include "core/error.h"

namespace fs = std::filesystem;

namespace raytime::hdf5 {
namespace {

// HDF5's atexit cleanup closes the files still open. One whose last flush failed (a full disk) is
// left half-closed by H5Fclose, and that cleanup then crashed the process after the error had
// been reported (exit 139, issue 30). Every raytime file is closed by its owner (Id), so the
// cleanup has nothing to do; the library is told not to register it, before its first use.
const bool kNoAtexitCleanup = [] {
  H5dont_atexit();
  return true;
}();

// Treat a filesystem that refuses locks (NFS, read-only mounts) as unlocked rather than failing
// to open; raytime files are never modified in place, so locking protects nothing here.
Id FileAccessList() {
  Id fapl(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
#if H5_VERSION_GE(1, 10, 7)
  if (fapl.get() >= 0) H5Pset_file_locking(fapl.get(), true, true);
#endif
  return fapl;
}

// Failures are reported through Context; HDF5's own printing of its error stack would only
// repeat them less clearly.
void SilenceErrors() { H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr); }

Id VlenStringType() {
  Id type(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(type.get(), H5T_VARIABLE);
  H5Tset_cset(type.get(), H5T_CSET_UTF8);
  return type;
}

void WriteAttribute(const Context& c, hid_t loc, const std::string& name, hid_t type,
                    const void* value) {
  const std::string what = "attribute " + name + " of " + ObjectName(loc);
  Id space(c.Check(H5Screate(H5S_SCALAR), what), H5Sclose);
  Id attr(c.Check(H5Acreate2(loc, name.c_str(), type, space.get(), H5P_DEFAULT, H5P_DEFAULT), what),
          H5Aclose);
  c.Check(H5Awrite(attr.get(), type, value), what);
}

// One scalar string of an attribute or dataset, read through `read` in the memory type given.
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

Id OpenAttribute(const Context& c, hid_t loc, const std::string& name, const std::string& what) {
  if (!HasAttribute(loc, name)) c.Fail("missing " + what);
  Id attr(c.Check(H5Aopen(loc, name.c_str(), H5P_DEFAULT), what), H5Aclose);
  Id space(c.Check(H5Aget_space(attr.get()), what), H5Sclose);
  if (H5Sget_simple_extent_npoints(space.get()) != 1) c.Fail(what + " is not a single value");
  return attr;
}

}  // namespace

void Context::Fail(const std::string& message) const {
  if (reading) ThrowInput(path, 0, message);
  // errno of the failed write() below HDF5, read before anything else can change it.
  const int error = errno;
  throw std::runtime_error(path + ": " + message + WriteFailureReason(path, error));
}

Id OpenFile(const Context& c) {
  SilenceErrors();
  std::error_code error;
  if (!fs::is_regular_file(c.path, error)) c.Fail("cannot open (no such file)");
  if (!std::ifstream(c.path, std::ios::binary)) {
    c.Fail(std::string("cannot open (") + std::strerror(errno) + ")");
  }
  const std::string unreadable = "is not a readable HDF5 file (truncated or corrupt?)";
  if (H5Fis_hdf5(c.path.c_str()) <= 0) c.Fail(unreadable);
  const Id fapl = FileAccessList();
  Id file(H5Fopen(c.path.c_str(), H5F_ACC_RDONLY, fapl.get()), H5Fclose);
  if (file.get() < 0) c.Fail(unreadable);
  return file;
}

Id CreateFile(const Context& c, const std::string& path) {
  SilenceErrors();
  const Id fapl = FileAccessList();
  Id file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, fapl.get()), H5Fclose);
  if (file.get() < 0) c.Fail("cannot create " + path);
  return file;
}

void CheckLinkName(const std::string& kind, const std::string& name) {
  if (name.empty() || name == "." || name.find('/') != std::string::npos) {
    throw InputError("invalid " + kind + " name '" + name + "' (must be non-empty, without '/')");
  }
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

bool HasAttribute(hid_t loc, const std::string& name) { return H5Aexists(loc, name.c_str()) > 0; }

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

std::vector<std::string> ChildNames(const Context& c, hid_t group) {
  // One pass over the links: a lookup by index walks the group's index from its start each time,
  // quadratic in the links (a 99,945-pair matches file was still being listed after 6 minutes).
  std::vector<std::string> names;
  const auto collect = [](hid_t, const char* name, const H5L_info_t*, void* data) -> herr_t {
    static_cast<std::vector<std::string>*>(data)->emplace_back(name);
    return 0;
  };
  hsize_t position = 0;
  c.Check(H5Literate(group, H5_INDEX_NAME, H5_ITER_INC, &position, collect, &names),
          "link names of " + ObjectName(group));
  return names;
}

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

void WriteStringAttribute(const Context& c, hid_t loc, const std::string& name,
                          const std::string& value) {
  const char* pointer = value.c_str();
  WriteAttribute(c, loc, name, VlenStringType().get(), &pointer);
}

void WriteIntAttribute(const Context& c, hid_t loc, const std::string& name, int value) {
  const int32_t v = value;
  WriteAttribute(c, loc, name, H5T_STD_I32LE, &v);
}

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

}  // namespace raytime::hdf5
