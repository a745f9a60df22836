#include "formats/stray.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/intrinsics.h"
#include "core/statistics.h"
#include "formats/capture.h"
#include "formats/text_util.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

std::string FrameName(int number) {
  char name[32];
  std::snprintf(name, sizeof(name), "frame_%06d.jpg", number);
  return name;
}

std::vector<std::string_view> SplitCommas(std::string_view line) {
  std::vector<std::string_view> fields;
  size_t start = 0;
  while (true) {
    const size_t comma = line.find(',', start);
    fields.push_back(text::Trim(line.substr(start, comma - start)));
    if (comma == std::string_view::npos) break;
    start = comma + 1;
  }
  return fields;
}

Eigen::Matrix3d ReadCameraMatrix(const std::string& path) {
  if (!fs::is_regular_file(path)) ThrowInput(path, 0, "file not found (the 3x3 camera matrix)");
  const std::string contents = ReadTextFile(path);
  Eigen::Matrix3d K;
  int row = 0;
  const std::vector<std::string_view> lines = text::SplitLines(contents);
  for (size_t i = 0; i < lines.size(); ++i) {
    if (text::Trim(lines[i]).empty()) continue;
    const int line = static_cast<int>(i) + 1;
    if (row == 3) ThrowInput(path, line, "more than 3 rows (expected a 3x3 matrix)");
    const std::vector<std::string_view> fields = SplitCommas(lines[i]);
    if (fields.size() != 3) {
      ThrowInput(path, line,
                 "expected 3 comma-separated numbers, got " + std::to_string(fields.size()));
    }
    for (int c = 0; c < 3; ++c) {
      if (!text::ParseDouble(fields[c], &K(row, c))) {
        ThrowInput(path, line, "not a finite number: '" + std::string(fields[c]) + "'");
      }
    }
    ++row;
  }
  if (row != 3) ThrowInput(path, 0, "expected 3 rows of 3 numbers, got " + std::to_string(row));
  return K;
}

// The trajectory of odometry.csv and each pose's frame number.
void ReadOdometry(const std::string& path, std::vector<StampedPose>* trajectory,
                  std::vector<int>* frames) {
  if (!fs::is_regular_file(path)) ThrowInput(path, 0, "file not found (the camera poses)");
  const std::string contents = ReadTextFile(path);
  const std::vector<std::string_view> lines = text::SplitLines(contents);
  static const std::vector<std::string> kColumns = {"timestamp", "frame", "x",  "y", "z",
                                                    "qx",        "qy",    "qz", "qw"};
  const std::string expected = "header 'timestamp, frame, x, y, z, qx, qy, qz, qw'";
  if (lines.empty()) ThrowInput(path, 1, "empty file; expected the " + expected);
  std::map<std::string, size_t> column;
  const std::vector<std::string_view> header = SplitCommas(lines[0]);
  for (size_t i = 0; i < header.size(); ++i) column[std::string(header[i])] = i;
  for (const std::string& name : kColumns) {
    if (!column.count(name))
      ThrowInput(path, 1, "no column '" + name + "'; expected the " + expected);
  }
  std::map<double, int> line_of_time;
  for (size_t i = 1; i < lines.size(); ++i) {
    if (text::Trim(lines[i]).empty()) continue;
    const int line = static_cast<int>(i) + 1;
    const std::vector<std::string_view> fields = SplitCommas(lines[i]);
    if (fields.size() != header.size()) {
      ThrowInput(path, line,
                 "expected " + std::to_string(header.size()) + " comma-separated values, got " +
                     std::to_string(fields.size()));
    }
    std::map<std::string, double> value;
    for (const std::string& name : kColumns) {
      if (!text::ParseDouble(fields[column[name]], &value[name])) {
        ThrowInput(path, line,
                   "column '" + name + "' is not a finite number: '" +
                       std::string(fields[column[name]]) + "'");
      }
    }
    const double number = value["frame"];
    if (number < 0 || number != std::floor(number) || number > 1e9) {
      ThrowInput(path, line, "column 'frame' must be a video frame number (a whole number >= 0)");
    }
    const Eigen::Quaterniond q(value["qw"], value["qx"], value["qy"], value["qz"]);
    if (std::abs(q.norm() - 1.0) > 0.01) {
      ThrowInput(path, line,
                 "quaternion (qx, qy, qz, qw) has norm " + std::to_string(q.norm()) + ", not 1");
    }
    const auto [previous, inserted] = line_of_time.emplace(value["timestamp"], line);
    if (!inserted) {
      ThrowInput(path, line,
                 "timestamp " + text::FormatDouble(value["timestamp"]) + " repeats line " +
                     std::to_string(previous->second));
    }
    trajectory->push_back(
        {value["timestamp"],
         PoseFromCameraToWorld(q.normalized().toRotationMatrix(),
                               Eigen::Vector3d(value["x"], value["y"], value["z"]), path,
                               "line " + std::to_string(line))});
    frames->push_back(static_cast<int>(number));
  }
  if (trajectory->empty()) ThrowInput(path, 0, "no poses below the header");
}

}  // namespace

Dataset ReadStray(const std::string& root) {
  Dataset dataset;
  CaptureVideo video;
  video.path = (fs::path(root) / "rgb.mp4").string();
  if (!fs::is_regular_file(video.path)) {
    ThrowInput(video.path, 0, "video not found (a Stray Scanner export has rgb.mp4)");
  }
  video.intrinsics_file = (fs::path(root) / "camera_matrix.csv").string();
  video.K = FromArkitIntrinsics(ReadCameraMatrix(video.intrinsics_file));
  video.trajectory_file = (fs::path(root) / "odometry.csv").string();
  ReadOdometry(video.trajectory_file, &video.trajectory, &video.trajectory_frames);
  dataset.files = {video.path, video.intrinsics_file, video.trajectory_file};
  dataset.video = std::move(video);
  return dataset;
}

PoseSet ReadStrayPoses(const std::string& path) {
  const std::string file =
      fs::is_directory(path) ? (fs::path(path) / "odometry.csv").string() : path;
  std::vector<StampedPose> trajectory;
  std::vector<int> frames;
  ReadOdometry(file, &trajectory, &frames);
  PoseSet poses;
  for (size_t i = 0; i < trajectory.size(); ++i) {
    poses.world_from_cam.emplace(FrameName(frames[i]), trajectory[i].world_from_cam);
  }
  return poses;
}

void AttachVideoFrames(const ImageSet& frames, const std::vector<DecodedFrame>& decoded,
                       int capture_width, const TimestampJoinOptions& options, Dataset* dataset) {
  const CaptureVideo& video = *dataset->video;
  if (frames.images.size() != decoded.size() || frames.cameras.empty()) {
    throw std::invalid_argument("AttachVideoFrames: one decoded frame per image expected");
  }
  const int width = frames.cameras.front().width, height = frames.cameras.front().height;

  // Intrinsics at the decoded size.
  Eigen::Matrix3d K = video.K;
  const double rx = 2.0 * (K(0, 2) + 0.5) / width, ry = 2.0 * (K(1, 2) + 0.5) / height;
  double scale = 1.0;
  bool estimated = false;
  if (capture_width > 0) {
    scale = double(width) / capture_width;
  } else if (std::abs(rx - 1.0) > 0.1 || std::abs(ry - 1.0) > 0.1) {
    // The principal point of a rescaled copy lies at the same fraction of both sides (rx = ry > 0).
    if (!(rx > 0 && ry > 0 && std::abs(rx / ry - 1.0) <= 0.05)) {
      ThrowInput(video.intrinsics_file, 0,
                 "the principal point (" + text::FormatDouble(K(0, 2)) + ", " +
                     text::FormatDouble(K(1, 2)) + ") is not near the centre of the decoded " +
                     std::to_string(width) + "x" + std::to_string(height) +
                     " frames, nor of a rescaled copy of them; set dataset.capture_width");
    }
    scale = 2.0 / (rx + ry);
    estimated = true;
  }
  if (scale != 1.0) {
    // One scale for both axes (the capture's frames have the decoded frames' aspect): focal lengths
    // multiply, the principal point keeps its place measured from the image's corner. Not through
    // ScaleK with the capture size rounded to whole pixels: a size that rounds to 0 divided by 0.
    K(0, 0) *= scale;
    K(0, 1) *= scale;
    K(1, 1) *= scale;
    K(0, 2) = (K(0, 2) + 0.5) * scale - 0.5;
    K(1, 2) = (K(1, 2) + 0.5) * scale - 0.5;
    char from[64];
    std::snprintf(from, sizeof(from), "%.0fx%.0f", width / scale, height / scale);
    if (!K.allFinite()) {
      ThrowInput(video.intrinsics_file, 0,
                 "the intrinsics scaled by " + text::FormatDouble(scale) + " from about " + from +
                     " pixels to the decoded " + std::to_string(width) + "x" +
                     std::to_string(height) + " frames are not finite");
    }
    Warning warning{"intrinsics_rescaled",
                    video.intrinsics_file + " is for about " + from +
                        " pixels but the video decodes to " + std::to_string(width) + "x" +
                        std::to_string(height) + ": focal lengths and principal point scaled by " +
                        text::FormatDouble(scale) +
                        (estimated ? " (estimated from the principal point; set "
                                     "dataset.capture_width for the exact ratio)"
                                   : ""),
                    {},
                    {},
                    {{"scale", scale}, {"estimated", estimated}, {"file", video.intrinsics_file}}};
    dataset->warnings.push_back(warning);
  }
  const CameraIntrinsics camera =
      IntrinsicsFromK(K, width, height, video.intrinsics_file, "video", &dataset->warnings);

  // The video's clock on the trajectory's: the median offset over poses naming a decoded frame.
  std::map<int, double> video_time;
  for (const DecodedFrame& frame : decoded) video_time[frame.number] = frame.time_s;
  std::vector<double> offsets;
  for (size_t i = 0; i < video.trajectory.size(); ++i) {
    const auto it = video_time.find(video.trajectory_frames[i]);
    if (it != video_time.end()) offsets.push_back(video.trajectory[i].time_s - it->second);
  }
  if (offsets.empty()) {
    ThrowInput(video.trajectory_file, 0,
               "no pose names a decoded video frame (column 'frame'), so the video's clock cannot "
               "be matched to the poses' (" +
                   std::to_string(decoded.size()) + " frames decoded, " +
                   std::to_string(video.trajectory.size()) + " poses)");
  }
  const double offset = Median(offsets, 0.0);
  std::map<std::string, double> frame_times;
  for (size_t i = 0; i < decoded.size(); ++i) {
    frame_times[frames.images[i].name] = decoded[i].time_s + offset;
  }
  const TimestampJoin join = JoinByTimestamp(frame_times, video.trajectory, options);
  if (!join.left_out.empty()) {
    dataset->warnings.push_back(
        UnjoinedFramesWarning(join, fs::path(video.trajectory_file).filename().string(), options));
  }
  if (join.poses.size() == 0) {
    ThrowInput(video.trajectory_file, 0,
               "no decoded frame lies within dataset.max_time_gap_s of its poses");
  }
  dataset->images = ImageSet();
  dataset->images.image_root = frames.image_root;
  dataset->images.cameras = {camera};
  for (const ImageInfo& image : frames.images) {
    if (!join.poses.Has(image.name)) continue;
    dataset->images.images.push_back({image.name, width, height, 0});
    dataset->timestamps[image.name] = frame_times[image.name];
  }
  dataset->capture = join.poses;
}

}  // namespace raytime
