// Guardrails (paper §3.6 "Prior trust region", §4.3 wander test, and the inconsistent-pairs test
// beyond the paper): each fires on a constructed case (matches that pull the solve away from the
// prior; image pairs whose matches belong to the wrong copy of a repeated structure), says so, and
// stays quiet on a healthy solve. The first two return the prior, the last only flags; its
// residual kernel agrees with the solve's cost functors.
#include <ceres/problem.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <set>
#include <utility>

#include "refine/cross_projection_cost.h"
#include "refine/guardrails.h"
#include "refine/pair_consistency.h"
#include "refine/problem_layout.h"
#include "refine/ray_time_problem.h"
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

PairResidual MakePair(int image1, int image2, double median_px) {
  PairResidual pair;
  pair.image1 = image1;
  pair.image2 = image2;
  pair.num_matches = 50;
  pair.median_px = median_px;
  return pair;
}

TEST(RefineGuardrailTest, InconsistentPairsFiresAboveTheFractionAndListsThePairs) {
  // Ten pairs, one above 4 px (fountain-P11-like): a fraction of exactly 0.1 does not fire.
  std::vector<PairResidual> pairs;
  for (int p = 0; p < 10; ++p) pairs.push_back(MakePair(p, p + 1, 0.5 + 0.1 * p));
  pairs[3].median_px = 34.0;
  pairs[6].median_px = 4.0;  // at the threshold: consistent
  InconsistentPairsVerdict verdict = CheckInconsistentPairs(pairs, 4.0, 0.1);
  EXPECT_TRUE(verdict.enabled);
  EXPECT_FALSE(verdict.fired);
  EXPECT_EQ(verdict.num_pairs, 10);
  EXPECT_EQ(verdict.num_inconsistent, 1);
  EXPECT_DOUBLE_EQ(verdict.fraction, 0.1);
  EXPECT_EQ(verdict.pair_threshold_px, 4.0);
  EXPECT_EQ(verdict.fraction_threshold, 0.1);
  ASSERT_EQ(verdict.pairs.size(), 1u);
  EXPECT_EQ(verdict.pairs[0].image1, 3);
  EXPECT_EQ(verdict.pairs[0].median_px, 34.0);

  // A castle-P19-like third of the pairs wrong fires and lists them in input order.
  pairs[0].median_px = 120.0;
  pairs[8].median_px = 6.5;
  verdict = CheckInconsistentPairs(pairs, 4.0, 0.1);
  EXPECT_TRUE(verdict.fired);
  EXPECT_EQ(verdict.num_inconsistent, 3);
  EXPECT_DOUBLE_EQ(verdict.fraction, 0.3);
  ASSERT_EQ(verdict.pairs.size(), 3u);
  EXPECT_EQ(verdict.pairs[0].image1, 0);
  EXPECT_EQ(verdict.pairs[1].image1, 3);
  EXPECT_EQ(verdict.pairs[2].image1, 8);
  EXPECT_EQ(verdict.pairs[2].num_matches, 50);
  EXPECT_LT(verdict.median_pair_px, 4.0);

  const InconsistentPairsVerdict none = CheckInconsistentPairs({}, 4.0, 0.1);
  EXPECT_TRUE(none.enabled);
  EXPECT_FALSE(none.fired);
  EXPECT_EQ(none.num_pairs, 0);
}

// The kernel recomputes the residuals the solve minimizes from plain arrays: at a perturbed state
// (distorted lens, poses and ray times off) each equals the autodiff functor's and the cached
// cost's value in the Ceres problem, per-observation and anchored, and the per-pair medians are
// those of the problem's own residuals.
TEST(RefineGuardrailTest, PairResidualKernelAgreesWithTheCostFunctors) {
  SyntheticSceneOptions scene_options;
  scene_options.num_cameras = 5;
  scene_options.num_points = 80;
  scene_options.distortion = true;
  scene_options.seed = 21;
  const SyntheticScene scene = MakeSyntheticScene(scene_options);
  std::vector<Rigid3> poses = JitterPoses(scene.ground_truth, 1.0, 0.2, 22);
  for (Rigid3& pose : poses) pose.rotation.normalize();
  const IntrinsicsVector intrinsics(scene.input.intrinsics.params.data());
  const auto pixel = [&](const LayoutObservation& obs) -> Eigen::Vector2d {
    return scene.input.keypoints[obs.image].row(obs.keypoint).transpose();
  };

  for (const bool anchored : {false, true}) {
    SCOPED_TRACE(anchored ? "anchored" : "per_observation");
    const ProblemLayout layout = anchored ? BuildAnchoredLayout(scene.input, 0, 0)
                                          : BuildPerObservationLayout(scene.input, 0, 0);
    const std::vector<double> ray_times = JitterValues(TrueRayTimes(scene, layout), 0.2, 23);
    RayTimeProblemSettings settings;
    settings.num_threads = 1;
    RayTimeProblem problem(scene.input, layout, poses, poses, scene.input.intrinsics, ray_times,
                           settings);
    ceres::Problem::EvaluateOptions evaluate;
    evaluate.residual_blocks = problem.match_blocks();
    evaluate.apply_loss_function = false;
    std::vector<double> cached;
    problem.problem().Evaluate(evaluate, nullptr, &cached, nullptr, nullptr);
    ASSERT_EQ(cached.size(), 2 * layout.residuals.size());

    double largest = 0.0;
    for (size_t r = 0; r < layout.residuals.size(); ++r) {
      const LayoutObservation& source = layout.observations[layout.residuals[r].source];
      const LayoutObservation& target = layout.observations[layout.residuals[r].target];
      const double ray_time = ray_times[source.ray_time];
      const Eigen::Vector2d kernel =
          CrossProjectionResidual(intrinsics, poses[source.image], ray_time, pixel(source),
                                  poses[target.image], pixel(target));
      // The autodiff functor through Ceres' CostFunction interface.
      const std::unique_ptr<ceres::CostFunction> functor(
          CrossProjectionAutoDiffCost::Create(pixel(source), pixel(target)));
      const double* parameters[4] = {problem.intrinsics_block(), problem.pose_block(source.image),
                                     &ray_time, problem.pose_block(target.image)};
      double autodiff[2];
      ASSERT_TRUE(functor->Evaluate(parameters, autodiff, nullptr));
      EXPECT_NEAR(kernel.x(), autodiff[0], 1e-9);
      EXPECT_NEAR(kernel.y(), autodiff[1], 1e-9);
      EXPECT_NEAR(kernel.x(), cached[2 * r], 1e-9);
      EXPECT_NEAR(kernel.y(), cached[2 * r + 1], 1e-9);
      largest = std::max(largest, kernel.norm());
    }
    EXPECT_GT(largest, 10.0) << "the state is away from the optimum";

    // The kernel's arrays, as RefinePoses builds them from a layout.
    const int n = static_cast<int>(layout.observations.size());
    Eigen::VectorXi images(n), point_source(n);
    Keypoints pixels(n, 2);
    Eigen::VectorXd point_ray_time(n);
    for (int o = 0; o < n; ++o) {
      const LayoutObservation& obs = layout.observations[o];
      images(o) = obs.image;
      pixels.row(o) = pixel(obs).transpose();
      point_source(o) = layout.ray_time_observation[obs.point_ray_time];
      point_ray_time(o) = ray_times[obs.point_ray_time];
    }
    std::vector<PairObservationMatches> pairs(scene.input.pairs.size());
    std::vector<std::vector<int>> rows(pairs.size());
    for (size_t m = 0; m < layout.matches.size(); ++m) rows[layout.matches[m].pair].push_back(m);
    for (size_t p = 0; p < pairs.size(); ++p) {
      pairs[p].image1 = scene.input.pairs[p].image1;
      pairs[p].image2 = scene.input.pairs[p].image2;
      pairs[p].observations.resize(static_cast<Eigen::Index>(rows[p].size()), 2);
      for (size_t k = 0; k < rows[p].size(); ++k) {
        const LayoutMatch& match = layout.matches[rows[p][k]];
        pairs[p].observations.row(static_cast<Eigen::Index>(k)) << match.observation1,
            match.observation2;
      }
    }
    const std::vector<PairResidual> medians =
        PairResidualMedians(intrinsics, poses, images, pixels, point_source, point_ray_time, pairs);
    ASSERT_EQ(medians.size(), pairs.size());
    if (!anchored) {
      // Match m's residuals are the problem's residual blocks 2m (1 in 2) and 2m + 1 (2 in 1).
      for (size_t p = 0; p < pairs.size(); ++p) {
        std::vector<double> values;
        for (int m : rows[p]) {
          double sum = 0.0;
          for (int c = 4 * m; c < 4 * m + 4; ++c) sum += cached[c] * cached[c];
          values.push_back(std::sqrt(sum / 2.0));
        }
        std::sort(values.begin(), values.end());
        const size_t mid = values.size() / 2;
        const double median =
            values.size() % 2 == 1 ? values[mid] : 0.5 * (values[mid - 1] + values[mid]);
        EXPECT_EQ(medians[p].image1, pairs[p].image1);
        EXPECT_EQ(medians[p].image2, pairs[p].image2);
        EXPECT_EQ(medians[p].num_matches, static_cast<int>(rows[p].size()));
        EXPECT_NEAR(medians[p].median_px, median, 1e-9);
      }
    }
    // At the ground truth every pair is explained, whichever observation holds the point.
    const std::vector<double> true_times = TrueRayTimes(scene, layout);
    for (int o = 0; o < n; ++o)
      point_ray_time(o) = true_times[layout.observations[o].point_ray_time];
    for (const PairResidual& pair : PairResidualMedians(
             intrinsics, scene.ground_truth, images, pixels, point_source, point_ray_time, pairs)) {
      EXPECT_GT(pair.num_matches, 0);
      EXPECT_LT(pair.median_px, 1e-6);
    }
  }
}

// A healthy noise-free solve from an exact prior explains every pair to ~0 px (checked with a
// threshold of 1e-3 px, above which any pair would be listed), with either parameterization.
TEST(RefineGuardrailTest, InconsistentPairsStaysQuietOnAHealthySolve) {
  SyntheticSceneOptions scene_options = Scene();
  scene_options.pixel_noise = 0.0;
  const SyntheticScene scene = MakeSyntheticScene(scene_options);
  for (const char* parameterization : {"per_observation", "anchored"}) {
    SCOPED_TRACE(parameterization);
    RefineOptions options;
    options.parameterization = parameterization;
    options.inconsistent_pair_px = 1e-3;
    options.max_inconsistent_pair_fraction = 0.0;
    options.num_threads = 2;
    RefineOutput output;
    const RefineSummary summary = RefinePoses(scene.input, options, &output);
    const InconsistentPairsVerdict& verdict = summary.inconsistent_pairs;
    EXPECT_TRUE(verdict.enabled);
    EXPECT_FALSE(verdict.fired);
    EXPECT_EQ(verdict.num_pairs, static_cast<int>(scene.input.pairs.size()));
    EXPECT_EQ(verdict.num_inconsistent, 0);
    EXPECT_LT(verdict.median_pair_px, 1e-3);
    EXPECT_TRUE(summary.guardrails_fired.empty());
    EXPECT_EQ(summary.ToJson()["guardrails"]["inconsistent_pairs"]["fired"], false);
  }
}

// Repeated structure (§4.11; castle-P19's walls): in every third pair (i, j), image j's side of
// each match is replaced by a new keypoint of j, the projection of the point moved 1.5 m along the
// vertical axis (the same window one storey over). The pair's matches agree with each other and
// with a wrong relative pose (camera j moved 1.5 m the other way), not with the scene, and are
// 130 px off it. Returns the corrupted pairs.
std::set<std::pair<int, int>> CorruptEveryThirdPair(SyntheticScene* scene) {
  const CameraIntrinsics& intrinsics = scene->input.intrinsics;
  const Eigen::Vector3d storey(0.0, -1.5, 0.0);
  std::set<std::pair<int, int>> corrupted;
  for (size_t p = 1; p < scene->input.pairs.size(); p += 3) {
    PairMatchIndices& pair = scene->input.pairs[p];
    const int i = pair.image1;
    const int j = pair.image2;
    Keypoints& keypoints = scene->input.keypoints[j];
    std::vector<std::pair<uint32_t, uint32_t>> rows;
    for (Eigen::Index m = 0; m < pair.matches.rows(); ++m) {
      const std::vector<int>& map = scene->keypoint_of_point[i];
      const int point =
          static_cast<int>(std::find(map.begin(), map.end(), pair.matches(m, 0)) - map.begin());
      const Eigen::Vector3d copy = scene->points[point] + storey;
      const Eigen::Vector3d c = scene->ground_truth[j].Inverse() * copy;
      if (c.z() < 1.0) continue;
      double undistorted[2], distorted[2];
      ProjectPinhole(intrinsics.params.data(), c.data(), undistorted);
      DistortPixel(intrinsics.params.data(), undistorted, distorted);
      if (distorted[0] < 0 || distorted[1] < 0 || distorted[0] > intrinsics.width ||
          distorted[1] > intrinsics.height) {
        continue;
      }
      const Eigen::Index row = keypoints.rows();
      keypoints.conservativeResize(row + 1, 2);
      keypoints.row(row) << distorted[0], distorted[1];
      rows.emplace_back(pair.matches(m, 0), static_cast<uint32_t>(row));
    }
    pair.matches.resize(static_cast<Eigen::Index>(rows.size()), 2);
    for (size_t m = 0; m < rows.size(); ++m) {
      pair.matches(static_cast<Eigen::Index>(m), 0) = rows[m].first;
      pair.matches(static_cast<Eigen::Index>(m), 1) = rows[m].second;
    }
    corrupted.emplace(i, j);
  }
  return corrupted;
}

// With the basin configuration (trust region off, λR = 0, cap 100) from an exact prior, a third
// of the pairs matched to the wrong copy: the test fires, lists exactly those pairs, and the
// solution is still returned; switched off, nothing is measured.
TEST(RefineGuardrailTest, InconsistentPairsFlagsWrongPairsAndReturnsTheSolution) {
  SyntheticScene scene = MakeSyntheticScene(Scene());
  const std::set<std::pair<int, int>> corrupted = CorruptEveryThirdPair(&scene);
  const int num_pairs = static_cast<int>(scene.input.pairs.size());
  ASSERT_EQ(corrupted.size(), 6u);
  ASSERT_EQ(num_pairs, 18);
  for (const PairMatchIndices& pair : scene.input.pairs) ASSERT_GT(pair.matches.rows(), 20);

  RefineOptions options;
  options.trust_region = false;
  options.orientation_weight = 0.0;
  options.max_matches_per_pair = 100;
  options.num_threads = 2;
  RefineOutput output;
  const RefineSummary summary = RefinePoses(scene.input, options, &output);
  const InconsistentPairsVerdict& verdict = summary.inconsistent_pairs;
  EXPECT_TRUE(verdict.fired);
  EXPECT_EQ(verdict.num_pairs, num_pairs);
  EXPECT_NEAR(verdict.fraction, 6.0 / 18.0, 1e-12);
  EXPECT_LT(verdict.median_pair_px, 1.0) << "the correct pairs are explained";
  std::set<std::pair<int, int>> listed;
  for (const PairResidual& pair : verdict.pairs) {
    listed.emplace(pair.image1, pair.image2);
    EXPECT_GT(pair.median_px, 4.0);
    EXPECT_GT(pair.num_matches, 20);
    EXPECT_LE(pair.num_matches, 100);
  }
  EXPECT_EQ(listed, corrupted);
  ASSERT_EQ(summary.guardrails_fired.size(), 1u);
  EXPECT_EQ(summary.guardrails_fired[0], "inconsistent_pairs");
  EXPECT_FALSE(summary.returned_prior);
  for (size_t i = 0; i < output.world_from_cam.size(); ++i) {
    EXPECT_EQ(output.world_from_cam[i].translation, output.solved_world_from_cam[i].translation);
  }
  const nlohmann::json json = summary.ToJson()["guardrails"];
  EXPECT_EQ(json["fired"][0], "inconsistent_pairs");
  EXPECT_EQ(json["returned_prior"], false);
  EXPECT_EQ(json["inconsistent_pairs"]["fired"], true);
  EXPECT_EQ(json["inconsistent_pairs"]["num_inconsistent"], 6);
  EXPECT_EQ(json["inconsistent_pairs"]["pair_threshold_px"], 4.0);
  EXPECT_EQ(json["inconsistent_pairs"]["fraction_threshold"], 0.1);
  ASSERT_EQ(json["inconsistent_pairs"]["pairs"].size(), 6u);
  EXPECT_TRUE(json["inconsistent_pairs"]["pairs"][0].contains("median_px"));
  EXPECT_TRUE(json["inconsistent_pairs"]["pairs"][0].contains("num_matches"));

  options.inconsistent_pairs_test = false;
  const RefineSummary off = RefinePoses(scene.input, options, &output);
  EXPECT_FALSE(off.inconsistent_pairs.enabled);
  EXPECT_FALSE(off.inconsistent_pairs.fired);
  EXPECT_TRUE(off.guardrails_fired.empty());
}

}  // namespace
}  // namespace raytime
