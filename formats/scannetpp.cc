#include "formats/scannetpp.h"
#include "core/atomic_file.h"

#include <algorithm>
#include <filesystem>

#include "core/error.h"
#include "core/statistics.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {

namespace {

// A rows x rows matrix given as nested rows or as rows * rows numbers (row-major).
Eigen::MatrixXd JsonMatrix(const json& entry, const std::string& key, int rows,
                           const std::string& path, const std::string& where) {
  if (!entry.contains(key)) ThrowInput(path, 0, where + ": missing \"" + key + "\"");
  std::vector<double> values;
  const json& value = entry[key];
  if (value.is_array() && value.size() == static_cast<size_t>(rows) && value[0].is_array()) {
    for (int r = 0; r < rows; ++r) {
      const json row = {{"row", value[r]}};
      const std::vector<double> v =
          JsonNumbers(row, "row", rows, path, where + ": " + key + "[" + std::to_string(r) + "]");
      values.insert(values.end(), v.begin(), v.end());
    }
  } else {
    values = JsonNumbers(entry, key, rows * rows, path, where);
  }
  Eigen::MatrixXd m(rows, rows);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < rows; ++c) m(r, c) = values[r * rows + c];
  }
  return m;
}

Rigid3 PoseOf(const Eigen::MatrixXd& m, const std::string& path, const std::string& where) {
  if ((m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-6) {
    ThrowInput(path, 0, where + ": a 4x4 pose's last row must be 0 0 0 1");
  }
  return PoseFromCameraToWorld(m.topLeftCorner(3, 3), m.topRightCorner(3, 1), path, where);
}

// Median disagreement (radians) between the relative rotations of consecutive frames in `a`
// (turned to OpenCV axes by `flip`) and in `b`.
double RelativeRotationDisagreement(const std::vector<Rigid3>& a, const std::vector<Rigid3>& b,
                                    const Eigen::Matrix3d& flip) {
  std::vector<double> angles;
  for (size_t i = 1; i < a.size(); ++i) {
    const Eigen::Matrix3d ra =
        flip * a[i - 1].RotationMatrix().transpose() * a[i].RotationMatrix() * flip;
    const Eigen::Matrix3d rb = b[i - 1].RotationMatrix().transpose() * b[i].RotationMatrix();
    angles.push_back(RotationAngle(Eigen::Matrix3d(ra.transpose() * rb)));
  }
  return Median(angles, 0.0);
}

}  // namespace

CaptureRecording ReadScanNetPPIphone(const std::string& path) {
  const fs::path iphone =
      fs::is_directory(fs::path(path) / "iphone") ? fs::path(path) / "iphone" : fs::path(path);
  const std::string json_path = (iphone / "pose_intrinsic_imu.json").string();
  const fs::path rgb = iphone / "rgb";
  if (!fs::is_directory(rgb)) {
    ThrowInput(
        rgb.string(), 0,
        "no extracted frames: extract iphone/rgb.mkv to iphone/rgb/frame_NNNNNN.jpg with the "
        "ScanNet++ toolkit (python -m iphone.prepare_iphone_data)");
  }
  const json top = ReadJsonFile(json_path);
  if (!top.is_object() || top.empty()) {
    ThrowInput(json_path, 0, "expected an object keyed by frame_NNNNNN");
  }
  CaptureRecording recording;
  recording.format = "scannetpp_iphone";
  recording.image_root = rgb.string();
  recording.files.push_back(json_path);
  std::vector<Rigid3> arkit, aligned;  // of the frames that have both, in key order
  for (const auto& [key, entry] : top.items()) {
    const std::string where = "frame " + key;
    if (!entry.is_object()) ThrowInput(json_path, 0, where + ": expected an object");
    CaptureFrame frame;
    frame.source = json_path;
    frame.name = key + ".jpg";
    frame.has_image = PathExists((rgb / frame.name).string());
    frame.K = FromArkitIntrinsics(JsonMatrix(entry, "intrinsic", 3, json_path, where));
    if (entry.contains("pose"))
      frame.capture = PoseOf(JsonMatrix(entry, "pose", 4, json_path, where), json_path, where);
    if (entry.contains("aligned_pose")) {
      frame.ground_truth =
          PoseOf(JsonMatrix(entry, "aligned_pose", 4, json_path, where), json_path, where);
    }
    if (entry.contains("timestamp"))
      frame.time_s = JsonNumber(entry, "timestamp", json_path, where);
    if (frame.capture && frame.ground_truth) {
      arkit.push_back(*frame.capture);
      aligned.push_back(*frame.ground_truth);
    }
    recording.frames.push_back(std::move(frame));
  }
  // ARKit camera axes for `pose` when they explain the motion clearly better than OpenCV's.
  if (arkit.size() >= 3 &&
      RelativeRotationDisagreement(arkit, aligned, ArkitFromOpenCvAxes()) <
          0.5 * RelativeRotationDisagreement(arkit, aligned, Eigen::Matrix3d::Identity())) {
    for (CaptureFrame& frame : recording.frames) {
      if (!frame.capture) continue;
      frame.capture->rotation =
          Eigen::Quaterniond(frame.capture->RotationMatrix() * ArkitFromOpenCvAxes());
    }
  }
  std::sort(recording.frames.begin(), recording.frames.end(),
            [](const CaptureFrame& a, const CaptureFrame& b) { return a.name < b.name; });
  return recording;
}

}  // namespace raytime
