#include "formats/arkitscenes.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>

#include "core/atomic_file.h"
#include "core/error.h"
#include "formats/text_util.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

// The time in a name "<video>_<t>": the part after the last '_'.
bool TimeOfStem(const std::string& stem, double* time_s) {
  const size_t underscore = stem.rfind('_');
  return underscore != std::string::npos &&
         text::ParseDouble(std::string_view(stem).substr(underscore + 1), time_s);
}

std::vector<StampedPose> ReadTraj(const std::string& path) {
  if (!fs::is_regular_file(path)) ThrowInput(path, 0, "trajectory file not found");
  const std::string contents = ReadTextFile(path);
  const auto lines = text::SplitLines(contents);
  std::vector<StampedPose> trajectory;
  std::map<double, int> line_of_time;
  for (size_t k = 0; k < lines.size(); ++k) {
    const auto tokens = text::SplitWhitespace(lines[k]);
    if (tokens.empty()) continue;
    const int line = static_cast<int>(k) + 1;
    if (tokens.size() != 7) {
      ThrowInput(path, line,
                 "expected 7 numbers (timestamp, axis-angle rotation (3), translation (3)), got " +
                     std::to_string(tokens.size()));
    }
    double v[7];
    for (int i = 0; i < 7; ++i) {
      if (!text::ParseDouble(tokens[i], &v[i])) {
        ThrowInput(path, line, "'" + std::string(tokens[i]) + "' is not a finite number");
      }
    }
    if (!line_of_time.emplace(v[0], line).second) {
      ThrowInput(path, line, "timestamp repeats line " + std::to_string(line_of_time[v[0]]));
    }
    // World-to-camera: x_cam = R x_world + t.
    const Eigen::Matrix3d cam_from_world = ExpSO3(Eigen::Vector3d(v[1], v[2], v[3]));
    const Eigen::Vector3d centre =
        -(cam_from_world.transpose() * Eigen::Vector3d(v[4], v[5], v[6]));
    // Finite numbers can still overflow: the angle of an axis-angle of 1e200 is infinite.
    if (!cam_from_world.allFinite() || !centre.allFinite()) {
      ThrowInput(path, line,
                 "the pose is not finite once converted (an axis-angle or translation too large "
                 "for a double)");
    }
    trajectory.push_back({v[0], Rigid3(Eigen::Quaterniond(cam_from_world.transpose()), centre)});
  }
  if (trajectory.empty()) ThrowInput(path, 0, "no poses");
  return trajectory;
}

}  // namespace

CaptureRecording ReadArkitScenes(const std::string& path, const TimestampJoinOptions& options) {
  fs::path root(path);
  if (!fs::exists(root / "lowres_wide.traj")) {
    const fs::path frames = root / (root.filename().string() + "_frames");
    if (fs::exists(frames / "lowres_wide.traj")) root = frames;
  }
  const std::string traj_path = (root / "lowres_wide.traj").string();
  const fs::path images = root / "lowres_wide";
  const fs::path intrinsics = root / "lowres_wide_intrinsics";
  if (!fs::exists(traj_path) || !fs::is_directory(images) || !fs::is_directory(intrinsics)) {
    ThrowInput(path, 0,
               "not an ARKitScenes video folder: expected lowres_wide.traj, lowres_wide/ and "
               "lowres_wide_intrinsics/ (here or in <video>_frames/)");
  }
  CaptureRecording recording;
  recording.format = "arkitscenes";
  recording.image_root = images.string();
  recording.files.push_back(traj_path);
  const std::vector<StampedPose> trajectory = ReadTraj(traj_path);

  // Intrinsics files by time (names may differ from the image's in the last digit).
  std::map<double, fs::path> pincams;
  for (const auto& entry : fs::directory_iterator(intrinsics)) {
    double time = 0;
    if (entry.path().extension() == ".pincam" && TimeOfStem(entry.path().stem().string(), &time)) {
      pincams[time] = entry.path();
    }
  }
  std::map<std::string, double> frame_times;
  std::map<std::string, fs::path> frame_pincam;
  for (const auto& entry : fs::directory_iterator(images)) {
    double time = 0;
    if (entry.path().extension() != ".png" || !TimeOfStem(entry.path().stem().string(), &time)) {
      continue;
    }
    const std::string name = entry.path().filename().string();
    auto nearest = pincams.lower_bound(time - 0.0015);
    if (nearest == pincams.end() || std::abs(nearest->first - time) > 0.0015) {
      ThrowInput(entry.path().string(), 0,
                 "no .pincam in " + intrinsics.string() + " within 1.5 ms of this frame's time");
    }
    frame_times[name] = time;
    frame_pincam[name] = nearest->second;
  }
  if (frame_times.empty()) ThrowInput(images.string(), 0, "no <video>_<timestamp>.png frames");
  const TimestampJoin join = JoinByTimestamp(frame_times, trajectory, options);
  if (!join.left_out.empty()) {
    recording.warnings.push_back(UnjoinedFramesWarning(join, "lowres_wide.traj", options));
  }
  for (const auto& [name, pose] : join.poses.world_from_cam) {
    const std::string pincam = frame_pincam[name].string();
    const std::vector<double> v = ReadNumbersFile(pincam);
    if (v.size() != 6) {
      ThrowInput(pincam, 0,
                 "expected 6 numbers: width height fx fy cx cy, got " + std::to_string(v.size()));
    }
    recording.files.push_back(pincam);
    CaptureFrame frame;
    frame.name = name;
    frame.source = pincam;
    frame.ground_truth = pose;
    Eigen::Matrix3d K;
    K << v[2], 0, v[4], 0, v[3], v[5], 0, 0, 1;
    frame.K = K;
    frame.width = PixelSize(v[0], pincam, 0, "width (the first number)");
    frame.height = PixelSize(v[1], pincam, 0, "height (the second number)");
    frame.time_s = frame_times[name];
    recording.frames.push_back(std::move(frame));
  }
  std::sort(recording.files.begin(), recording.files.end());
  return recording;
}

}  // namespace raytime
