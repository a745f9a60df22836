// Frames joined to a trajectory by time (core/timestamps.h, issue 10): known answers on a small
// synthetic trajectory.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/geometry.h"
#include "core/timestamps.h"
#include "tests/expect_pose.h"

namespace raytime {
namespace {

Rigid3 Pose(const Eigen::Vector3d& rotation_vector, const Eigen::Vector3d& centre) {
  return Rigid3(Eigen::Quaterniond(ExpSO3(rotation_vector)), centre);
}

// The geodesic between a and b at `fraction`, written independently of InterpolatePose:
// R = Ra exp(fraction log(Ra^T Rb)), c = ca + fraction (cb - ca).
Rigid3 Geodesic(const Rigid3& a, const Rigid3& b, double fraction) {
  const Eigen::Matrix3d ra = a.RotationMatrix(), rb = b.RotationMatrix();
  const Eigen::Matrix3d r = ra * ExpSO3(fraction * LogSO3(ra.transpose() * rb));
  return Rigid3(Eigen::Quaterniond(r), a.translation + fraction * (b.translation - a.translation));
}

const std::vector<StampedPose> kTrajectory = {
    {10.0, Pose({0.0, 0.0, 0.0}, {0, 0, 0})},
    {10.05, Pose({0.1, -0.2, 0.3}, {0.1, 0.0, -0.05})},
    {10.10, Pose({0.2, -0.1, 0.5}, {0.2, 0.02, -0.1})},
    // A 0.5 s gap: tracking lost.
    {10.60, Pose({0.3, 0.1, 0.6}, {0.5, 0.1, -0.3})},
    {10.65, Pose({0.35, 0.1, 0.65}, {0.55, 0.1, -0.3})},
};

TEST(TimestampJoin, InterpolatedPoseLiesOnTheSlerp) {
  // 30 % of the way from the second pose to the third.
  const std::map<std::string, double> frames = {{"a.jpg", 10.065}};
  const TimestampJoin join = JoinByTimestamp(frames, kTrajectory, TimestampJoinOptions());
  ASSERT_EQ(join.poses.size(), 1u);
  EXPECT_EQ(join.num_interpolated, 1);
  EXPECT_NEAR(join.largest_gap_s, 0.035, 1e-12);
  ExpectPoseNear(join.poses.world_from_cam.at("a.jpg"),
                 Geodesic(kTrajectory[1].world_from_cam, kTrajectory[2].world_from_cam, 0.3),
                 1e-12);
}

TEST(TimestampJoin, SlerpTakesTheShorterArcWhateverTheQuaternionSign) {
  Rigid3 b = kTrajectory[1].world_from_cam;
  b.rotation.coeffs() *= -1.0;  // the same rotation
  const Rigid3 mid = InterpolatePose(kTrajectory[0].world_from_cam, b, 0.5);
  ExpectPoseNear(mid, Geodesic(kTrajectory[0].world_from_cam, kTrajectory[1].world_from_cam, 0.5),
                 1e-12);
}

TEST(TimestampJoin, FrameAtAPoseTimeTakesThatPoseExactly) {
  const std::map<std::string, double> frames = {{"b.jpg", 10.05}};
  const TimestampJoin join = JoinByTimestamp(frames, kTrajectory, TimestampJoinOptions());
  ASSERT_EQ(join.num_exact, 1);
  const Rigid3& pose = join.poses.world_from_cam.at("b.jpg");
  EXPECT_EQ(pose.rotation.coeffs(), kTrajectory[1].world_from_cam.rotation.coeffs());
  EXPECT_EQ(pose.translation, kTrajectory[1].world_from_cam.translation);
}

TEST(TimestampJoin, FramesBeyondToleranceAreLeftOutAndReported) {
  const std::map<std::string, double> frames = {
      {"before.jpg", 9.9},    // 0.1 s before the first pose
      {"edge.jpg", 9.9995},   // within the 1 ms rounding of the first pose
      {"gap.jpg", 10.3},      // 0.2 s from each neighbour across the gap
      {"inside.jpg", 10.62},  // after the gap: joined
      {"after.jpg", 10.7},    // after the last pose
  };
  TimestampJoinOptions options;
  const TimestampJoin join = JoinByTimestamp(frames, kTrajectory, options);
  EXPECT_EQ(join.left_out, (std::vector<std::string>{"after.jpg", "before.jpg", "gap.jpg"}));
  EXPECT_EQ(join.num_before_start, 1);
  EXPECT_EQ(join.num_after_end, 1);
  EXPECT_EQ(join.num_in_gaps, 1);
  ASSERT_TRUE(join.poses.Has("edge.jpg"));
  ASSERT_TRUE(join.poses.Has("inside.jpg"));
  ExpectPoseNear(join.poses.world_from_cam.at("edge.jpg"), kTrajectory[0].world_from_cam, 0);
  ExpectPoseNear(join.poses.world_from_cam.at("inside.jpg"),
                 Geodesic(kTrajectory[3].world_from_cam, kTrajectory[4].world_from_cam, 0.4),
                 1e-12);

  const Warning warning = UnjoinedFramesWarning(join, "odometry.csv", options);
  EXPECT_EQ(warning.code, "unjoined_frames");
  EXPECT_EQ(warning.images, join.left_out);
  EXPECT_NE(warning.message.find("odometry.csv"), std::string::npos);
  EXPECT_EQ(warning.details["num_in_gaps"], 1);

  // A wider tolerance bridges the gap.
  options.max_time_gap_s = 0.3;
  EXPECT_TRUE(JoinByTimestamp(frames, kTrajectory, options).poses.Has("gap.jpg"));
}

TEST(TimestampJoin, TrajectoryOrderDoesNotMatterButRepeatedTimesAreRefused) {
  std::vector<StampedPose> shuffled(kTrajectory.rbegin(), kTrajectory.rend());
  const std::map<std::string, double> frames = {{"a.jpg", 10.065}};
  const TimestampJoin join = JoinByTimestamp(frames, shuffled, TimestampJoinOptions());
  ExpectPoseNear(join.poses.world_from_cam.at("a.jpg"),
                 Geodesic(kTrajectory[1].world_from_cam, kTrajectory[2].world_from_cam, 0.3),
                 1e-12);
  shuffled.push_back(kTrajectory[2]);
  EXPECT_THROW(JoinByTimestamp(frames, shuffled, TimestampJoinOptions()), InputError);
}

}  // namespace
}  // namespace raytime
