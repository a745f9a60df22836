#include "formats/record3d.h"
#include "core/atomic_file.h"

#include <cmath>
#include <filesystem>

#include "core/error.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {

CaptureRecording ReadRecord3d(const std::string& path) {
  const fs::path root = fs::is_directory(path) ? fs::path(path) : fs::path(path).parent_path();
  const std::string metadata_path =
      fs::is_directory(path) ? (root / "metadata.json").string() : path;
  const json metadata = ReadJsonFile(metadata_path);
  if (!metadata.is_object()) ThrowInput(metadata_path, 0, "expected a JSON object");

  CaptureRecording recording;
  recording.format = "record3d";
  recording.image_root = (root / "rgb").string();
  recording.files.push_back(metadata_path);

  const int width =
      PixelSize(JsonNumber(metadata, "w", metadata_path, ""), metadata_path, 0, "\"w\"");
  const int height =
      PixelSize(JsonNumber(metadata, "h", metadata_path, ""), metadata_path, 0, "\"h\"");
  const std::vector<double> k = JsonNumbers(metadata, "K", 9, metadata_path, "");
  const Eigen::Matrix3d shared_K = Eigen::Map<const Eigen::Matrix3d>(k.data());  // column-major

  if (!metadata.contains("poses") || !metadata["poses"].is_array() || metadata["poses"].empty()) {
    ThrowInput(metadata_path, 0,
               "expected a non-empty \"poses\" array of [qx, qy, qz, qw, tx, ty, tz]");
  }
  const json& poses = metadata["poses"];
  const size_t n = poses.size();
  const auto per_frame = [&](const char* key) -> const json* {
    if (!metadata.contains(key)) return nullptr;
    const json& list = metadata[key];
    if (!list.is_array() || list.size() != n) {
      ThrowInput(metadata_path, 0,
                 std::string("\"") + key + "\" must be an array with one entry per pose (" +
                     std::to_string(n) + "), got " +
                     (list.is_array() ? std::to_string(list.size()) + " entries"
                                      : std::string(list.type_name())));
    }
    return &list;
  };
  const json* coefficients = per_frame("perFrameIntrinsicCoeffs");
  const json* timestamps = per_frame("frameTimestamps");

  for (size_t i = 0; i < n; ++i) {
    const std::string where = "frame " + std::to_string(i);
    CaptureFrame frame;
    frame.source = metadata_path;
    frame.name = std::to_string(i) + ".jpg";
    if (!PathExists((root / "rgb" / frame.name).string()) &&
        fs::exists(root / "rgb" / (std::to_string(i) + ".png"))) {
      frame.name = std::to_string(i) + ".png";
    }
    frame.has_image = PathExists((root / "rgb" / frame.name).string());
    const json wrapper = {{"pose", poses[i]}};
    const std::vector<double> p =
        JsonNumbers(wrapper, "pose", 7, metadata_path, "poses[" + std::to_string(i) + "]");
    Eigen::Quaterniond q(p[3], p[0], p[1], p[2]);
    if (std::abs(q.norm() - 1.0) > 0.01) {
      ThrowInput(metadata_path, 0,
                 "poses[" + std::to_string(i) + "]: quaternion [qx, qy, qz, qw] has norm " +
                     std::to_string(q.norm()) + ", not 1");
    }
    frame.capture = PoseFromArkitCameraToWorld(
        q.normalized().toRotationMatrix(), Eigen::Vector3d(p[4], p[5], p[6]), metadata_path, where);
    Eigen::Matrix3d K = shared_K;
    if (coefficients) {
      const json entry = {{"c", (*coefficients)[i]}};
      const std::vector<double> c = JsonNumbers(
          entry, "c", 4, metadata_path, "perFrameIntrinsicCoeffs[" + std::to_string(i) + "]");
      K(0, 0) = c[0];
      K(1, 1) = c[1];
      K(0, 2) = c[2];
      K(1, 2) = c[3];
    }
    frame.K = FromArkitIntrinsics(K);
    frame.width = width;
    frame.height = height;
    if (timestamps) {
      const json entry = {{"t", (*timestamps)[i]}};
      frame.time_s =
          JsonNumber(entry, "t", metadata_path, "frameTimestamps[" + std::to_string(i) + "]");
    }
    recording.frames.push_back(std::move(frame));
  }
  return recording;
}

}  // namespace raytime
