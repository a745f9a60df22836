#include "core/hdf5_store.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <ctime>
#include <filesystem>
#include <stdexcept>
#include <utility>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/hdf5_io.h"
#include "core/version.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

std::string NowUtc() {
  const std::time_t now = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  return buf;
}

void WriteProvenance(const hdf5::Context& c, hid_t loc, const Provenance& p) {
  hdf5::WriteStringAttribute(c, loc, "stage", p.stage);
  hdf5::WriteStringAttribute(c, loc, "options", p.options.dump());
  hdf5::WriteStringAttribute(c, loc, "created_utc",
                             p.created_utc.empty() ? NowUtc() : p.created_utc);
  hdf5::WriteStringAttribute(c, loc, "raytime_version",
                             p.raytime_version.empty() ? Version() : p.raytime_version);
}

nlohmann::json ParseJson(const hdf5::Context& c, const std::string& what, const std::string& text) {
  try {
    return nlohmann::json::parse(text);
  } catch (const nlohmann::json::exception& e) {  // parse_error, or out_of_range for 1e999
    c.Fail(what + " is not valid JSON: " + e.what());
  }
}

void ReadProvenance(const hdf5::Context& c, hid_t loc, Provenance* p) {
  if (p == nullptr) return;
  p->stage = hdf5::ReadStringAttribute(c, loc, "stage");
  p->options = ParseJson(c, "attribute 'options' of " + hdf5::ObjectName(loc),
                         hdf5::ReadStringAttribute(c, loc, "options"));
  p->created_utc = hdf5::ReadStringAttribute(c, loc, "created_utc");
  p->raytime_version = hdf5::ReadStringAttribute(c, loc, "raytime_version");
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

}  // namespace

// --- Hdf5Writer ----------------------------------------------------------------------------------

struct Hdf5Writer::Impl {
  hdf5::Context context;
  std::string temporary;
  hdf5::Id file;
  bool committed = false;
  int num_images = -1;  // known once WriteImages ran; used to check features and matches

  hid_t Root() const {
    if (committed) throw std::logic_error("Hdf5Writer used after Commit() for " + context.path);
    return file.get();
  }
  hdf5::Id OpenOrCreate(const std::string& name) {
    if (hdf5::HasLink(Root(), name)) return hdf5::OpenGroup(context, Root(), name);
    return hdf5::CreateGroup(context, Root(), name);
  }
};

Hdf5Writer::Hdf5Writer(const std::string& path) : impl_(std::make_unique<Impl>()) {
  impl_->context = hdf5::Context{path, false};
  const fs::path parent = fs::path(path).parent_path();
  if (!parent.empty()) fs::create_directories(parent);
  impl_->temporary = TemporarySibling(path);
  RegisterTemporary(impl_->temporary);
  impl_->file = hdf5::CreateFile(impl_->context, impl_->temporary);
  try {
    hdf5::WriteStringAttribute(impl_->context, impl_->file.get(), "schema", "raytime");
    hdf5::WriteIntAttribute(impl_->context, impl_->file.get(), "schema_version",
                            kHdf5SchemaVersion);
  } catch (...) {
    // The destructor does not run for a throwing constructor.
    impl_->file.Reset();
    std::error_code ignored;
    fs::remove(impl_->temporary, ignored);
    ForgetTemporary(impl_->temporary);
    throw;
  }
}

Hdf5Writer::~Hdf5Writer() {
  ForgetTemporary(impl_->temporary);
  if (impl_->committed) return;
  impl_->file.Reset();
  std::error_code ignored;
  fs::remove(impl_->temporary, ignored);
}

void Hdf5Writer::WriteImages(const ImageSet& images) {
  const hdf5::Context& c = impl_->context;
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
    const hdf5::Id group = hdf5::CreateGroup(c, impl_->Root(), "images");
    hdf5::WriteStrings(c, group.get(), "names", names);
    hdf5::WriteArray(c, group.get(), "width", width);
    hdf5::WriteArray(c, group.get(), "height", height);
    hdf5::WriteArray(c, group.get(), "camera_index", camera_index);
    hdf5::WriteStringAttribute(c, group.get(), "image_root", images.image_root);
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
  const hdf5::Id group = hdf5::CreateGroup(c, impl_->Root(), "cameras");
  hdf5::WriteMatrix(c, group.get(), "params", params);
  hdf5::WriteArray(c, group.get(), "width", camera_width);
  hdf5::WriteArray(c, group.get(), "height", camera_height);
  impl_->num_images = static_cast<int>(images.images.size());
}

void Hdf5Writer::WritePoseSet(const std::string& name, const PoseSet& poses, PoseRole role,
                              const Provenance& provenance) {
  hdf5::CheckLinkName("pose set", name);
  const hdf5::Context& c = impl_->context;
  const hdf5::Id parent = impl_->OpenOrCreate("poses");
  const hdf5::Id group = hdf5::CreateGroup(c, parent.get(), name);
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
  hdf5::WriteStrings(c, group.get(), "names", names);
  hdf5::WriteMatrix(c, group.get(), "rotation_wxyz", rotation);
  hdf5::WriteMatrix(c, group.get(), "centre", centre);
  hdf5::WriteStringAttribute(c, group.get(), "role", PoseRoleName(role));
  WriteProvenance(c, group.get(), provenance);
}

void Hdf5Writer::WriteRayTimes(const std::string& pose_set, const RayTimeObservations& rays) {
  hdf5::CheckLinkName("pose set", pose_set);
  const auto n = rays.observations.rows();
  if (rays.pixels.rows() != n || rays.ray_times.size() != n) {
    throw std::invalid_argument("ray times of '" + pose_set + "': " + std::to_string(n) +
                                " observations, " + std::to_string(rays.pixels.rows()) +
                                " pixels, " + std::to_string(rays.ray_times.size()) + " ray times");
  }
  for (Eigen::Index o = 0; o < n; ++o) {
    if (rays.observations(o, 0) >= rays.image_names.size()) {
      throw std::invalid_argument("ray times of '" + pose_set + "': observation " +
                                  std::to_string(o) + " names image row " +
                                  std::to_string(rays.observations(o, 0)) + " of " +
                                  std::to_string(rays.image_names.size()));
    }
  }
  if (rays.matches.size() > 0 && rays.matches.maxCoeff() >= n) {
    throw std::invalid_argument("ray times of '" + pose_set + "': a match names observation " +
                                std::to_string(rays.matches.maxCoeff()) + " of " +
                                std::to_string(n));
  }
  const hdf5::Context& c = impl_->context;
  const hdf5::Id parent = impl_->OpenOrCreate("ray_times");
  const hdf5::Id group = hdf5::CreateGroup(c, parent.get(), pose_set);
  hdf5::WriteStrings(c, group.get(), "image_names", rays.image_names);
  hdf5::WriteMatrix(c, group.get(), "observations", rays.observations);
  hdf5::WriteMatrix(c, group.get(), "pixels", rays.pixels);
  hdf5::WriteArray(c, group.get(), "ray_time", rays.ray_times.data(), {static_cast<hsize_t>(n)});
  hdf5::WriteMatrix(c, group.get(), "matches", rays.matches);
}

void Hdf5Writer::WriteFeatures(const std::vector<ImageFeatures>& features,
                               const Provenance& provenance) {
  const hdf5::Context& c = impl_->context;
  if (impl_->num_images >= 0 && static_cast<int>(features.size()) != impl_->num_images) {
    throw std::invalid_argument("features for " + std::to_string(features.size()) +
                                " images, but the file lists " + std::to_string(impl_->num_images) +
                                " images");
  }
  const hdf5::Id group = hdf5::CreateGroup(c, impl_->Root(), "features");
  WriteProvenance(c, group.get(), provenance);
  for (size_t i = 0; i < features.size(); ++i) {
    const ImageFeatures& f = features[i];
    if (f.descriptors.rows() != 0 && f.descriptors.rows() != f.keypoints.rows()) {
      throw std::invalid_argument("image " + std::to_string(i) + " has " +
                                  std::to_string(f.keypoints.rows()) + " keypoints but " +
                                  std::to_string(f.descriptors.rows()) + " descriptors");
    }
    const hdf5::Id image = hdf5::CreateGroup(c, group.get(), std::to_string(i));
    hdf5::WriteMatrix(c, image.get(), "keypoints", f.keypoints);
    hdf5::WriteMatrix(c, image.get(), "descriptors", f.descriptors);
  }
}

void Hdf5Writer::WriteMatches(const std::vector<PairMatches>& pairs, const Provenance& provenance) {
  const hdf5::Context& c = impl_->context;
  const hdf5::Id group = hdf5::CreateGroup(c, impl_->Root(), "matches");
  WriteProvenance(c, group.get(), provenance);
  for (const PairMatches& pair : pairs) {
    const std::string name = std::to_string(pair.image1) + "_" + std::to_string(pair.image2);
    if (pair.image1 < 0 || pair.image1 >= pair.image2 ||
        (impl_->num_images >= 0 && pair.image2 >= impl_->num_images)) {
      throw std::invalid_argument("invalid image pair " + name +
                                  " (need 0 <= image1 < image2 < number of images)");
    }
    const hdf5::Id g = hdf5::CreateGroup(c, group.get(), name);
    const TwoViewGeometry& geometry = pair.geometry;
    hdf5::WriteMatrix(c, g.get(), "matches", pair.matches);
    hdf5::WriteMatrix(c, g.get(), "inlier_matches", geometry.inlier_matches);
    // Eigen's Matrix3d is column-major; the dataset is row-major like every other one.
    using RowMatrix3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
    hdf5::WriteMatrix(c, g.get(), "E", RowMatrix3d(geometry.E));
    hdf5::WriteMatrix(c, g.get(), "F", RowMatrix3d(geometry.F));
    hdf5::WriteMatrix(c, g.get(), "H", RowMatrix3d(geometry.H));
    const Eigen::Quaterniond& q = geometry.cam2_from_cam1.rotation;
    const Eigen::Vector3d& t = geometry.cam2_from_cam1.translation;
    const std::vector<double> pose = {q.w(), q.x(), q.y(), q.z(), t.x(), t.y(), t.z()};
    hdf5::WriteArray(c, g.get(), "cam2_from_cam1_wxyz_t", pose);
    hdf5::WriteIntAttribute(c, g.get(), "config", static_cast<int>(geometry.config));
  }
}

void Hdf5Writer::WriteJson(const std::string& name, const nlohmann::json& value) {
  hdf5::CheckLinkName("JSON document", name);
  const hdf5::Context& c = impl_->context;
  const hdf5::Id parent = impl_->OpenOrCreate("json");
  if (hdf5::HasLink(parent.get(), name))
    c.Fail("/json/" + name + " was already written to this file");
  hdf5::WriteStringScalar(c, parent.get(), name, value.dump());
}

void Hdf5Writer::Commit() {
  impl_->Root();  // throws when committed twice
  impl_->committed = true;
  const hdf5::Context& c = impl_->context;
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
  hdf5::Context context;
  hdf5::Id file;
  int schema_version = 0;

  // The named top-level group, or an error listing what the file holds instead.
  hdf5::Id Group(const std::string& name, const std::string& description) const {
    if (!hdf5::HasLink(file.get(), name)) {
      ThrowInputNoGroup(description + " (/" + name + ")");
    }
    return hdf5::OpenGroup(context, file.get(), name);
  }
  [[noreturn]] void ThrowInputNoGroup(const std::string& what) const {
    throw InputError("file " + context.path + " has no " + what +
                     " (it has: " + ListOrNone(hdf5::ChildNames(context, file.get())) + ")");
  }
};

Hdf5Reader::Hdf5Reader(const std::string& path) : impl_(std::make_unique<Impl>()) {
  hdf5::Context& c = impl_->context;
  c = hdf5::Context{path, true};
  impl_->file = hdf5::OpenFile(c);

  const hid_t root = impl_->file.get();
  if (!hdf5::HasAttribute(root, "schema")) {
    c.Fail("not a raytime file (no root attribute 'schema'; expected schema \"raytime\")");
  }
  const std::string schema = hdf5::ReadStringAttribute(c, root, "schema");
  if (schema != "raytime") {
    c.Fail("not a raytime file (root attribute schema is \"" + schema +
           "\", expected \"raytime\")");
  }
  if (!hdf5::HasAttribute(root, "schema_version")) c.Fail("no root attribute 'schema_version'");
  impl_->schema_version = hdf5::ReadIntAttribute(c, root, "schema_version");
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
  return hdf5::HasLink(impl_->file.get(), "images") && hdf5::HasLink(impl_->file.get(), "cameras");
}

ImageSet Hdf5Reader::ReadImages() const {
  const hdf5::Context& c = impl_->context;
  ImageSet out;
  const hdf5::Id cameras = impl_->Group("cameras", "camera list");
  const auto params = hdf5::ReadArray<double>(c, cameras.get(), "params", {-1, kNumIntrinsics});
  const int64_t num_cameras = static_cast<int64_t>(params.dims[0]);
  const auto camera_width = hdf5::ReadArray<int32_t>(c, cameras.get(), "width", {num_cameras});
  const auto camera_height = hdf5::ReadArray<int32_t>(c, cameras.get(), "height", {num_cameras});
  for (int64_t i = 0; i < num_cameras; ++i) {
    CameraIntrinsics camera;
    camera.width = camera_width.data[i];
    camera.height = camera_height.data[i];
    std::copy_n(params.data.begin() + i * kNumIntrinsics, kNumIntrinsics, camera.params.begin());
    out.cameras.push_back(camera);
  }

  const hdf5::Id images = impl_->Group("images", "image list");
  const std::vector<std::string> names = hdf5::ReadStrings(c, images.get(), "names", -1);
  const int64_t n = static_cast<int64_t>(names.size());
  const auto width = hdf5::ReadArray<int32_t>(c, images.get(), "width", {n});
  const auto height = hdf5::ReadArray<int32_t>(c, images.get(), "height", {n});
  const auto camera_index = hdf5::ReadArray<int32_t>(c, images.get(), "camera_index", {n});
  out.image_root = hdf5::ReadStringAttribute(c, images.get(), "image_root");
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
  if (!hdf5::HasLink(impl_->file.get(), "poses")) return {};
  const hdf5::Id poses = hdf5::OpenGroup(impl_->context, impl_->file.get(), "poses");
  return hdf5::ChildNames(impl_->context, poses.get());
}

bool Hdf5Reader::HasPoseSet(const std::string& name) const {
  const std::vector<std::string> names = PoseSetNames();
  return std::find(names.begin(), names.end(), name) != names.end();
}

PoseSet Hdf5Reader::ReadPoseSet(const std::string& name, PoseRole* role,
                                Provenance* provenance) const {
  const hdf5::Context& c = impl_->context;
  if (!HasPoseSet(name)) {
    throw InputError("file " + c.path + " has no pose set '" + name +
                     "' (it has: " + ListOrNone(PoseSetNames()) + ")");
  }
  const hdf5::Id poses = hdf5::OpenGroup(c, impl_->file.get(), "poses");
  const hdf5::Id group = hdf5::OpenGroup(c, poses.get(), name);
  const std::vector<std::string> names = hdf5::ReadStrings(c, group.get(), "names", -1);
  const int64_t n = static_cast<int64_t>(names.size());
  const auto rotation = hdf5::ReadArray<double>(c, group.get(), "rotation_wxyz", {n, 4});
  const auto centre = hdf5::ReadArray<double>(c, group.get(), "centre", {n, 3});
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
    const std::string role_name = hdf5::ReadStringAttribute(c, group.get(), "role");
    try {
      *role = PoseRoleFromName(role_name);
    } catch (const InputError& e) {
      c.Fail(std::string("pose set '") + name + "': " + e.what());
    }
  }
  ReadProvenance(c, group.get(), provenance);
  return out;
}

bool Hdf5Reader::HasFeatures() const { return hdf5::HasLink(impl_->file.get(), "features"); }

std::vector<ImageFeatures> Hdf5Reader::ReadFeatures(Provenance* provenance) const {
  const hdf5::Context& c = impl_->context;
  const hdf5::Id group = impl_->Group("features", "features");
  ReadProvenance(c, group.get(), provenance);
  const size_t n = hdf5::ChildNames(c, group.get()).size();
  std::vector<ImageFeatures> out(n);
  for (size_t i = 0; i < n; ++i) {
    const std::string name = std::to_string(i);
    if (!hdf5::HasLink(group.get(), name)) {
      c.Fail("/features has " + std::to_string(n) + " entries but no /features/" + name);
    }
    const hdf5::Id image = hdf5::OpenGroup(c, group.get(), name);
    out[i].keypoints =
        hdf5::ReadMatrix<decltype(out[i].keypoints)>(c, image.get(), "keypoints", -1, 4);
    out[i].descriptors =
        hdf5::ReadMatrix<decltype(out[i].descriptors)>(c, image.get(), "descriptors", -1, -1);
  }
  return out;
}

bool Hdf5Reader::HasMatches() const { return hdf5::HasLink(impl_->file.get(), "matches"); }

std::vector<PairMatches> Hdf5Reader::ReadMatches(Provenance* provenance) const {
  const hdf5::Context& c = impl_->context;
  const hdf5::Id group = impl_->Group("matches", "matches");
  ReadProvenance(c, group.get(), provenance);
  std::vector<PairMatches> out;
  for (const std::string& name : hdf5::ChildNames(c, group.get())) {
    PairMatches pair;
    if (!ParsePairName(name, &pair.image1, &pair.image2)) {
      c.Fail("unexpected entry /matches/" + name + " (expected <image1>_<image2>)");
    }
    const hdf5::Id g = hdf5::OpenGroup(c, group.get(), name);
    TwoViewGeometry& geometry = pair.geometry;
    pair.matches = hdf5::ReadMatrix<decltype(pair.matches)>(c, g.get(), "matches", -1, 2);
    geometry.inlier_matches =
        hdf5::ReadMatrix<decltype(geometry.inlier_matches)>(c, g.get(), "inlier_matches", -1, 2);
    using RowMatrix3d = Eigen::Matrix<double, 3, 3, Eigen::RowMajor>;
    geometry.E = hdf5::ReadMatrix<RowMatrix3d>(c, g.get(), "E", 3, 3);
    geometry.F = hdf5::ReadMatrix<RowMatrix3d>(c, g.get(), "F", 3, 3);
    geometry.H = hdf5::ReadMatrix<RowMatrix3d>(c, g.get(), "H", 3, 3);
    const auto pose = hdf5::ReadArray<double>(c, g.get(), "cam2_from_cam1_wxyz_t", {7}).data;
    geometry.cam2_from_cam1 = Rigid3(Eigen::Quaterniond(pose[0], pose[1], pose[2], pose[3]),
                                     Eigen::Vector3d(pose[4], pose[5], pose[6]));
    const int config = hdf5::ReadIntAttribute(c, g.get(), "config");
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

bool Hdf5Reader::HasRayTimes(const std::string& pose_set) const {
  if (!hdf5::HasLink(impl_->file.get(), "ray_times")) return false;
  const hdf5::Id group = hdf5::OpenGroup(impl_->context, impl_->file.get(), "ray_times");
  return hdf5::HasLink(group.get(), pose_set);
}

RayTimeObservations Hdf5Reader::ReadRayTimes(const std::string& pose_set) const {
  const hdf5::Context& c = impl_->context;
  if (!HasRayTimes(pose_set)) {
    c.Fail("no ray times of pose set '" + pose_set + "' (/ray_times/" + pose_set +
           "; a refine stage writes them beside its pose set)");
  }
  const hdf5::Id parent = hdf5::OpenGroup(c, impl_->file.get(), "ray_times");
  const hdf5::Id group = hdf5::OpenGroup(c, parent.get(), pose_set);
  RayTimeObservations out;
  out.image_names = hdf5::ReadStrings(c, group.get(), "image_names", -1);
  out.observations =
      hdf5::ReadMatrix<decltype(out.observations)>(c, group.get(), "observations", -1, 2);
  const int64_t n = out.observations.rows();
  out.pixels = hdf5::ReadMatrix<decltype(out.pixels)>(c, group.get(), "pixels", n, 2);
  const auto ray_time = hdf5::ReadArray<double>(c, group.get(), "ray_time", {n});
  out.ray_times = Eigen::Map<const Eigen::VectorXd>(ray_time.data.data(), n);
  out.matches = hdf5::ReadMatrix<decltype(out.matches)>(c, group.get(), "matches", -1, 2);
  const std::string what = "/ray_times/" + pose_set;
  for (int64_t o = 0; o < n; ++o) {
    if (out.observations(o, 0) >= out.image_names.size()) {
      c.Fail(what + ": observation " + std::to_string(o) + " names image row " +
             std::to_string(out.observations(o, 0)) + " but there are " +
             std::to_string(out.image_names.size()) + " images");
    }
    const double t = out.ray_times(o);
    if (!std::isnan(t) && !(t > 0 && std::isfinite(t))) {
      c.Fail(what + ": observation " + std::to_string(o) + " has ray time " + std::to_string(t) +
             " (expected a positive number, or NaN for none)");
    }
    if (!out.pixels.row(o).allFinite()) {
      c.Fail(what + ": observation " + std::to_string(o) + " has a pixel that is not finite");
    }
  }
  if (out.matches.size() > 0 && out.matches.maxCoeff() >= n) {
    c.Fail(what + ": a match names observation " + std::to_string(out.matches.maxCoeff()) +
           " but there are " + std::to_string(n) + " observations");
  }
  return out;
}

bool Hdf5Reader::HasJson(const std::string& name) const {
  if (!hdf5::HasLink(impl_->file.get(), "json")) return false;
  const hdf5::Id group = hdf5::OpenGroup(impl_->context, impl_->file.get(), "json");
  return hdf5::HasLink(group.get(), name);
}

nlohmann::json Hdf5Reader::ReadJson(const std::string& name) const {
  const hdf5::Context& c = impl_->context;
  if (!HasJson(name)) {
    std::vector<std::string> names;
    if (hdf5::HasLink(impl_->file.get(), "json")) {
      names = hdf5::ChildNames(c, hdf5::OpenGroup(c, impl_->file.get(), "json").get());
    }
    throw InputError("file " + c.path + " has no JSON document '" + name +
                     "' (it has: " + ListOrNone(names) + ")");
  }
  const hdf5::Id group = hdf5::OpenGroup(c, impl_->file.get(), "json");
  return ParseJson(c, "/json/" + name, hdf5::ReadStringScalar(c, group.get(), name));
}

}  // namespace raytime
