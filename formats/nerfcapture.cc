#include "formats/nerfcapture.h"
#include "core/atomic_file.h"

#include <cmath>
#include <filesystem>

#include "core/error.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {

namespace {

// A frame's value of `key`, or the shared one at the top level.
double FrameNumber(const json& top, const json& frame, const char* key, const std::string& path,
                   const std::string& where) {
  if (frame.contains(key)) return JsonNumber(frame, key, path, where);
  if (top.contains(key)) return JsonNumber(top, key, path, "");
  ThrowInput(path, 0, where + ": missing \"" + key + "\" (neither in the frame nor shared)");
}

}  // namespace

CaptureRecording ReadNerfCapture(const std::string& path) {
  const json top = ReadJsonFile(path);
  if (!top.is_object() || !top.contains("frames") || !top["frames"].is_array() ||
      top["frames"].empty()) {
    ThrowInput(path, 0, "expected a JSON object with a non-empty \"frames\" array");
  }
  const fs::path root = fs::path(path).parent_path();
  CaptureRecording recording;
  recording.format = "nerfcapture";
  recording.files.push_back(path);
  std::string directory;  // shared by every file_path, e.g. "images"
  for (size_t i = 0; i < top["frames"].size(); ++i) {
    const json& entry = top["frames"][i];
    const std::string where = "frame " + std::to_string(i);
    if (!entry.is_object() || !entry.contains("file_path") || !entry["file_path"].is_string()) {
      ThrowInput(path, 0, where + ": missing \"file_path\" (a string)");
    }
    std::string file_path = entry["file_path"].get<std::string>();
    if (file_path.rfind("./", 0) == 0) file_path.erase(0, 2);
    const std::string parent = fs::path(file_path).parent_path().string();
    if (i == 0) directory = parent;
    if (parent != directory) {
      ThrowInput(path, 0,
                 where + ": file_path " + file_path + " is not in " + directory +
                     "/ like the first frame's");
    }
    CaptureFrame frame;
    frame.source = path;
    frame.name = fs::path(file_path).filename().string();
    // The app writes "images/<n>" for the file images/<n>.png.
    const fs::path folder = root / directory;
    if (!PathExists((folder / frame.name).string())) {
      for (const char* extension : {".png", ".jpg", ".jpeg"}) {
        if (PathExists((folder / (frame.name + extension)).string())) {
          frame.name += extension;
          break;
        }
      }
    }
    frame.has_image = PathExists((folder / frame.name).string());
    const std::vector<double> rows = [&] {
      if (!entry.contains("transform_matrix") || !entry["transform_matrix"].is_array() ||
          entry["transform_matrix"].size() != 4) {
        ThrowInput(path, 0, where + ": transform_matrix must be 4 rows of 4 numbers");
      }
      std::vector<double> values;
      for (size_t r = 0; r < 4; ++r) {
        const json row = {{"row", entry["transform_matrix"][r]}};
        const std::vector<double> v = JsonNumbers(
            row, "row", 4, path, where + ": transform_matrix[" + std::to_string(r) + "]");
        values.insert(values.end(), v.begin(), v.end());
      }
      return values;
    }();
    const Eigen::Matrix4d m =
        Eigen::Map<const Eigen::Matrix<double, 4, 4, Eigen::RowMajor>>(rows.data());
    if ((m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-3) {
      ThrowInput(path, 0, where + ": transform_matrix last row must be 0 0 0 1");
    }
    frame.capture =
        PoseFromArkitCameraToWorld(m.topLeftCorner<3, 3>(), m.topRightCorner<3, 1>(), path, where);
    Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
    K(0, 0) = FrameNumber(top, entry, "fl_x", path, where);
    K(1, 1) = FrameNumber(top, entry, "fl_y", path, where);
    K(0, 2) = FrameNumber(top, entry, "cx", path, where);
    K(1, 2) = FrameNumber(top, entry, "cy", path, where);
    frame.K = FromArkitIntrinsics(K);
    frame.width = PixelSize(FrameNumber(top, entry, "w", path, where), path, 0, where + ": \"w\"");
    frame.height = PixelSize(FrameNumber(top, entry, "h", path, where), path, 0, where + ": \"h\"");
    if (entry.contains("timestamp")) frame.time_s = JsonNumber(entry, "timestamp", path, where);
    recording.frames.push_back(std::move(frame));
  }
  recording.image_root = (root / directory).lexically_normal().string();
  while (recording.image_root.size() > 1 && recording.image_root.back() == '/') {
    recording.image_root.pop_back();
  }
  return recording;
}

}  // namespace raytime
