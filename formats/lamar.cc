#include "formats/lamar.h"

#include <filesystem>
#include <map>
#include <set>

#include "core/atomic_file.h"
#include "core/error.h"
#include "formats/text_util.h"

namespace fs = std::filesystem;

namespace raytime {

namespace {

struct Row {
  int line = 0;
  std::vector<std::string> fields;
};

// The non-comment lines of a comma-separated file, fields trimmed.
std::vector<Row> ReadCsv(const std::string& path) {
  if (!fs::is_regular_file(path)) ThrowInput(path, 0, "file not found");
  const std::string contents = ReadTextFile(path);
  std::vector<Row> rows;
  const auto lines = text::SplitLines(contents);
  for (size_t k = 0; k < lines.size(); ++k) {
    const std::string_view line = text::Trim(lines[k]);
    if (line.empty() || line.front() == '#') continue;
    Row row;
    row.line = static_cast<int>(k) + 1;
    size_t start = 0;
    while (true) {
      const size_t comma = line.find(',', start);
      row.fields.emplace_back(text::Trim(line.substr(start, comma - start)));
      if (comma == std::string_view::npos) break;
      start = comma + 1;
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

double Number(const std::string& path, const Row& row, size_t index, const char* what) {
  double value = 0;
  if (index >= row.fields.size() || !text::ParseDouble(row.fields[index], &value)) {
    ThrowInput(path, row.line,
               std::string(what) + " (field " + std::to_string(index + 1) +
                   ") is missing or not a finite number");
  }
  return value;
}

// Microseconds whose seconds (t * 1e-6, what the join by time compares) are distinct doubles for
// distinct integers: the spacing of doubles below 2^52 * 1e-6 s is at most 2^-20 s < 1 us. Unix
// time in microseconds is 1.7e15 today; 2^52 is 4.5e15 (the year 2112).
constexpr int64_t kMaxTimestampUs = int64_t{1} << 52;

int64_t Timestamp(const std::string& path, const Row& row) {
  int64_t value = 0;
  if (row.fields.empty() || !text::ParseInt(row.fields[0], &value)) {
    ThrowInput(path, row.line, "the timestamp (field 1) must be an integer (microseconds)");
  }
  if (value > kMaxTimestampUs || value < -kMaxTimestampUs) {
    ThrowInput(path, row.line,
               "the timestamp (field 1) " + row.fields[0] +
                   " is beyond 2^52 microseconds (4503599627370496), where two microseconds "
                   "become the same time in seconds");
  }
  return value;
}

// qw, qx, qy, qz, tx, ty, tz from field `first` on: a sensor-to-world (or -to-rig) pose.
Rigid3 PoseAt(const std::string& path, const Row& row, size_t first) {
  if (row.fields.size() < first + 7) {
    ThrowInput(path, row.line, "expected qw, qx, qy, qz, tx, ty, tz after the ids");
  }
  double v[7];
  static const char* kNames[] = {"qw", "qx", "qy", "qz", "tx", "ty", "tz"};
  for (int i = 0; i < 7; ++i) v[i] = Number(path, row, first + i, kNames[i]);
  const Eigen::Quaterniond q(v[0], v[1], v[2], v[3]);
  if (std::abs(q.norm() - 1.0) > 0.01) {
    ThrowInput(path, row.line, "quaternion (qw, qx, qy, qz) has norm " + std::to_string(q.norm()));
  }
  return Rigid3(q.normalized(), Eigen::Vector3d(v[4], v[5], v[6]));
}

// (device id) -> trajectory of that device.
std::map<std::string, std::vector<StampedPose>> ReadTrajectories(
    const std::string& path, std::map<std::pair<int64_t, std::string>, Rigid3>* exact) {
  std::map<std::string, std::vector<StampedPose>> by_device;
  for (const Row& row : ReadCsv(path)) {
    const int64_t timestamp = Timestamp(path, row);
    if (row.fields.size() < 2) ThrowInput(path, row.line, "expected timestamp, device_id, pose");
    const Rigid3 pose = PoseAt(path, row, 2);
    if (!exact->emplace(std::make_pair(timestamp, row.fields[1]), pose).second) {
      ThrowInput(path, row.line, "a second pose of device " + row.fields[1] + " at this timestamp");
    }
    by_device[row.fields[1]].push_back({timestamp * 1e-6, pose});
  }
  return by_device;
}

// A camera of sensors.txt: its intrinsics (OpenCV's pixel convention) and image size.
struct LamarCamera {
  Eigen::Matrix3d K = Eigen::Matrix3d::Identity();
  int width = 0, height = 0;
};

// The cameras of sensors.txt by sensor id (PINHOLE and SIMPLE_PINHOLE; other sensors skipped).
std::map<std::string, LamarCamera> ReadCameras(const std::string& sensors_path) {
  std::map<std::string, LamarCamera> cameras;
  for (const Row& row : ReadCsv(sensors_path)) {
    if (row.fields.size() < 3 || row.fields[2] != "camera") continue;
    const std::string& id = row.fields[0];
    const std::string model = row.fields.size() > 3 ? row.fields[3] : "";
    LamarCamera camera;
    camera.width =
        PixelSize(Number(sensors_path, row, 4, "width"), sensors_path, row.line, "width (field 5)");
    camera.height = PixelSize(Number(sensors_path, row, 5, "height"), sensors_path, row.line,
                              "height (field 6)");
    Eigen::Matrix3d& K = camera.K;
    if (model == "PINHOLE") {
      K(0, 0) = Number(sensors_path, row, 6, "fx");
      K(1, 1) = Number(sensors_path, row, 7, "fy");
      K(0, 2) = Number(sensors_path, row, 8, "cx");
      K(1, 2) = Number(sensors_path, row, 9, "cy");
    } else if (model == "SIMPLE_PINHOLE") {
      K(0, 0) = K(1, 1) = Number(sensors_path, row, 6, "f");
      K(0, 2) = Number(sensors_path, row, 7, "cx");
      K(1, 2) = Number(sensors_path, row, 8, "cy");
    } else {
      ThrowInput(sensors_path, row.line,
                 "camera " + id + " has model '" + model +
                     "'; the lamar reader takes PINHOLE and SIMPLE_PINHOLE cameras");
    }
    // COLMAP's pixel convention (top-left pixel centre at 0.5) to OpenCV's.
    K(0, 2) -= 0.5;
    K(1, 2) -= 0.5;
    cameras[id] = camera;
  }
  return cameras;
}

// One trajectory file: the poses at their exact (timestamp, device) and each device's trajectory.
struct Trajectories {
  std::map<std::pair<int64_t, std::string>, Rigid3> exact;
  std::map<std::string, std::vector<StampedPose>> by_device;

  bool empty() const { return by_device.empty(); }
};

// The poses of the recording's cameras: rigs (sensor -> rig, rig_from_sensor) and trajectories.
class LamarPoses {
 public:
  LamarPoses(const fs::path& root, const TimestampJoinOptions& options,
             std::vector<std::string>* files)
      : options_(options) {
    const std::string rigs_path = (root / "rigs.txt").string();
    if (fs::exists(rigs_path)) {
      files->push_back(rigs_path);
      for (const Row& row : ReadCsv(rigs_path)) {
        if (row.fields.size() < 2)
          ThrowInput(rigs_path, row.line, "expected rig_id, sensor_id, pose");
        rig_of_[row.fields[1]] = {row.fields[0], PoseAt(rigs_path, row, 2)};
      }
    }
    capture_.by_device = ReadTrajectories((root / "trajectories.txt").string(), &capture_.exact);
    const std::string aligned_path = (root / "proc" / "alignment_trajectories.txt").string();
    if (fs::exists(aligned_path)) {
      files->push_back(aligned_path);
      aligned_.by_device = ReadTrajectories(aligned_path, &aligned_.exact);
    }
  }

  // The capture pose and the ground truth (the alignment's) of camera `sensor` at `timestamp`.
  void Attach(int64_t timestamp, const std::string& sensor, CaptureFrame* frame,
              TimestampJoin* unjoined) const {
    frame->capture = PoseOf(capture_, timestamp, sensor, unjoined, frame->name);
    if (!aligned_.empty()) {
      TimestampJoin ignored;
      frame->ground_truth = PoseOf(aligned_, timestamp, sensor, &ignored, frame->name);
    }
  }

 private:
  // The pose of camera `sensor` at `timestamp`: its own, or its rig's times sensor-to-rig; joined
  // by time when the trajectory has no pose at that timestamp. nullopt when there is none.
  std::optional<Rigid3> PoseOf(const Trajectories& trajectories, int64_t timestamp,
                               const std::string& sensor, TimestampJoin* unjoined,
                               const std::string& name) const {
    std::string device = sensor;
    Rigid3 device_from_sensor;
    if (!trajectories.by_device.count(sensor) && rig_of_.count(sensor)) {
      device = rig_of_.at(sensor).first;
      device_from_sensor = rig_of_.at(sensor).second;
    }
    const auto it = trajectories.exact.find({timestamp, device});
    if (it != trajectories.exact.end()) return it->second * device_from_sensor;
    const auto trajectory = trajectories.by_device.find(device);
    if (trajectory == trajectories.by_device.end()) return std::nullopt;
    const TimestampJoin join =
        JoinByTimestamp({{name, timestamp * 1e-6}}, trajectory->second, options_);
    if (join.poses.size() == 0) {
      unjoined->left_out.push_back(name);
      unjoined->num_before_start += join.num_before_start;
      unjoined->num_after_end += join.num_after_end;
      unjoined->num_in_gaps += join.num_in_gaps;
      return std::nullopt;
    }
    return join.poses.world_from_cam.at(name) * device_from_sensor;
  }

  const TimestampJoinOptions& options_;
  std::map<std::string, std::pair<std::string, Rigid3>> rig_of_;
  Trajectories capture_, aligned_;
};

}  // namespace

CaptureRecording ReadLamar(const std::string& path, const TimestampJoinOptions& options) {
  const fs::path root(path);
  const std::string sensors_path = (root / "sensors.txt").string();
  const std::string images_path = (root / "images.txt").string();
  const std::string trajectories_path = (root / "trajectories.txt").string();
  CaptureRecording recording;
  recording.format = "lamar";
  recording.image_root = (root / "raw_data").string();
  recording.files = {sensors_path, images_path, trajectories_path};
  const std::map<std::string, LamarCamera> cameras = ReadCameras(sensors_path);
  const LamarPoses poses(root, options, &recording.files);

  TimestampJoin unjoined;  // images without a capture pose
  std::set<std::string> names;
  for (const Row& row : ReadCsv(images_path)) {
    const int64_t timestamp = Timestamp(images_path, row);
    if (row.fields.size() < 3)
      ThrowInput(images_path, row.line, "expected timestamp, sensor_id, image_path");
    const std::string& sensor = row.fields[1];
    const auto camera = cameras.find(sensor);
    if (camera == cameras.end()) {
      ThrowInput(images_path, row.line, "sensor " + sensor + " is not a camera of sensors.txt");
    }
    CaptureFrame frame;
    frame.name = row.fields[2];
    frame.source = images_path;
    if (!names.insert(frame.name).second) {
      ThrowInput(images_path, row.line, "image " + frame.name + " is listed twice");
    }
    // The name comes from the file: a path the system cannot even look up (too long, say) is an
    // image that is not there, reported as such, not an escaping filesystem_error.
    frame.has_image = PathExists((root / "raw_data" / frame.name).string());
    frame.K = camera->second.K;
    frame.width = camera->second.width;
    frame.height = camera->second.height;
    frame.time_s = timestamp * 1e-6;
    poses.Attach(timestamp, sensor, &frame, &unjoined);
    if (!frame.capture && !frame.ground_truth) continue;  // no pose at all: not a frame
    recording.frames.push_back(std::move(frame));
  }
  if (!unjoined.left_out.empty()) {
    recording.warnings.push_back(UnjoinedFramesWarning(unjoined, "trajectories.txt", options));
  }
  if (recording.frames.empty()) {
    ThrowInput(images_path, 0, "no image has a pose in trajectories.txt or the alignment");
  }
  return recording;
}

}  // namespace raytime
