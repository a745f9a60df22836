#include "formats/polycam.h"
#include "core/atomic_file.h"

#include <algorithm>
#include <cmath>
#include <filesystem>

#include "core/error.h"
#include "formats/text_util.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {

CaptureRecording ReadPolycam(const std::string& path) {
  const fs::path keyframes = fs::is_directory(fs::path(path) / "keyframes")
                                 ? fs::path(path) / "keyframes"
                                 : fs::path(path);
  const bool corrected = fs::is_directory(keyframes / "corrected_cameras") &&
                         fs::is_directory(keyframes / "corrected_images");
  const fs::path cameras = keyframes / (corrected ? "corrected_cameras" : "cameras");
  const fs::path images = keyframes / (corrected ? "corrected_images" : "images");
  if (!fs::is_directory(cameras)) {
    ThrowInput(path, 0,
               "not a Polycam raw-data export: expected keyframes/cameras (or "
               "keyframes/corrected_cameras) with one <timestamp>.json per frame");
  }
  std::vector<fs::path> camera_files;
  for (const auto& entry : fs::directory_iterator(cameras)) {
    if (entry.is_regular_file() && entry.path().extension() == ".json") {
      camera_files.push_back(entry.path());
    }
  }
  std::sort(camera_files.begin(), camera_files.end());
  if (camera_files.empty()) ThrowInput(cameras.string(), 0, "no <timestamp>.json camera files");

  CaptureRecording recording;
  recording.format = "polycam";
  recording.image_root = images.string();
  for (const fs::path& file : camera_files) {
    const std::string source = file.string();
    recording.files.push_back(source);
    const json camera = ReadJsonFile(source);
    if (!camera.is_object()) ThrowInput(source, 0, "expected a JSON object");
    CaptureFrame frame;
    frame.source = source;
    frame.name = file.stem().string() + ".jpg";
    frame.has_image = PathExists((images / frame.name).string());
    Eigen::Matrix3d rotation;
    Eigen::Vector3d centre;
    for (int r = 0; r < 3; ++r) {
      for (int c = 0; c < 4; ++c) {
        const double value =
            JsonNumber(camera, "t_" + std::to_string(r) + std::to_string(c), source, "");
        if (c < 3) {
          rotation(r, c) = value;
        } else {
          centre[r] = value;
        }
      }
    }
    frame.capture = PoseFromArkitCameraToWorld(rotation, centre, source, "");
    Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
    K(0, 0) = JsonNumber(camera, "fx", source, "");
    K(1, 1) = JsonNumber(camera, "fy", source, "");
    K(0, 2) = JsonNumber(camera, "cx", source, "");
    K(1, 2) = JsonNumber(camera, "cy", source, "");
    frame.K = FromArkitIntrinsics(K);
    frame.width = PixelSize(JsonNumber(camera, "width", source, ""), source, 0, "\"width\"");
    frame.height = PixelSize(JsonNumber(camera, "height", source, ""), source, 0, "\"height\"");
    // The file name is the timestamp in microseconds (PolyCam/polyform README).
    int64_t microseconds = 0;
    if (camera.contains("timestamp") && camera["timestamp"].is_number()) {
      frame.time_s = camera["timestamp"].get<double>() * 1e-6;
    } else if (text::ParseInt(file.stem().string(), &microseconds)) {
      frame.time_s = static_cast<double>(microseconds) * 1e-6;
    }
    recording.frames.push_back(std::move(frame));
  }
  return recording;
}

}  // namespace raytime
