#include "formats/tum.h"

#include <stdexcept>

#include "core/atomic_file.h"
#include "core/error.h"
#include "formats/text_util.h"

namespace raytime {

PoseSet ReadTumTrajectory(const std::string& path, const std::vector<std::string>& names) {
  const std::string contents = ReadTextFile(path);
  const auto lines = text::SplitLines(contents);
  PoseSet poses;
  size_t row = 0;
  for (size_t k = 0; k < lines.size(); ++k) {
    const int line_number = static_cast<int>(k + 1);
    const auto tokens = text::SplitWhitespace(lines[k]);
    if (tokens.empty() || tokens[0].front() == '#') continue;
    if (tokens.size() != 8) {
      ThrowInput(path, line_number,
                 "expected 8 fields (timestamp tx ty tz qx qy qz qw), got " +
                     std::to_string(tokens.size()));
    }
    double v[7];
    for (int i = 0; i < 7; ++i) {
      if (!text::ParseDouble(tokens[1 + i], &v[i])) {
        ThrowInput(path, line_number,
                   "field " + std::to_string(i + 2) + " '" + std::string(tokens[1 + i]) +
                       "' is not a finite number (expected timestamp tx ty tz qx qy qz qw)");
      }
    }
    const Eigen::Quaterniond cam_to_world(v[6], v[3], v[4], v[5]);  // (w, x, y, z)
    if (!(cam_to_world.norm() > 1e-12)) ThrowInput(path, line_number, "quaternion has zero norm");
    if (!names.empty() && row >= names.size()) {
      ThrowInput(path, line_number,
                 "more pose rows than the " + std::to_string(names.size()) + " names given");
    }
    const std::string name = names.empty() ? std::string(tokens[0]) : names[row];
    if (!poses.world_from_cam
             .emplace(name, Rigid3(cam_to_world.normalized(), Eigen::Vector3d(v[0], v[1], v[2])))
             .second) {
      ThrowInput(path, line_number, "pose name '" + name + "' appears twice");
    }
    ++row;
  }
  if (!names.empty() && row != names.size()) {
    ThrowInput(path, 0,
               std::to_string(row) + " pose rows but " + std::to_string(names.size()) +
                   " names given; they must correspond one to one");
  }
  return poses;
}

void WriteTumTrajectory(const std::string& path, const PoseSet& poses,
                        const std::vector<std::string>& timestamps) {
  if (!timestamps.empty() && timestamps.size() != poses.size()) {
    throw std::invalid_argument("WriteTumTrajectory: " + std::to_string(timestamps.size()) +
                                " timestamps for " + std::to_string(poses.size()) + " poses");
  }
  std::string out = "# timestamp tx ty tz qx qy qz qw (camera-to-world)\n";
  size_t row = 0;
  for (const auto& [name, world_from_cam] : poses.world_from_cam) {
    const std::string& first = timestamps.empty() ? name : timestamps[row++];
    // The first column is one whitespace-free token; anything else would shift the columns.
    if (text::SplitWhitespace(first).size() != 1 || first != text::Trim(first) ||
        first.front() == '#') {
      throw InputError("TUM first column '" + first +
                       "' must be a single token not starting with '#'");
    }
    const Eigen::Quaterniond q = world_from_cam.rotation.normalized();
    const Eigen::Vector3d& t = world_from_cam.translation;
    out += first;
    for (const double v : {t.x(), t.y(), t.z(), q.x(), q.y(), q.z(), q.w()}) {
      out += ' ' + text::FormatDouble(v);
    }
    out += '\n';
  }
  WriteTextFileAtomically(path, out);
}

}  // namespace raytime
