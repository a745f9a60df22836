// The combinatorial half of the refiner (paper §3.2, §3.6, §4.7): per-observation and anchored
// layouts, the deterministic per-pair match cap, and the ray-time initialization.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

#include "core/error.h"
#include "core/statistics.h"
#include "refine/solve/problem_layout.h"
#include "refine/solve/ray_time_init.h"
#include "testing/synthetic_scene.h"
#include "tests/refine_test_util.h"

namespace raytime {
namespace {

// Three images with 4 keypoints each; a track 0:0 ~ 1:1 ~ 2:2, a two-view match 0:1 ~ 2:0, a
// match inside one image (skipped).
RefineInput TinyInput() {
  RefineInput input;
  input.cameras = {SyntheticIntrinsics(false)};
  input.camera_index = {0, 0, 0};
  input.prior_world_from_cam.resize(3);
  input.keypoints.assign(3, Keypoints::Zero(4, 2));
  input.pairs = {MakePairMatches(0, 1, {{0, 1}}), MakePairMatches(1, 2, {{1, 2}}),
                 MakePairMatches(0, 2, {{1, 0}}), MakePairMatches(1, 1, {{0, 3}})};
  return input;
}

TEST(RefineLayoutTest, PerObservationOwnsOneRayTimePerObservationAndTwoResidualsPerMatch) {
  const ProblemLayout layout = BuildPerObservationLayout(TinyInput(), 0, 0);
  EXPECT_EQ(layout.num_matches_input, 3);  // the within-image match is not counted
  EXPECT_EQ(layout.num_matches_used, 3);
  ASSERT_EQ(layout.observations.size(), 5u);  // 0:0 0:1 1:1 2:0 2:2
  EXPECT_EQ(layout.ray_time_observation.size(), 5u);
  EXPECT_EQ(layout.residuals.size(), 6u);
  for (size_t o = 1; o < layout.observations.size(); ++o) {
    const auto& a = layout.observations[o - 1];
    const auto& b = layout.observations[o];
    EXPECT_TRUE(a.image < b.image || (a.image == b.image && a.keypoint < b.keypoint));
  }
  // The used matches keep their input pair.
  ASSERT_EQ(layout.matches.size(), 3u);
  for (int m = 0; m < 3; ++m) {
    EXPECT_EQ(layout.matches[m].pair, m);
    EXPECT_EQ(layout.residuals[2 * m].source, layout.matches[m].observation1);
    EXPECT_EQ(layout.residuals[2 * m].target, layout.matches[m].observation2);
  }
  // Symmetric pairs, never within one image.
  for (size_t r = 0; r < layout.residuals.size(); r += 2) {
    EXPECT_EQ(layout.residuals[r].source, layout.residuals[r + 1].target);
    EXPECT_EQ(layout.residuals[r].target, layout.residuals[r + 1].source);
    EXPECT_NE(layout.observations[layout.residuals[r].source].image,
              layout.observations[layout.residuals[r].target].image);
  }
}

TEST(RefineLayoutTest, AnchoredProjectsEachTrackAnchorIntoItsOtherObservations) {
  const ProblemLayout layout = BuildAnchoredLayout(TinyInput(), 0, 0);
  EXPECT_EQ(layout.num_tracks, 2);
  ASSERT_EQ(layout.ray_time_observation.size(), 2u);
  // Track {0:0, 1:1, 2:2} anchored at 0:0 (two residuals), track {0:1, 2:0} at 0:1 (one).
  EXPECT_EQ(layout.residuals.size(), 3u);
  for (const CrossProjection& r : layout.residuals) {
    const LayoutObservation& anchor = layout.observations[r.source];
    EXPECT_EQ(anchor.image, 0);
    EXPECT_GE(anchor.ray_time, 0);
  }
  EXPECT_EQ(layout.matches.size(), 3u);
}

TEST(RefineLayoutTest, RejectsOutOfRangeIndices) {
  RefineInput input = TinyInput();
  input.pairs.push_back(MakePairMatches(0, 2, {{9, 0}}));
  EXPECT_THROW(BuildPerObservationLayout(input, 0, 0), InputError);
  input = TinyInput();
  input.pairs.push_back(MakePairMatches(0, 5, {{0, 0}}));
  EXPECT_THROW(BuildAnchoredLayout(input, 0, 0), InputError);
}

TEST(RefineLayoutTest, MatchCapIsDeterministicPerPairAndRespectsK) {
  const std::vector<int> a = CappedMatchIndices(3, 7, 500, 100, 0);
  EXPECT_EQ(a, CappedMatchIndices(3, 7, 500, 100, 0));
  ASSERT_EQ(a.size(), 100u);
  EXPECT_TRUE(std::is_sorted(a.begin(), a.end()));
  EXPECT_EQ(std::set<int>(a.begin(), a.end()).size(), 100u);
  EXPECT_GE(a.front(), 0);
  EXPECT_LT(a.back(), 500);
  EXPECT_NE(a, CappedMatchIndices(3, 8, 500, 100, 0)) << "the seed depends on the pair";
  EXPECT_NE(a, CappedMatchIndices(3, 7, 500, 100, 1)) << "and on the base seed";
  EXPECT_EQ(CappedMatchIndices(3, 7, 80, 100, 0).size(), 80u);
  EXPECT_EQ(CappedMatchIndices(3, 7, 80, 0, 0).size(), 80u);
  // Uniform: over many pairs every index is drawn about cap/count of the time.
  std::vector<int> hits(500, 0);
  for (int j = 0; j < 400; ++j) {
    for (int m : CappedMatchIndices(1, 100 + j, 500, 100, 0)) ++hits[m];
  }
  for (int count : hits) {
    EXPECT_GT(count, 40);  // expected 80, sd ~8
    EXPECT_LT(count, 125);
  }
}

TEST(RefineLayoutTest, CapAppliesPerPairInTheLayout) {
  SyntheticSceneOptions options;
  options.num_cameras = 5;
  options.num_points = 300;
  const SyntheticScene scene = MakeSyntheticScene(options);
  const ProblemLayout full = BuildPerObservationLayout(scene.input, 0, 0);
  const ProblemLayout capped = BuildPerObservationLayout(scene.input, 40, 0);
  int expected = 0;
  for (const PairMatchIndices& pair : scene.input.pairs) {
    expected += std::min<int>(40, static_cast<int>(pair.matches.rows()));
  }
  EXPECT_EQ(full.num_matches_used, full.num_matches_input);
  EXPECT_EQ(capped.num_matches_input, full.num_matches_input);
  EXPECT_EQ(capped.num_matches_used, expected);
  EXPECT_LT(capped.num_matches_used, full.num_matches_used);
}

// Six cameras on the arc, 200 points, exact keypoints: the ray-time starts' scene.
SyntheticSceneOptions SixCameras() {
  SyntheticSceneOptions options;
  options.num_cameras = 6;
  options.num_points = 200;
  return options;
}

// "auto" starts each image's ray times near the depth of what it sees (8–25 m here), from the
// prior alone; "constant" at the constant.
TEST(RefineLayoutTest, AutoRayTimesFollowTheSceneDepth) {
  const SyntheticScene scene = MakeSyntheticScene(SixCameras());
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  const std::vector<double> truth = TrueRayTimes(scene, layout);
  for (const double prior_error_deg : {0.0, 4.0}) {
    SCOPED_TRACE(prior_error_deg);
    RayTimeInitSummary summary;
    const std::vector<double> init = InitialRayTimes(
        layout, scene.input, JitterPoses(scene.ground_truth, prior_error_deg, 0.0, 5),
        PerCameraBlocks(scene.input), RayTimeInitMode::kAuto, 1.0, &summary);
    ASSERT_EQ(init.size(), truth.size());
    EXPECT_GT(summary.num_depth_samples, static_cast<int>(layout.residuals.size() / 2));
    EXPECT_EQ(summary.images_with_fallback, 0);
    EXPECT_GT(summary.min_depth, 10.0);
    EXPECT_LT(summary.max_depth, 22.0);
    std::vector<double> sorted = truth;
    std::sort(sorted.begin(), sorted.end());
    EXPECT_NEAR(summary.median_depth, sorted[sorted.size() / 2], 2.0);
  }
  RayTimeInitSummary summary;
  const std::vector<double> constant =
      InitialRayTimes(layout, scene.input, scene.ground_truth, PerCameraBlocks(scene.input),
                      RayTimeInitMode::kConstant, 1.0, &summary);
  EXPECT_EQ(constant, std::vector<double>(truth.size(), 1.0));
}

// The basin-first finish's start (StartRayTimesAtClosestApproach): at exact poses and noise-free
// keypoints every flagged ray time starts at its own true depth, where the per-image start misses
// most by metres; unflagged ones keep their values.
TEST(RefineLayoutTest, ClosestApproachStartPutsEachFlaggedRayTimeAtItsTrueDepth) {
  const SyntheticScene scene = MakeSyntheticScene(SixCameras());
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  const std::vector<double> truth = TrueRayTimes(scene, layout);
  RayTimeInitSummary summary;
  const std::vector<double> per_image =
      InitialRayTimes(layout, scene.input, scene.ground_truth, PerCameraBlocks(scene.input),
                      RayTimeInitMode::kAuto, 1.0, &summary);
  std::vector<bool> needs_start(per_image.size());
  for (size_t t = 0; t < needs_start.size(); ++t) needs_start[t] = t % 2 == 0;
  std::vector<double> started = per_image;
  const int count = StartRayTimesAtClosestApproach(
      layout, scene.input, scene.ground_truth, PerCameraBlocks(scene.input), needs_start, &started);
  EXPECT_EQ(count, static_cast<int>((per_image.size() + 1) / 2));
  int per_image_off_by_a_metre = 0;
  for (size_t t = 0; t < started.size(); ++t) {
    const double expected = truth[layout.ray_time_observation[t]];
    if (needs_start[t]) {
      EXPECT_NEAR(started[t], expected, 1e-6 * expected) << "ray time " << t;
      if (std::abs(per_image[t] - expected) > 1.0) ++per_image_off_by_a_metre;
    } else {
      EXPECT_EQ(started[t], per_image[t]);
    }
  }
  EXPECT_GT(per_image_off_by_a_metre, count / 2);
}

// With per-image intrinsics (focal 3 %, principal point 8 px apart), noise-free keypoints and the
// exact prior, each observation's ray is unprojected with its own image's camera: matched rays
// meet, every closest-approach depth is the true depth, and each image's start is the upper
// median of its residuals' true source depths. One camera for all (camera 0's) misses them.
TEST(RefineLayoutTest, AutoRayTimesUnprojectEachImageWithItsOwnCamera) {
  SyntheticSceneOptions options = SixCameras();
  options.focal_drift = 0.03;
  options.principal_point_drift_px = 8.0;
  const SyntheticScene scene = MakeSyntheticScene(options);
  ASSERT_EQ(scene.input.cameras.size(), 6u);
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  const std::vector<double> truth = TrueRayTimes(scene, layout);  // ray time o on observation o
  std::vector<std::vector<double>> depths(scene.input.cameras.size());
  for (const CrossProjection& residual : layout.residuals) {
    depths[layout.observations[residual.source].image].push_back(truth[residual.source]);
  }
  RayTimeInitSummary summary;
  const std::vector<double> init =
      InitialRayTimes(layout, scene.input, scene.ground_truth, PerCameraBlocks(scene.input),
                      RayTimeInitMode::kAuto, 1.0, &summary);
  EXPECT_EQ(summary.images_with_fallback, 0);
  CameraBlocks one_camera = PerCameraBlocks(scene.input);
  one_camera.camera_of_image.assign(scene.input.camera_index.size(), 0);
  const std::vector<double> forced = InitialRayTimes(
      layout, scene.input, scene.ground_truth, one_camera, RayTimeInitMode::kAuto, 1.0, &summary);
  double worst_forced = 0.0;
  for (size_t t = 0; t < init.size(); ++t) {
    const double expected =
        UpperMedian(depths[layout.observations[layout.ray_time_observation[t]].image], 0.0);
    EXPECT_NEAR(init[t], expected, 1e-6 * expected) << "ray time " << t;
    worst_forced = std::max(worst_forced, std::abs(forced[t] - expected) / expected);
  }
  EXPECT_GT(worst_forced, 1e-3);
}

}  // namespace
}  // namespace raytime
