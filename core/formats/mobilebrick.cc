#include "core/formats/mobilebrick.h"

#include <algorithm>
#include <filesystem>

#include "core/error.h"

namespace fs = std::filesystem;

namespace raytime {

CaptureRecording ReadMobileBrick(const std::string& path) {
  const fs::path root(path);
  const fs::path images = root / "image";
  if (!fs::is_directory(images) || !fs::is_directory(root / "pose") ||
      !fs::is_directory(root / "intrinsic")) {
    ThrowInput(path, 0,
               "not a MobileBrick sequence: expected the folders image/, intrinsic/ and pose/");
  }
  std::vector<fs::path> image_files;
  for (const auto& entry : fs::directory_iterator(images)) {
    const std::string extension = entry.path().extension().string();
    if (entry.is_regular_file() && (extension == ".jpg" || extension == ".png")) {
      image_files.push_back(entry.path());
    }
  }
  std::sort(image_files.begin(), image_files.end());
  if (image_files.empty()) ThrowInput(images.string(), 0, "no .jpg or .png images");
  CaptureRecording recording;
  recording.format = "mobilebrick";
  recording.image_root = images.string();
  for (const fs::path& image : image_files) {
    const std::string stem = image.stem().string();
    const std::string pose_path = (root / "pose" / (stem + ".txt")).string();
    const std::string intrinsic_path = (root / "intrinsic" / (stem + ".txt")).string();
    recording.files.push_back(pose_path);
    recording.files.push_back(intrinsic_path);
    CaptureFrame frame;
    frame.name = image.filename().string();
    frame.source = intrinsic_path;
    const std::vector<double> k = ReadNumbersFile(intrinsic_path);
    if (k.size() != 9) {
      ThrowInput(intrinsic_path, 0,
                 "expected a 3x3 intrinsic matrix (9 numbers), got " + std::to_string(k.size()));
    }
    frame.K = Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(k.data());
    const std::vector<double> m = ReadNumbersFile(pose_path);
    if (m.size() != 16) {
      ThrowInput(
          pose_path, 0,
          "expected a 4x4 camera-to-world matrix (16 numbers), got " + std::to_string(m.size()));
    }
    const Eigen::Matrix4d pose =
        Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(m.data());
    if ((pose.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-6) {
      ThrowInput(pose_path, 0, "the 4x4 matrix's last row must be 0 0 0 1");
    }
    frame.ground_truth = PoseFromCameraToWorld(pose.topLeftCorner<3, 3>(),
                                               pose.topRightCorner<3, 1>(), pose_path, "");
    recording.frames.push_back(std::move(frame));
  }
  return recording;
}

}  // namespace raytime
