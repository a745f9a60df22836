#include "formats/mobilebrick.h"

#include <Eigen/QR>
#include <algorithm>
#include <cmath>
#include <filesystem>

#include "core/error.h"
#include "formats/npz.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

// The camera of an IDR-style projection P = K [R | t] (world to image, 3x4): R from the RQ
// decomposition of P's left 3x3 with K's diagonal positive, the centre -M^-1 p4.
Rigid3 PoseOfProjection(const Eigen::Matrix<double, 3, 4>& P, const std::string& path,
                        const std::string& where) {
  const Eigen::Matrix3d M = P.leftCols<3>();
  if (!(std::abs(M.determinant()) > 0)) ThrowInput(path, 0, where + ": singular projection");
  // RQ through QR of the row-reversed transpose: M = K R.
  const Eigen::Matrix3d flip = Eigen::Matrix3d::Identity().rowwise().reverse();
  const Eigen::HouseholderQR<Eigen::Matrix3d> qr((flip * M).transpose());
  const Eigen::Matrix3d q = qr.householderQ();
  const Eigen::Matrix3d r = qr.matrixQR().triangularView<Eigen::Upper>();
  Eigen::Matrix3d K = flip * r.transpose() * flip;
  Eigen::Matrix3d R = flip * q.transpose();
  const Eigen::Vector3d signs(K(0, 0) < 0 ? -1 : 1, K(1, 1) < 0 ? -1 : 1, K(2, 2) < 0 ? -1 : 1);
  K = K * signs.asDiagonal();
  R = signs.asDiagonal() * R;
  if (R.determinant() < 0) R = -R;  // P is projective: -P is the same camera
  const Eigen::Vector3d centre = -M.inverse() * P.col(3);
  return PoseFromCameraToWorld(R.transpose(), centre, path, where);
}

}  // namespace

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
  // The ARKit prior as PoRF distributes it (cameras_arkit.npz beside the sequence's files):
  // world_mat_<i> = K [R | t] of image i in name order; scale_mat_<i> (a normalization) ignored.
  const fs::path arkit = root / "cameras_arkit.npz";
  if (fs::exists(arkit)) {
    recording.files.push_back(arkit.string());
    const auto arrays = ReadNpz(arkit.string());
    for (size_t i = 0; i < recording.frames.size(); ++i) {
      const std::string key = "world_mat_" + std::to_string(i);
      const auto it = arrays.find(key);
      if (it == arrays.end()) {
        ThrowInput(arkit.string(), 0,
                   "no " + key + " for image " + recording.frames[i].name +
                       " (one world_mat_<i> "
                       "per image of image/, in name order, expected)");
      }
      const Eigen::MatrixXd& m = it->second;
      if (!((m.rows() == 4 || m.rows() == 3) && m.cols() == 4)) {
        ThrowInput(arkit.string(), 0, key + " must be 3x4 or 4x4");
      }
      recording.frames[i].capture = PoseOfProjection(m.topRows<3>(), arkit.string(), key);
    }
  }
  return recording;
}

}  // namespace raytime
