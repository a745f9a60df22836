// The reference of the efficiency benchmark (testing/efficiency.h, issue 50): the Cramér–Rao bound
// of the Sim(3)-aligned pose errors is what a bundle adjustment with one point per track, started
// at the truth, actually spreads by over independent noise draws. That agreement is what makes
// the bound the yardstick for the ray-time estimator (bench/efficiency_bench.cc).
#include "testing/efficiency.h"

#include <gtest/gtest.h>

#include <vector>

#include "testing/synthetic_scene.h"

namespace raytime {
namespace {

// The uncertainty calibration's 8-camera scene (tests/pose_uncertainty_test.cc) at 0.5 px. 40
// draws put an RMS within about ±11 % (1/sqrt(2·39)) of its expectation even if the cameras' errors
// were fully correlated; the bar is 20 %, as the uncertainty calibration's.
TEST(EfficiencyBoundTest, BundleAdjustmentFromTheTruthSpreadsAsTheBoundSays) {
  SyntheticSceneOptions options;
  options.num_cameras = 8;
  options.num_points = 300;
  options.seed = 3;
  const SyntheticScene scene = MakeSyntheticScene(options);
  const std::vector<SceneTrack> tracks = MatchedTracks(scene);
  const double sigma_px = 0.5;
  const RmsPoseError bound = CramerRaoBound(scene, tracks, sigma_px);
  ASSERT_GT(bound.rotation_deg, 0.0);
  ASSERT_GT(bound.centre, 0.0);
  RmsPoseErrorSum spread;
  for (int d = 0; d < 40; ++d) {
    spread.Add(BundleAdjustFromTruth(scene, tracks,
                                     NoisyKeypoints(scene.input.keypoints, sigma_px, 100 + d)),
               scene.ground_truth);
  }
  const RmsPoseError measured = spread.Rms();
  std::printf("bound %.4f° / %.5f, bundle adjustment from the truth %.4f° / %.5f\n",
              bound.rotation_deg, bound.centre, measured.rotation_deg, measured.centre);
  EXPECT_NEAR(measured.rotation_deg / bound.rotation_deg, 1.0, 0.2);
  EXPECT_NEAR(measured.centre / bound.centre, 1.0, 0.2);
  // The bound scales with the noise: it is σ² times a covariance of the geometry alone.
  const RmsPoseError twice = CramerRaoBound(scene, tracks, 2 * sigma_px);
  EXPECT_NEAR(twice.rotation_deg, 2 * bound.rotation_deg, 1e-9 * bound.rotation_deg);
}

}  // namespace
}  // namespace raytime
