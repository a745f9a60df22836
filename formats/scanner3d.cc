#include "formats/scanner3d.h"
#include "core/atomic_file.h"

#include <algorithm>
#include <filesystem>

#include "core/error.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {

CaptureRecording ReadScanner3d(const std::string& path) {
  if (!fs::is_directory(path)) ThrowInput(path, 0, "3D Scanner App export folder not found");
  std::vector<fs::path> frame_files;
  for (const auto& entry : fs::directory_iterator(path)) {
    const std::string name = entry.path().filename().string();
    if (entry.is_regular_file() && name.rfind("frame_", 0) == 0 &&
        entry.path().extension() == ".json") {
      frame_files.push_back(entry.path());
    }
  }
  std::sort(frame_files.begin(), frame_files.end());
  if (frame_files.empty()) {
    ThrowInput(path, 0, "no frame_NNNNN.json files (not a 3D Scanner App \"All Data\" export)");
  }
  CaptureRecording recording;
  recording.format = "scanner3d";
  recording.image_root = path;
  for (const fs::path& file : frame_files) {
    const std::string source = file.string();
    recording.files.push_back(source);
    const json frame_json = ReadJsonFile(source);
    if (!frame_json.is_object()) ThrowInput(source, 0, "expected a JSON object");
    CaptureFrame frame;
    frame.source = source;
    frame.name = file.stem().string() + ".jpg";
    frame.has_image = PathExists((fs::path(path) / frame.name).string());
    const std::vector<double> m = JsonNumbers(frame_json, "cameraPoseARFrame", 16, source, "");
    const Eigen::Matrix4d pose =
        Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(m.data());
    if ((pose.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-3) {
      ThrowInput(source, 0,
                 "cameraPoseARFrame must be a row-major 4x4 matrix whose last row is 0 0 0 1");
    }
    frame.capture = PoseFromArkitCameraToWorld(pose.topLeftCorner<3, 3>(),
                                               pose.topRightCorner<3, 1>(), source, "");
    const std::vector<double> k = JsonNumbers(frame_json, "intrinsics", 9, source, "");
    frame.K = FromArkitIntrinsics(
        Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(k.data()));
    if (frame_json.contains("time")) frame.time_s = JsonNumber(frame_json, "time", source, "");
    recording.frames.push_back(std::move(frame));
  }
  return recording;
}

}  // namespace raytime
