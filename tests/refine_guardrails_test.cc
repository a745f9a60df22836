// Guardrails (paper §3.6 "Prior trust region", §4.3 wander test): each fires on a constructed
// case (matches that pull the solve away from the prior), returns the prior and says so, and
// stays quiet on a healthy solve.
#include <gtest/gtest.h>

#include "refine/guardrails.h"
#include "refine/refine.h"
#include "tests/refine_synthetic.h"
#include "tests/refine_test_util.h"

namespace raytime {
namespace {

SyntheticSceneOptions Scene() {
  SyntheticSceneOptions options;
  options.num_cameras = 8;
  options.num_points = 200;
  options.pixel_noise = 0.3;
  options.max_pair_gap = 3;
  options.seed = 9;
  return options;
}

TEST(RefineGuardrailTest, TrustRegionMeasuresInThePriorFrame) {
  const SyntheticScene scene = MakeSyntheticScene(Scene());
  const std::vector<Rigid3>& prior = scene.ground_truth;
  // A similarity of the whole solution: no shape change, but every frame moves in the prior's
  // frame, which the trust region counts and the Sim(3)-aligned wander test does not.
  Sim3 gauge;
  gauge.scale = 1.01;
  gauge.rotation = Eigen::AngleAxisd(0.02, Eigen::Vector3d::UnitY());
  gauge.translation = Eigen::Vector3d(0.05, 0.0, 0.0);
  std::vector<Rigid3> moved;
  for (const Rigid3& pose : prior) moved.push_back(gauge.TransformPose(pose));
  const TrustRegionVerdict trust = CheckTrustRegion(prior, moved, 3.5, 0.022);
  EXPECT_TRUE(trust.fired);
  EXPECT_NEAR(trust.max_rotation_deg, DegreesFromRadians(0.02), 1e-9);
  EXPECT_GT(trust.max_translation, 0.05);
  const WanderVerdict wander = CheckWander(prior, moved, 0.01, 2.0);
  EXPECT_FALSE(wander.fired);
  EXPECT_LT(wander.median_displacement, 1e-9);
  EXPECT_FALSE(CheckTrustRegion(prior, prior, 3.5, 0.022).fired);
}

// Camera 3's keypoints are those of a camera turned by 6°: its matches agree with each other and
// pull it there (a castle-like failure, §4.11). The healthy case is the same scene with true
// keypoints and a prior 0.5° / 5 cm off.
TEST(RefineGuardrailTest, TrustRegionFiresOnMatchesThatPullAwayAndNotOnAHealthySolve) {
  RefineOptions options;
  options.length_unit_m = 30.0;  // building scale: 3.5° / 0.66 m
  options.num_threads = 2;

  SyntheticScene healthy = MakeSyntheticScene(Scene());
  healthy.input.prior_world_from_cam = JitterPoses(healthy.ground_truth, 0.5, 0.05, 3);
  RefineOutput output;
  const RefineSummary quiet = RefinePoses(healthy.input, options, &output);
  EXPECT_TRUE(quiet.trust_region.enabled);
  EXPECT_FALSE(quiet.trust_region.fired);
  EXPECT_FALSE(quiet.returned_prior);
  EXPECT_TRUE(quiet.guardrails_fired.empty());
  EXPECT_NEAR(quiet.trust_region.translation_threshold, 0.66, 1e-12);
  EXPECT_GT(quiet.trust_region.max_rotation_deg, 0.1) << "the healthy solve does correct the prior";

  SyntheticScene corrupted = MakeSyntheticScene(Scene());
  Rigid3 wrong = corrupted.ground_truth[3];
  wrong.rotation =
      Eigen::Quaterniond(Eigen::AngleAxisd(6.0 * M_PI / 180.0, Eigen::Vector3d::UnitY())) *
      wrong.rotation;
  ReprojectCamera(&corrupted, 3, wrong);
  const RefineSummary fired = RefinePoses(corrupted.input, options, &output);
  EXPECT_TRUE(fired.trust_region.fired);
  EXPECT_GT(fired.trust_region.max_rotation_deg, 3.5);
  EXPECT_TRUE(fired.returned_prior);
  ASSERT_EQ(fired.guardrails_fired.size(), 1u);
  EXPECT_EQ(fired.guardrails_fired[0], "trust_region");
  for (size_t i = 0; i < output.world_from_cam.size(); ++i) {
    EXPECT_EQ(output.world_from_cam[i].translation, corrupted.ground_truth[i].translation);
  }
  EXPECT_GT(RotationDistance(output.solved_world_from_cam[3].rotation,
                             corrupted.ground_truth[3].rotation),
            RadiansFromDegrees(3.5));
  EXPECT_EQ(fired.ToJson()["guardrails"]["fired"][0], "trust_region");
}

// Every camera's keypoints are those of a camera displaced by 1 m: the trajectory the matches
// prefer is a non-rigid warp of the prior, which the Sim(3)-aligned wander test catches. Healthy:
// true keypoints, a prior 2 cm off per frame.
TEST(RefineGuardrailTest, WanderTestFiresOnAWarpedSolveAndNotOnAHealthySolve) {
  RefineOptions options;
  options.trust_region = false;
  options.wander_test = true;
  options.wander_expected_m = 0.05;
  options.num_threads = 2;

  SyntheticScene healthy = MakeSyntheticScene(Scene());
  healthy.input.prior_world_from_cam = JitterPoses(healthy.ground_truth, 0.0, 0.02, 4);
  RefineOutput output;
  const RefineSummary quiet = RefinePoses(healthy.input, options, &output);
  EXPECT_TRUE(quiet.wander.enabled);
  EXPECT_FALSE(quiet.wander.fired);
  EXPECT_FALSE(quiet.trust_region.enabled);
  EXPECT_LT(quiet.wander.median_displacement, 0.1);
  EXPECT_FALSE(quiet.returned_prior);

  SyntheticScene warped = MakeSyntheticScene(Scene());
  const std::vector<Rigid3> displaced = JitterPoses(warped.ground_truth, 0.0, 1.0, 5);
  for (int i = 0; i < static_cast<int>(displaced.size()); ++i) {
    ReprojectCamera(&warped, i, displaced[i]);
  }
  const RefineSummary fired = RefinePoses(warped.input, options, &output);
  EXPECT_TRUE(fired.wander.fired);
  EXPECT_GT(fired.wander.median_displacement, 0.1);
  EXPECT_TRUE(fired.returned_prior);
  ASSERT_EQ(fired.guardrails_fired.size(), 1u);
  EXPECT_EQ(fired.guardrails_fired[0], "wander");
  EXPECT_EQ(output.world_from_cam[0].translation, warped.ground_truth[0].translation);
}

}  // namespace
}  // namespace raytime
