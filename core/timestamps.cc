#include "core/timestamps.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "core/error.h"

namespace raytime {

Rigid3 InterpolatePose(const Rigid3& a, const Rigid3& b, double fraction) {
  // Eigen's slerp takes the shorter arc (it flips b's sign when the dot product is negative).
  const Eigen::Quaterniond rotation =
      a.rotation.normalized().slerp(fraction, b.rotation.normalized()).normalized();
  return Rigid3(rotation, (1.0 - fraction) * a.translation + fraction * b.translation);
}

TimestampJoin JoinByTimestamp(const std::map<std::string, double>& frame_times,
                              std::vector<StampedPose> trajectory,
                              const TimestampJoinOptions& options) {
  std::stable_sort(trajectory.begin(), trajectory.end(),
                   [](const StampedPose& a, const StampedPose& b) { return a.time_s < b.time_s; });
  for (size_t i = 0; i < trajectory.size(); ++i) {
    if (!std::isfinite(trajectory[i].time_s)) {
      throw InputError("trajectory time is not finite");
    }
    if (i > 0 && trajectory[i].time_s == trajectory[i - 1].time_s) {
      throw InputError("two trajectory poses at time " + std::to_string(trajectory[i].time_s));
    }
  }
  TimestampJoin join;
  const auto take = [&](const std::string& name, const Rigid3& pose, double gap, bool exact) {
    join.poses.world_from_cam[name] = pose;
    join.largest_gap_s = std::max(join.largest_gap_s, gap);
    ++(exact ? join.num_exact : join.num_interpolated);
  };
  for (const auto& [name, time] : frame_times) {
    // First pose at or after the frame.
    const auto after =
        std::lower_bound(trajectory.begin(), trajectory.end(), time,
                         [](const StampedPose& pose, double t) { return pose.time_s < t; });
    if (after != trajectory.end() && after->time_s == time) {
      take(name, after->world_from_cam, 0.0, true);
      continue;
    }
    if (after == trajectory.begin() || after == trajectory.end()) {
      const bool before_start = after == trajectory.begin();
      if (!trajectory.empty()) {
        const StampedPose& end = before_start ? trajectory.front() : trajectory.back();
        const double gap = std::abs(end.time_s - time);
        if (gap <= kSameInstantS) {
          take(name, end.world_from_cam, gap, true);
          continue;
        }
      }
      join.left_out.push_back(name);
      ++(before_start ? join.num_before_start : join.num_after_end);
      continue;
    }
    const StampedPose& next = *after;
    const StampedPose& previous = *(after - 1);
    const double gap = std::max(time - previous.time_s, next.time_s - time);
    if (gap > options.max_time_gap_s) {
      join.left_out.push_back(name);
      ++join.num_in_gaps;
      continue;
    }
    const double fraction = (time - previous.time_s) / (next.time_s - previous.time_s);
    take(name, InterpolatePose(previous.world_from_cam, next.world_from_cam, fraction), gap, false);
  }
  return join;
}

namespace {
std::string Short(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%g", value);
  return buffer;
}
}  // namespace

Warning UnjoinedFramesWarning(const TimestampJoin& join, const std::string& what,
                              const TimestampJoinOptions& options) {
  Warning warning;
  warning.code = "unjoined_frames";
  warning.message = std::to_string(join.left_out.size()) + " frame(s) have no pose in " + what +
                    " within " + Short(options.max_time_gap_s) +
                    " s on both sides and are left out (" + std::to_string(join.num_before_start) +
                    " before its first pose, " + std::to_string(join.num_after_end) +
                    " after its last, " + std::to_string(join.num_in_gaps) + " in gaps)";
  warning.images = join.left_out;
  warning.details = {{"max_time_gap_s", options.max_time_gap_s},
                     {"num_before_start", join.num_before_start},
                     {"num_after_end", join.num_after_end},
                     {"num_in_gaps", join.num_in_gaps},
                     {"num_joined", join.poses.size()}};
  return warning;
}

}  // namespace raytime
