#include "formats/strecha.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <stdexcept>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/intrinsics.h"
#include "formats/text_util.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {
constexpr size_t kNumbersPerCamera = 26;
constexpr char kLayout[] = "K (3x3), distortion (3), R (3x3), centre (3), width height";
}  // namespace

StrechaCamera ReadStrechaCamera(const std::string& path, Warnings* warnings) {
  const text::NumbersWithLines numbers = text::ParseNumbers(path, ReadTextFile(path));
  const std::vector<double>& v = numbers.values;
  const std::vector<int>& line_of = numbers.lines;  // line of each number, for messages
  if (v.size() != kNumbersPerCamera) {
    ThrowInput(path, 0,
               "found " + std::to_string(v.size()) + " numbers, expected " +
                   std::to_string(kNumbersPerCamera) + ": " + kLayout);
  }
  if (v[9] != 0 || v[10] != 0 || v[11] != 0) {
    ThrowInput(path, 0, "distortion must be 0 0 0 (the images are undistorted)");
  }
  const double width = v[24], height = v[25];
  if (width < 1 || height < 1 || width != std::floor(width) || height != std::floor(height) ||
      width > 1e9 || height > 1e9) {
    ThrowInput(path, 0, "width and height must be positive whole numbers");
  }
  const Eigen::Matrix3d world_from_cam_rotation =
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(&v[12]);
  // Orthonormalize would quietly turn a sheared R into a ground truth degrees off.
  const std::string problem = RotationMatrixProblem(world_from_cam_rotation);
  if (!problem.empty()) ThrowInput(path, line_of[12], "R (numbers 13-21): " + problem);
  StrechaCamera camera;
  // NAME.camera belongs to image NAME.
  camera.intrinsics =
      IntrinsicsFromK(Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(&v[0]),
                      static_cast<int>(width), static_cast<int>(height), path,
                      fs::path(path).stem().string(), warnings);
  camera.world_from_cam = Rigid3(Eigen::Quaterniond(Orthonormalize(world_from_cam_rotation)),
                                 Eigen::Vector3d(v[21], v[22], v[23]));
  return camera;
}

void WriteStrechaCamera(const std::string& path, const StrechaCamera& camera) {
  const CameraIntrinsics& k = camera.intrinsics;
  if (k.HasDistortion()) {
    throw InputError("Strecha cameras are undistorted; cannot write " + path);
  }
  const Eigen::Matrix3d r = camera.world_from_cam.rotation.normalized().toRotationMatrix();
  const Eigen::Vector3d& c = camera.world_from_cam.translation;
  const auto row = [](double a, double b, double c) {
    return text::FormatDouble(a) + ' ' + text::FormatDouble(b) + ' ' + text::FormatDouble(c) + '\n';
  };
  std::string out = row(k.fx(), 0, k.cx()) + row(0, k.fy(), k.cy()) + row(0, 0, 1) + "0 0 0\n";
  for (int i = 0; i < 3; ++i) out += row(r(i, 0), r(i, 1), r(i, 2));
  out += row(c.x(), c.y(), c.z());
  out += std::to_string(k.width) + ' ' + std::to_string(k.height) + '\n';
  WriteTextFileAtomically(path, out);
}

void ReadStrechaScene(const std::string& root, ImageSet* images, PoseSet* ground_truth,
                      Warnings* warnings) {
  const fs::path camera_dir = fs::path(root) / "gt_dense_cameras";
  const fs::path image_dir = fs::path(root) / "images";
  for (const fs::path& dir : {camera_dir, image_dir}) {
    if (!fs::is_directory(dir)) ThrowInput(dir.string(), 0, "folder not found");
  }
  const std::string suffix = ".camera";
  std::vector<std::string> camera_names, image_names;
  for (const auto& entry : fs::directory_iterator(camera_dir)) {
    const std::string file = entry.path().filename().string();
    if (entry.is_regular_file() && file.size() > suffix.size() &&
        file.compare(file.size() - suffix.size(), suffix.size(), suffix) == 0) {
      camera_names.push_back(file.substr(0, file.size() - suffix.size()));
    }
  }
  for (const auto& entry : fs::directory_iterator(image_dir)) {
    const std::string file = entry.path().filename().string();
    if (entry.is_regular_file() && file.front() != '.') image_names.push_back(file);
  }
  if (camera_names.empty()) ThrowInput(camera_dir.string(), 0, "no *.camera files");
  const NameJoin join = JoinNames(camera_names, image_names);
  if (!join.only_left.empty()) {
    ThrowInput(root, 0,
               "missing image " + (image_dir / join.only_left.front()).string() + " (" +
                   join.Describe("gt_dense_cameras", "images") + ")");
  }
  if (!join.only_right.empty()) {
    ThrowInput(
        root, 0,
        "image without a ground-truth camera: " + join.Describe("gt_dense_cameras", "images"));
  }

  ImageSet image_set;
  PoseSet poses;
  image_set.image_root = image_dir.string();
  for (const std::string& name : join.both) {  // sorted by name
    const StrechaCamera camera =
        ReadStrechaCamera((camera_dir / (name + suffix)).string(), warnings);
    const auto same =
        std::find(image_set.cameras.begin(), image_set.cameras.end(), camera.intrinsics);
    const int camera_index = static_cast<int>(same - image_set.cameras.begin());
    if (same == image_set.cameras.end()) image_set.cameras.push_back(camera.intrinsics);
    image_set.images.push_back(
        {name, camera.intrinsics.width, camera.intrinsics.height, camera_index});
    poses.world_from_cam[name] = camera.world_from_cam;
  }
  if (images) *images = std::move(image_set);
  if (ground_truth) *ground_truth = std::move(poses);
}

}  // namespace raytime
