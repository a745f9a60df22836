// libFuzzer target: the HDF5 schema reader (core/hdf5_store.h, Hdf5Reader), structure-aware.
//
// Mutating the bytes of an HDF5 file mostly exercises libhdf5's own parser, which is not ours
// and which leaks, makes absurd allocations and loops forever on corrupt containers (1.10.8:
// tests/fuzz/README.md). Here the input is a program that builds a *valid* container
// with the HDF5 C API, and every Hdf5Reader method then runs on it. The program decides, for
// each group of docs/hdf5_schema.md, each dataset and each attribute, whether it is there and
// as the schema says, or missing, of another type class, width or byte order, another rank or
// extent, a huge extent never written (fill values), a scalar or null dataspace; datasets are
// contiguous, chunked, compressed or compact, and contents come from the input. Stray entries
// (a dataset where a group belongs, links, extra attributes) are mixed in.
//
// Decoding (ByteReader: an exhausted input reads as zeros, which means "as the schema says"; at
// most one read per function call's arguments, whose order C++ leaves open, so that gcc's replay
// decodes an input as clang's fuzzer did):
//   root attributes schema, schema_version; then until the input ends, one op byte choosing
//   images, cameras, a pose set, features, matches, a JSON document, a stray entry or an
//   attribute (op byte modulo 9), each followed by its own choices (see the functions below); the
//   op byte 255 (added later, so that the older seeds and reproducers decode as before) chooses
//   the ray times of a pose set.
#include <hdf5.h>

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/hdf5_store.h"
#include "tests/fuzz/fuzz_util.h"

namespace raytime::fuzz {
namespace {

// Owns an HDF5 identifier (the harness must not leak them: the library lives for the whole run).
class Handle {
 public:
  Handle() = default;
  Handle(hid_t id, herr_t (*close)(hid_t)) : id_(id), close_(close) {}
  Handle(Handle&& o) noexcept : id_(std::exchange(o.id_, H5I_INVALID_HID)), close_(o.close_) {}
  Handle& operator=(Handle&& o) noexcept {
    std::swap(id_, o.id_);
    std::swap(close_, o.close_);
    return *this;
  }
  ~Handle() {
    if (id_ >= 0) close_(id_);
  }
  hid_t get() const { return id_; }
  bool ok() const { return id_ >= 0; }

 private:
  hid_t id_ = H5I_INVALID_HID;
  herr_t (*close_)(hid_t) = nullptr;
};

enum class Kind { kFloat, kInt, kVlenString, kFixedString, kCompound, kArray };
constexpr int kNumKinds = 6;

Handle StringType(bool variable, size_t size) {
  Handle type(H5Tcopy(H5T_C_S1), H5Tclose);
  H5Tset_size(type.get(), variable ? H5T_VARIABLE : std::max<size_t>(size, 1));
  H5Tset_cset(type.get(), H5T_CSET_UTF8);
  return type;
}

// The file type of a dataset or attribute of `kind`; `variant` picks width and byte order.
Handle FileType(Kind kind, unsigned variant) {
  switch (kind) {
    case Kind::kFloat: {
      const hid_t types[] = {H5T_IEEE_F64LE, H5T_IEEE_F32LE, H5T_IEEE_F64BE, H5T_IEEE_F32BE};
      return Handle(H5Tcopy(types[variant % 4]), H5Tclose);
    }
    case Kind::kInt: {
      const hid_t types[] = {H5T_STD_I32LE, H5T_STD_U32LE, H5T_STD_U8LE,  H5T_STD_I64BE,
                             H5T_STD_I8LE,  H5T_STD_U64LE, H5T_STD_I16BE, H5T_STD_I32BE};
      return Handle(H5Tcopy(types[variant % 8]), H5Tclose);
    }
    case Kind::kVlenString:
      return StringType(true, 0);
    case Kind::kFixedString:
      return StringType(false, 1 + variant % 16);
    case Kind::kCompound: {
      Handle type(H5Tcreate(H5T_COMPOUND, 12), H5Tclose);
      H5Tinsert(type.get(), "a", 0, H5T_STD_I32LE);
      H5Tinsert(type.get(), "b", 4, H5T_IEEE_F64LE);
      return type;
    }
    case Kind::kArray: {
      const hsize_t dims[1] = {2};
      return Handle(H5Tarray_create2(H5T_STD_I32LE, 1, dims), H5Tclose);
    }
  }
  return Handle();
}

// Names: mostly from `usual` (so that images, poses and pairs refer to one another), sometimes
// arbitrary bytes.
std::string Name(ByteReader& in, const std::vector<std::string>& usual) {
  const uint8_t b = in.Byte();
  if (b < 224 && !usual.empty()) return usual[b % usual.size()];
  return in.String(24);
}

// One element's worth of numbers: mostly small, sometimes any bit pattern (NaN, huge, negative).
double FloatValue(ByteReader& in) {
  const uint8_t b = in.Byte();
  return b < 240 ? b / 16.0 - 4.0 : in.Value<double>();
}
int64_t IntValue(ByteReader& in, const std::vector<int64_t>& usual) {
  const uint8_t b = in.Byte();
  if (b >= 240) return in.Value<int64_t>();
  return usual.empty() ? b % 8 : usual[b % usual.size()];
}

const std::vector<std::string> kImageNames = {"a.jpg", "b.jpg", "c.jpg", "0000.jpg", ""};
const std::vector<std::string> kJsonTexts = {"{}", "null", "[1, 2]",   "{\"a\": {\"b\": [true]}}",
                                             "",   "{",    "\"text\"", "1e999"};

// Writes `count` elements of `kind` from the input through the matching memory type.
herr_t WriteData(ByteReader& in, Kind kind, hid_t file_type, size_t count,
                 const std::function<herr_t(hid_t, const void*)>& write,
                 const std::vector<std::string>& strings, const std::vector<int64_t>& ints) {
  switch (kind) {
    case Kind::kFloat: {
      std::vector<double> v(count);
      for (double& x : v) x = FloatValue(in);
      return write(H5T_NATIVE_DOUBLE, v.data());
    }
    case Kind::kInt: {
      std::vector<int64_t> v(count);
      for (int64_t& x : v) x = IntValue(in, ints);
      return write(H5T_NATIVE_INT64, v.data());
    }
    case Kind::kVlenString: {
      std::vector<std::string> values(count);
      std::vector<const char*> pointers(count);
      for (size_t i = 0; i < count; ++i) {
        values[i] = Name(in, strings);
        pointers[i] = values[i].c_str();
      }
      return write(file_type, pointers.data());
    }
    default: {
      // Fixed-length strings, compounds and arrays: raw bytes in the file type's layout.
      const std::string bytes = in.Bytes(count * H5Tget_size(file_type));
      return write(file_type, bytes.data());
    }
  }
}

// A dataset `name` in `loc` that the schema wants as `kind` with `dims` (empty: scalar).
void Dataset(ByteReader& in, hid_t loc, const std::string& name, Kind kind,
             std::vector<hsize_t> dims, const std::vector<std::string>& strings = kImageNames) {
  const uint8_t control = in.Byte();
  const unsigned action = control % 16;
  const unsigned variant = control >> 4;
  bool scalar = dims.empty(), null_space = false, write = true;
  switch (action) {
    case 10:
      return;  // missing
    case 11:
      kind = static_cast<Kind>(in.Pick(kNumKinds));
      break;
    case 12:
      if (!dims.empty() && in.Bool()) {
        dims.pop_back();
      } else {
        dims.push_back(in.Pick(4));
      }
      scalar = dims.empty();
      break;
    case 13:
      for (hsize_t& d : dims) d = in.Pick(9);
      break;
    case 14:
      // An extent far beyond the file's size, never written: reads produce fill values.
      if (dims.empty()) dims.push_back(1);
      for (hsize_t& d : dims) d = hsize_t{1} << in.Pick(41);
      write = false;
      break;
    case 15:
      scalar = in.Bool();
      null_space = !scalar;
      break;
    default:
      break;
  }
  if (variant == 15) write = false;  // created but never written

  Handle space;
  if (null_space) {
    space = Handle(H5Screate(H5S_NULL), H5Sclose);
  } else if (scalar) {
    space = Handle(H5Screate(H5S_SCALAR), H5Sclose);
  } else {
    space = Handle(H5Screate_simple(static_cast<int>(dims.size()), dims.data(), nullptr), H5Sclose);
  }
  const Handle type = FileType(kind, variant);
  if (!space.ok() || !type.ok()) return;
  // Saturates above kMaxWritten: only small datasets are written.
  constexpr hsize_t kMaxWritten = 4096;
  hsize_t count = null_space ? 0 : 1;
  if (!scalar && !null_space) {
    for (hsize_t d : dims) count = d != 0 && count > kMaxWritten / d ? kMaxWritten + 1 : count * d;
  }
  if (count > kMaxWritten) write = false;

  Handle create(H5Pcreate(H5P_DATASET_CREATE), H5Pclose);
  const unsigned layout = in.Pick(4);
  if (!scalar && !null_space && layout >= 1 && layout <= 2) {
    std::vector<hsize_t> chunk(dims.size());
    for (size_t i = 0; i < dims.size(); ++i)
      chunk[i] = std::max<hsize_t>(1, std::min<hsize_t>(dims[i], 4));
    H5Pset_chunk(create.get(), static_cast<int>(chunk.size()), chunk.data());
    if (layout == 2) H5Pset_deflate(create.get(), 1);
  } else if (layout == 3 && count * H5Tget_size(type.get()) < 32768) {
    H5Pset_layout(create.get(), H5D_COMPACT);
  }
  const Handle set(H5Dcreate2(loc, name.c_str(), type.get(), space.get(), H5P_DEFAULT, create.get(),
                              H5P_DEFAULT),
                   H5Dclose);
  if (!set.ok() || !write || count == 0) return;
  WriteData(in, kind, type.get(), count,
            [&](hid_t memory_type, const void* buffer) {
              return H5Dwrite(set.get(), memory_type, H5S_ALL, H5S_ALL, H5P_DEFAULT, buffer);
            },
            strings, {});
}

// An attribute `name` on `loc` that the schema wants as a single `kind` value (kVlenString or
// kInt); values mostly from `strings` or `ints`.
void Attribute(ByteReader& in, hid_t loc, const std::string& name, Kind kind,
               const std::vector<std::string>& strings, const std::vector<int64_t>& ints = {}) {
  const uint8_t control = in.Byte();
  const unsigned action = control % 16;
  const unsigned variant = control >> 4;
  unsigned type_variant = 0;  // the schema's type: int32 little-endian, UTF-8 string
  Handle space(H5Screate(H5S_SCALAR), H5Sclose);
  switch (action) {
    case 10:
      return;  // missing
    case 11:
      kind = static_cast<Kind>(in.Pick(kNumKinds));
      type_variant = variant;
      break;
    case 12: {
      const hsize_t dims[1] = {in.Pick(3)};
      space = Handle(H5Screate_simple(1, dims, nullptr), H5Sclose);
      break;
    }
    case 13:
      space = Handle(H5Screate(H5S_NULL), H5Sclose);
      break;
    case 14:
      kind = Kind::kFixedString;
      type_variant = variant;
      break;
    case 15:
      type_variant = variant;  // another width or byte order
      break;
    default:
      break;
  }
  const Handle type = FileType(kind, type_variant);
  if (!space.ok() || !type.ok()) return;
  H5Adelete(loc, name.c_str());  // an op may set it twice
  const Handle attr(
      H5Acreate2(loc, name.c_str(), type.get(), space.get(), H5P_DEFAULT, H5P_DEFAULT), H5Aclose);
  if (!attr.ok()) return;
  const hssize_t count = H5Sget_simple_extent_npoints(space.get());
  if (count <= 0) return;
  WriteData(
      in, kind, type.get(), static_cast<size_t>(count),
      [&](hid_t memory_type, const void* buffer) {
        return H5Awrite(attr.get(), memory_type, buffer);
      },
      strings, ints);
}

// The group `name` in `loc`, opened when it exists, created otherwise; invalid when `name` is
// taken by something else or not a valid link name.
Handle Group(hid_t loc, const std::string& name) {
  if (H5Lexists(loc, name.c_str(), H5P_DEFAULT) > 0) {
    return Handle(H5Gopen2(loc, name.c_str(), H5P_DEFAULT), H5Gclose);
  }
  return Handle(H5Gcreate2(loc, name.c_str(), H5P_DEFAULT, H5P_DEFAULT, H5P_DEFAULT), H5Gclose);
}

void ProvenanceAttributes(ByteReader& in, hid_t loc) {
  Attribute(in, loc, "stage", Kind::kVlenString, {"prior", "refine", "features"});
  Attribute(in, loc, "options", Kind::kVlenString, kJsonTexts);
  Attribute(in, loc, "created_utc", Kind::kVlenString, {"2024-05-01T10:00:00Z"});
  Attribute(in, loc, "raytime_version", Kind::kVlenString, {"0.1.0"});
}

const std::vector<std::string> kPoseSetNames = {"prior", "refined", "ground_truth", "refined@gnc"};
const std::vector<std::string> kRoles = {"prior", "refined", "ground_truth", "other"};
const std::vector<std::string> kJsonNames = {"refine_summary", "bootstrap_pairs",
                                             "bootstrap_support"};

// Everything the harness created that the reader can be asked about by name.
struct Built {
  std::vector<std::string> pose_sets = {"prior"};
  std::vector<std::string> json_names = {"refine_summary"};
};

void Images(ByteReader& in, hid_t root) {
  const Handle group = Group(root, "images");
  if (!group.ok()) return;
  const hsize_t n = in.Pick(5);
  Dataset(in, group.get(), "names", Kind::kVlenString, {n});
  Dataset(in, group.get(), "width", Kind::kInt, {n});
  Dataset(in, group.get(), "height", Kind::kInt, {n});
  Dataset(in, group.get(), "camera_index", Kind::kInt, {n});
  Attribute(in, group.get(), "image_root", Kind::kVlenString, {"", "images"});
}

void Cameras(ByteReader& in, hid_t root) {
  const Handle group = Group(root, "cameras");
  if (!group.ok()) return;
  const hsize_t n = in.Pick(4);
  Dataset(in, group.get(), "params", Kind::kFloat, {n, 8});
  Dataset(in, group.get(), "width", Kind::kInt, {n});
  Dataset(in, group.get(), "height", Kind::kInt, {n});
}

void PoseSetGroup(ByteReader& in, hid_t root, Built* built) {
  const Handle poses = Group(root, "poses");
  if (!poses.ok()) return;
  const std::string name = Name(in, kPoseSetNames);
  const Handle group = Group(poses.get(), name);
  if (!group.ok()) return;
  built->pose_sets.push_back(name);
  const hsize_t n = in.Pick(5);
  Dataset(in, group.get(), "names", Kind::kVlenString, {n});
  Dataset(in, group.get(), "rotation_wxyz", Kind::kFloat, {n, 4});
  Dataset(in, group.get(), "centre", Kind::kFloat, {n, 3});
  Attribute(in, group.get(), "role", Kind::kVlenString, kRoles);
  ProvenanceAttributes(in, group.get());
}

void Features(ByteReader& in, hid_t root) {
  const Handle group = Group(root, "features");
  if (!group.ok()) return;
  ProvenanceAttributes(in, group.get());
  const unsigned images = in.Pick(4);
  for (unsigned i = 0; i < images; ++i) {
    const Handle image = Group(group.get(), Name(in, {std::to_string(i), "0", "1", "x"}));
    if (!image.ok()) continue;
    const hsize_t k = in.Pick(5);
    const hsize_t descriptor_size[] = {128, 0, 2, 128};
    Dataset(in, image.get(), "keypoints", Kind::kFloat, {k, 4});
    Dataset(in, image.get(), "descriptors", Kind::kInt, {k, descriptor_size[in.Pick(4)]});
  }
}

void Matches(ByteReader& in, hid_t root) {
  const Handle group = Group(root, "matches");
  if (!group.ok()) return;
  ProvenanceAttributes(in, group.get());
  const unsigned pairs = in.Pick(4);
  for (unsigned p = 0; p < pairs; ++p) {
    const Handle pair = Group(
        group.get(), Name(in, {"0_1", "0_2", "1_2", "1_0", "0_999999999", "9999999999_1", "_"}));
    if (!pair.ok()) continue;
    Dataset(in, pair.get(), "matches", Kind::kInt, {in.Pick(5), 2});
    Dataset(in, pair.get(), "inlier_matches", Kind::kInt, {in.Pick(5), 2});
    for (const char* matrix : {"E", "F", "H"})
      Dataset(in, pair.get(), matrix, Kind::kFloat, {3, 3});
    Dataset(in, pair.get(), "cam2_from_cam1_wxyz_t", Kind::kFloat, {7});
    Attribute(in, pair.get(), "config", Kind::kInt, {}, {2, 0, 3, 8, 9, -1});
  }
}

void RayTimes(ByteReader& in, hid_t root, Built* built) {
  const Handle parent = Group(root, "ray_times");
  if (!parent.ok()) return;
  const std::string name = Name(in, kPoseSetNames);
  const Handle group = Group(parent.get(), name);
  if (!group.ok()) return;
  built->pose_sets.push_back(name);
  const hsize_t n = in.Pick(5);
  Dataset(in, group.get(), "image_names", Kind::kVlenString, {in.Pick(4)});
  Dataset(in, group.get(), "observations", Kind::kInt, {n, 2});
  Dataset(in, group.get(), "pixels", Kind::kFloat, {n, 2});
  Dataset(in, group.get(), "ray_time", Kind::kFloat, {n});
  Dataset(in, group.get(), "matches", Kind::kInt, {in.Pick(5), 2});
}

void Json(ByteReader& in, hid_t root, Built* built) {
  const Handle group = Group(root, "json");
  if (!group.ok()) return;
  const std::string name = Name(in, kJsonNames);
  built->json_names.push_back(name);
  Dataset(in, group.get(), name, Kind::kVlenString, {}, kJsonTexts);
}

const std::vector<std::string> kStrayNames = {"images", "cameras", "poses", "features", "matches",
                                              "json",   "names",   "0",     "0_1",      "prior"};
const std::vector<std::string> kParents = {"/",           "/images", "/poses",       "/features",
                                           "/matches",    "/json",   "/poses/prior", "/features/0",
                                           "/matches/0_1"};

// Something the schema does not expect where the reader looks: a dataset or group under a
// schema name, or a soft or hard link.
void Stray(ByteReader& in, hid_t root) {
  const std::string parent_name = Name(in, kParents);
  if (H5Lexists(root, parent_name.c_str(), H5P_DEFAULT) <= 0 && parent_name != "/") return;
  const Handle parent(H5Oopen(root, parent_name.c_str(), H5P_DEFAULT), H5Oclose);
  if (!parent.ok() || H5Iget_type(parent.get()) != H5I_GROUP) return;
  const std::string name = Name(in, kStrayNames);
  switch (in.Pick(4)) {
    case 0: {
      const auto kind = static_cast<Kind>(in.Pick(kNumKinds));
      Dataset(in, parent.get(), name, kind, {in.Pick(4)});
      break;
    }
    case 1:
      Group(parent.get(), name);
      break;
    case 2:
      H5Lcreate_soft(Name(in, kParents).c_str(), parent.get(), name.c_str(), H5P_DEFAULT,
                     H5P_DEFAULT);
      break;
    case 3:
      H5Lcreate_hard(root, Name(in, kParents).c_str(), parent.get(), name.c_str(), H5P_DEFAULT,
                     H5P_DEFAULT);
      break;
  }
}

// An extra or replaced attribute on an existing object.
void StrayAttribute(ByteReader& in, hid_t root) {
  const std::string object = Name(in, kParents);
  const Handle target(H5Oopen(root, object.c_str(), H5P_DEFAULT), H5Oclose);
  if (!target.ok()) return;
  const std::string name =
      Name(in, {"schema", "schema_version", "role", "config", "stage", "options", "image_root"});
  const Kind kind = in.Bool() ? Kind::kInt : Kind::kVlenString;
  Attribute(in, target.get(), name, kind, kRoles);
}

Built Build(ByteReader& in, hid_t file) {
  Built built;
  Attribute(in, file, "schema", Kind::kVlenString, {"raytime", "other", ""});
  Attribute(in, file, "schema_version", Kind::kInt, {}, {1, 0, 2, -1});
  while (!in.empty()) {
    const uint8_t op = in.Byte();
    if (op == 255) {
      RayTimes(in, file, &built);
      continue;
    }
    switch (op % 9) {
      case 0:
        Images(in, file);
        break;
      case 1:
        Cameras(in, file);
        break;
      case 2:
        PoseSetGroup(in, file, &built);
        break;
      case 3:
        Features(in, file);
        break;
      case 4:
        Matches(in, file);
        break;
      case 5:
        Json(in, file, &built);
        break;
      case 6:
        Stray(in, file);
        break;
      case 7:
        StrayAttribute(in, file);
        break;
      case 8:
        Images(in, file);
        Cameras(in, file);
        break;
    }
  }
  return built;
}

// Runs `call`; an InputError is the reader's expected answer to a file it cannot use.
template <typename F>
void ExpectInputError(F&& call) {
  try {
    call();
  } catch (const InputError&) {
  }
}

// Opens `path` and calls every reader method, for the pose sets it lists and `pose_sets`, and for
// the JSON documents `json_names`.
void ReadAll(const std::string& path, std::vector<std::string> pose_sets,
             const std::vector<std::string>& json_names) {
  std::unique_ptr<Hdf5Reader> reader;
  try {
    reader = std::make_unique<Hdf5Reader>(path);
  } catch (const InputError&) {
    return;
  }
  const Hdf5Reader& r = *reader;
  r.path();
  r.schema_version();
  ExpectInputError([&] { r.HasImages(); });
  ExpectInputError([&] { r.ReadImages(); });
  ExpectInputError([&] {
    for (const std::string& name : r.PoseSetNames()) pose_sets.push_back(name);
  });
  for (const std::string& name : pose_sets) {
    ExpectInputError([&] { r.HasPoseSet(name); });
    ExpectInputError([&] { r.ReadPoseSet(name); });
    ExpectInputError([&] {
      PoseRole role;
      Provenance provenance;
      r.ReadPoseSet(name, &role, &provenance);
    });
    ExpectInputError([&] { r.HasRayTimes(name); });
    ExpectInputError([&] { r.ReadRayTimes(name); });
  }
  ExpectInputError([&] { r.HasFeatures(); });
  ExpectInputError([&] { r.ReadFeatures(); });
  ExpectInputError([&] {
    Provenance provenance;
    r.ReadFeatures(&provenance);
  });
  ExpectInputError([&] { r.HasMatches(); });
  ExpectInputError([&] { r.ReadMatches(); });
  ExpectInputError([&] {
    Provenance provenance;
    r.ReadMatches(&provenance);
  });
  for (const std::string& name : json_names) {
    ExpectInputError([&] { r.HasJson(name); });
    ExpectInputError([&] { r.ReadJson(name); });
  }
}

}  // namespace
}  // namespace raytime::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace raytime::fuzz;
  H5Eset_auto2(H5E_DEFAULT, nullptr, nullptr);  // failed creations are expected; stay quiet
  // libhdf5 callocs about 1 MB per opened file (metadata cache) and per converting read or write
  // (conversion buffer) and, beyond its default free-list limits, hands them back to malloc;
  // under ASan every such block is then a fresh mapping whose page faults cost more than the
  // rest of an execution. Unlimited free lists keep the blocks (4x more executions).
  H5set_free_list_limits(-1, -1, -1, -1, -1, -1);
  const std::string path = ScratchPath("store.h5");
  Built built;
  {
    const Handle file(H5Fcreate(path.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, H5P_DEFAULT), H5Fclose);
    if (!file.ok()) {
      std::fprintf(stderr, "cannot create %s\n", path.c_str());
      std::abort();
    }
    ByteReader in(data, size);
    built = Build(in, file.get());
  }
  ReadAll(path, built.pose_sets, built.json_names);
  return 0;
}
