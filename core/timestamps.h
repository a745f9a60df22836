// Frames joined to a pose trajectory by time (issue 10). Where frames and poses carry their own
// clocks (a video's frames and an odometry log, a trajectory at another rate than the images),
// each frame takes the pose interpolated between its two neighbouring poses in time: SLERP of the
// rotation and linear interpolation of the centre, when both neighbours are close enough in time;
// otherwise the frame has no pose and is reported, never given a pose from far away.
#pragma once

#include <map>
#include <string>
#include <vector>

#include "core/geometry.h"
#include "core/options.h"
#include "core/types.h"
#include "core/warnings.h"

namespace raytime {

// A frame outside the trajectory's time span by at most this takes the end pose unchanged:
// timestamps printed to the millisecond (ARKitScenes' frame names, say) name the same instant as
// a pose up to this rounding. Inside the span, frames are always interpolated.
inline constexpr double kSameInstantS = 1e-3;

struct TimestampJoinOptions {
  // A hand-held phone moves ~0.5 m/s and turns ~30°/s; over 0.1 s such a motion is close to
  // linear, so interpolating across it costs millimetres, while a longer gap (tracking lost, a
  // paused log) would invent a pose. 0.1 s still joins odometry at 10 Hz to any frame rate.
  double max_time_gap_s = 0.1;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("max_time_gap_s", max_time_gap_s,
      "Timestamp join (stray, arkitscenes, lamar): largest time from a frame to each of the two "
      "poses it is interpolated between (SLERP + linear), seconds; frames further from the "
      "trajectory are reported and left out",
      Positive(), AtMost(86400));
  }
};

struct StampedPose {
  double time_s = 0;
  Rigid3 world_from_cam;
};

// One decoded frame of a video: its number in the video (0 first) and its presentation time
// (seconds from the start of the video).
struct DecodedFrame {
  int number = 0;
  double time_s = 0;
};

struct TimestampJoin {
  PoseSet poses;                      // one per joined frame, keyed by the frame's name
  std::vector<std::string> left_out;  // frames without a pose, in name order
  int num_before_start = 0;           // of left_out: earlier than the trajectory's first pose
  int num_after_end = 0;              // later than its last pose
  int num_in_gaps = 0;                // between two poses further apart than the tolerance allows
  int num_exact = 0;                  // joined frames whose time is a pose's (no interpolation)
  int num_interpolated = 0;
  double largest_gap_s = 0;  // largest time from a joined frame to a neighbour it used
};

// The pose at `fraction` (0 = a, 1 = b) of the way from a to b: rotation by SLERP along the
// shorter arc, centre linearly.
Rigid3 InterpolatePose(const Rigid3& a, const Rigid3& b, double fraction);

// Joins frames (name -> time, seconds) to `trajectory` (same clock, any order; times must be
// distinct, std::invalid_argument otherwise: readers check their files and name the line). A
// frame at a pose's time takes that pose; a frame between two poses takes InterpolatePose when
// both are within options.max_time_gap_s of it; a frame within kSameInstantS outside the span takes
// the end pose; every other frame is left out.
TimestampJoin JoinByTimestamp(const std::map<std::string, double>& frame_times,
                              std::vector<StampedPose> trajectory,
                              const TimestampJoinOptions& options);

// The "unjoined_frames" warning for a join that left frames out (`what` names the trajectory, e.g.
// "odometry.csv"), with the counts by reason in its details.
Warning UnjoinedFramesWarning(const TimestampJoin& join, const std::string& what,
                              const TimestampJoinOptions& options);

}  // namespace raytime
