// The refiner's objective (paper §3.2–3.3, §3.7): cross-projection residuals vanish at the ground
// truth, Ceres' total cost is exactly the energy of eq. (energy), and the shared evaluation
// cache's "gradient surgery" Jacobians equal both the uncached automatic derivatives and
// numeric differentiation, with and without distortion and with self-calibration.
#include <ceres/crs_matrix.h>
#include <ceres/numeric_diff_cost_function.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>

#include "core/geometry.h"
#include "refine/cross_projection_cost.h"
#include "refine/evaluation_cache.h"
#include "refine/problem_layout.h"
#include "refine/ray_time_problem.h"
#include "tests/refine_synthetic.h"
#include "tests/refine_test_util.h"

namespace raytime {
namespace {

SyntheticSceneOptions SmallScene(bool distortion) {
  SyntheticSceneOptions options;
  options.num_cameras = 5;
  options.num_points = 120;
  options.distortion = distortion;
  options.seed = distortion ? 7 : 3;
  return options;
}

RayTimeProblemSettings Settings(bool cache, bool self_calibrate) {
  RayTimeProblemSettings settings;
  settings.use_evaluation_cache = cache;
  settings.refine_focal = settings.refine_principal_point = settings.refine_distortion =
      self_calibrate;
  settings.num_threads = 2;
  return settings;
}

// Residuals of the match blocks (no loss), via Problem::Evaluate restricted to them.
std::vector<double> MatchResiduals(RayTimeProblem* problem) {
  ceres::Problem::EvaluateOptions options;
  options.residual_blocks = problem->match_blocks();
  options.apply_loss_function = false;
  std::vector<double> residuals;
  problem->problem().Evaluate(options, nullptr, &residuals, nullptr, nullptr);
  return residuals;
}

class RefineObjectiveTest : public ::testing::TestWithParam<bool> {};  // param: distortion

TEST_P(RefineObjectiveTest, ResidualsVanishAtGroundTruth) {
  const SyntheticScene scene = MakeSyntheticScene(SmallScene(GetParam()));
  for (const bool anchored : {false, true}) {
    SCOPED_TRACE(anchored ? "anchored" : "per_observation");
    const ProblemLayout layout = anchored ? BuildAnchoredLayout(scene.input, 0, 0)
                                          : BuildPerObservationLayout(scene.input, 0, 0);
    ASSERT_GT(layout.residuals.size(), 300u);
    for (const bool cache : {true, false}) {
      SCOPED_TRACE(cache ? "cached" : "uncached");
      RayTimeProblem problem(scene.input, layout, scene.ground_truth, scene.ground_truth,
                             scene.input.intrinsics, TrueRayTimes(scene, layout),
                             Settings(cache, false));
      double worst = 0.0;
      for (double r : MatchResiduals(&problem)) worst = std::max(worst, std::abs(r));
      EXPECT_LT(worst, 1e-7) << "pixels";
      double cost = -1.0;
      problem.problem().Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr,
                                 nullptr);
      EXPECT_LT(cost, 1e-14);
    }
  }
}

// E = 1/(4M) Σ ρ(|r|²) + λp/N Σ |O - O^prior|² + λR/N Σ |Log(R^prior^-1 R)|², recomputed here
// from the residual functor and core/geometry's LogSO3, against Ceres' cost at a perturbed state.
TEST_P(RefineObjectiveTest, TotalCostEqualsTheEnergyFormula) {
  const SyntheticScene scene = MakeSyntheticScene(SmallScene(GetParam()));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  const std::vector<Rigid3> prior = JitterPoses(scene.ground_truth, 3.0, 0.4, 11);
  const std::vector<Rigid3> start = JitterPoses(scene.ground_truth, 2.0, 0.3, 12);
  const std::vector<double> ray_times = JitterValues(TrueRayTimes(scene, layout), 0.3, 13);
  RayTimeProblemSettings settings = Settings(true, false);
  settings.position_weight = 0.7;  // non-default weights, so each term is checked on its own
  settings.orientation_weight = 250.0;
  RayTimeProblem problem(scene.input, layout, prior, start, scene.input.intrinsics, ray_times,
                         settings);
  const int num_matches = layout.num_matches_used;
  const int num_cameras = static_cast<int>(start.size());
  ASSERT_EQ(layout.residuals.size(), 2u * num_matches);

  for (const double a : {100.0, 1e4}) {
    SCOPED_TRACE(a);
    problem.SetLossScale(a);
    double match_sum = 0.0;
    for (const CrossProjection& residual : layout.residuals) {
      const LayoutObservation& s = layout.observations[residual.source];
      const LayoutObservation& t = layout.observations[residual.target];
      const CrossProjectionAutoDiffCost functor(
          scene.input.keypoints[s.image].row(s.keypoint).transpose(),
          scene.input.keypoints[t.image].row(t.keypoint).transpose());
      double r[2];
      functor(problem.intrinsics_block(), problem.pose_block(s.image),
              problem.ray_time_block(s.ray_time), problem.pose_block(t.image), r);
      const double sq = r[0] * r[0] + r[1] * r[1];
      match_sum += a * std::atan(sq / a);
    }
    double position_sum = 0.0, orientation_sum = 0.0;
    for (int i = 0; i < num_cameras; ++i) {
      position_sum += (start[i].translation - prior[i].translation).squaredNorm();
      orientation_sum +=
          LogSO3(prior[i].RotationMatrix().transpose() * start[i].RotationMatrix()).squaredNorm();
    }
    const double energy = match_sum / (4.0 * num_matches) +
                          settings.position_weight / num_cameras * position_sum +
                          settings.orientation_weight / num_cameras * orientation_sum;
    double cost = 0.0;
    problem.problem().Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, nullptr);
    EXPECT_NEAR(cost, energy, 1e-11 * energy);
    EXPECT_GT(match_sum / (4.0 * num_matches), 1e-3 * energy) << "match term must matter";
  }
}

INSTANTIATE_TEST_SUITE_P(Distortion, RefineObjectiveTest, ::testing::Bool(),
                         [](const auto& info) { return info.param ? "distorted" : "pinhole"; });

// Jacobian checks of single residuals at a perturbed state.
struct JacobianCase {
  const char* name;
  bool distortion;
  bool perturb_intrinsics;  // self-calibration: intrinsics away from their true values
};

class RefineJacobianTest : public ::testing::TestWithParam<JacobianCase> {};

constexpr int kBlockSizes[4] = {kNumIntrinsics, kPoseBlockSize, 1, kPoseBlockSize};

double RelativeDifference(const std::vector<double>& a, const std::vector<double>& b) {
  double diff = 0.0, norm = 0.0;
  for (size_t k = 0; k < a.size(); ++k) {
    diff += (a[k] - b[k]) * (a[k] - b[k]);
    norm += b[k] * b[k];
  }
  return std::sqrt(diff) / std::max(std::sqrt(norm), 1e-300);
}

TEST_P(RefineJacobianTest, CachedEqualsAutoDiffAndNumeric) {
  const JacobianCase& c = GetParam();
  const SyntheticScene scene = MakeSyntheticScene(SmallScene(c.distortion));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  CameraIntrinsics intrinsics = scene.input.intrinsics;
  if (c.perturb_intrinsics) {
    intrinsics.params = {1420.0, 1380.0, 760.0, 515.0, -0.05, 0.01, 1e-3, -5e-4};
  }
  RayTimeProblem problem(scene.input, layout, scene.ground_truth,
                         JitterPoses(scene.ground_truth, 2.0, 0.3, 21), intrinsics,
                         JitterValues(TrueRayTimes(scene, layout), 0.2, 22),
                         Settings(true, c.perturb_intrinsics));
  problem.cache()->PrepareForEvaluation(/*evaluate_jacobians=*/true, /*new_point=*/true);

  double worst_autodiff = 0.0, worst_numeric = 0.0;
  for (size_t n = 0; n < layout.residuals.size(); n += 7) {
    const CrossProjection& residual = layout.residuals[n];
    const LayoutObservation& s = layout.observations[residual.source];
    const LayoutObservation& t = layout.observations[residual.target];
    const Eigen::Vector2d source_pixel = scene.input.keypoints[s.image].row(s.keypoint);
    const Eigen::Vector2d target_pixel = scene.input.keypoints[t.image].row(t.keypoint);
    std::unique_ptr<ceres::CostFunction> cached(
        CachedCrossProjectionCost::Create(problem.cache(), residual.source, residual.target));
    std::unique_ptr<ceres::CostFunction> autodiff(
        CrossProjectionAutoDiffCost::Create(source_pixel, target_pixel));
    // Ridders' default first step is 1 % of a parameter (an absolute 0.01 for a zero p1), far
    // outside the lens range where 5 Newton iterations converge; start small instead.
    ceres::NumericDiffOptions numeric_options;
    numeric_options.ridders_relative_initial_step_size = 1e-4;
    std::unique_ptr<ceres::CostFunction> numeric(
        new ceres::NumericDiffCostFunction<CrossProjectionAutoDiffCost, ceres::RIDDERS, 2,
                                           kNumIntrinsics, kPoseBlockSize, 1, kPoseBlockSize>(
            new CrossProjectionAutoDiffCost(source_pixel, target_pixel), ceres::TAKE_OWNERSHIP, 2,
            numeric_options));
    const double* parameters[4] = {problem.intrinsics_block(), problem.pose_block(s.image),
                                   problem.ray_time_block(s.ray_time), problem.pose_block(t.image)};
    std::vector<double> J[3][4];
    double* jacobians[3][4];
    double residuals[3][2];
    for (int f = 0; f < 3; ++f) {
      for (int b = 0; b < 4; ++b) {
        J[f][b].assign(2 * kBlockSizes[b], 0.0);
        jacobians[f][b] = J[f][b].data();
      }
    }
    ASSERT_TRUE(cached->Evaluate(parameters, residuals[0], jacobians[0]));
    ASSERT_TRUE(autodiff->Evaluate(parameters, residuals[1], jacobians[1]));
    ASSERT_TRUE(numeric->Evaluate(parameters, residuals[2], jacobians[2]));
    EXPECT_NEAR(residuals[0][0], residuals[1][0], 1e-9);
    EXPECT_NEAR(residuals[0][1], residuals[1][1], 1e-9);
    for (int b = 0; b < 4; ++b) {
      const double ad = RelativeDifference(J[0][b], J[1][b]);
      const double nd = RelativeDifference(J[0][b], J[2][b]);
      worst_autodiff = std::max(worst_autodiff, ad);
      worst_numeric = std::max(worst_numeric, nd);
      EXPECT_LT(ad, 1e-10) << "block " << b << " residual " << n;
      EXPECT_LT(nd, 1e-6) << "block " << b << " residual " << n;
    }
  }
  std::printf("%s: worst relative Jacobian difference %.2e vs autodiff, %.2e vs numeric\n", c.name,
              worst_autodiff, worst_numeric);
}

// The whole problem, through Ceres (manifolds, constant blocks, loss): cached and uncached give
// the same cost, gradient and Jacobian.
TEST_P(RefineJacobianTest, CachedAndUncachedProblemsAgree) {
  const JacobianCase& c = GetParam();
  const SyntheticScene scene = MakeSyntheticScene(SmallScene(c.distortion));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  const std::vector<Rigid3> start = JitterPoses(scene.ground_truth, 2.0, 0.3, 31);
  const std::vector<double> ray_times = JitterValues(TrueRayTimes(scene, layout), 0.2, 32);
  double cost[2];
  std::vector<double> gradient[2];
  ceres::CRSMatrix jacobian[2];
  for (int k = 0; k < 2; ++k) {
    RayTimeProblem problem(scene.input, layout, scene.ground_truth, start, scene.input.intrinsics,
                           ray_times, Settings(k == 0, c.perturb_intrinsics));
    problem.problem().Evaluate(ceres::Problem::EvaluateOptions(), &cost[k], nullptr, &gradient[k],
                               &jacobian[k]);
  }
  EXPECT_NEAR(cost[0], cost[1], 1e-12 * cost[1]);
  EXPECT_LT(RelativeDifference(gradient[0], gradient[1]), 1e-10);
  ASSERT_EQ(jacobian[0].num_cols, jacobian[1].num_cols);
  ASSERT_EQ(jacobian[0].rows, jacobian[1].rows);
  ASSERT_EQ(jacobian[0].cols, jacobian[1].cols);
  EXPECT_LT(RelativeDifference(jacobian[0].values, jacobian[1].values), 1e-10);
}

INSTANTIATE_TEST_SUITE_P(Cases, RefineJacobianTest,
                         ::testing::Values(JacobianCase{"pinhole", false, false},
                                           JacobianCase{"distorted", true, false},
                                           JacobianCase{"self_calibration", true, true}),
                         [](const auto& info) { return std::string(info.param.name); });

// dû/d(intrinsics) from the cache's jets against central differences of the Newton
// undistortion (paper §3.2: differentiable, ≤ 5 iterations).
TEST(RefineCacheTest, UndistortionDerivativesMatchNumeric) {
  const SyntheticScene scene = MakeSyntheticScene(SmallScene(true));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  CameraIntrinsics intrinsics = scene.input.intrinsics;
  intrinsics.params = {1390.0, 1405.0, 772.0, 505.0, -0.2, 0.06, 6e-4, -4e-4};
  RayTimeProblem problem(scene.input, layout, scene.ground_truth, scene.ground_truth, intrinsics,
                         TrueRayTimes(scene, layout), Settings(true, true));
  ObservationCache& cache = *problem.cache();
  cache.PrepareForEvaluation(true, true);
  double worst = 0.0;
  for (int o = 0; o < cache.size(); o += 5) {
    const LayoutObservation& obs = layout.observations[o];
    const double pixel[2] = {scene.input.keypoints[obs.image](obs.keypoint, 0),
                             scene.input.keypoints[obs.image](obs.keypoint, 1)};
    for (int c = 0; c < kNumIntrinsics; ++c) {
      const double h = 1e-6 * std::max(1.0, std::abs(intrinsics.params[c]));
      auto plus = intrinsics.params, minus = intrinsics.params;
      plus[c] += h;
      minus[c] -= h;
      double up[2], um[2];
      UndistortPixel(plus.data(), pixel, up);
      UndistortPixel(minus.data(), pixel, um);
      for (int r = 0; r < 2; ++r) {
        const double numeric = (up[r] - um[r]) / (2 * h);
        const double cached = cache[o].d_undistorted[kNumIntrinsics * r + c];
        const double error = std::abs(numeric - cached) / std::max(1.0, std::abs(numeric));
        worst = std::max(worst, error);
      }
    }
    // The undistorted pixel redistorts onto the observation.
    double back[2];
    DistortPixel(intrinsics.params.data(), cache[o].undistorted, back);
    EXPECT_NEAR(back[0], pixel[0], 1e-6);
    EXPECT_NEAR(back[1], pixel[1], 1e-6);
  }
  EXPECT_LT(worst, 1e-6);
}

// Recompute on a new point; jets only when Jacobians are asked for and the cache holds values
// only (PLATFORM.md "EvaluationCallback"); value and jet passes agree.
TEST(RefineCacheTest, RecomputesOnlyWhenNeeded) {
  const SyntheticScene scene = MakeSyntheticScene(SmallScene(true));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  RayTimeProblem problem(scene.input, layout, scene.ground_truth,
                         JitterPoses(scene.ground_truth, 1.0, 0.1, 41), scene.input.intrinsics,
                         TrueRayTimes(scene, layout), Settings(true, false));
  ObservationCache& cache = *problem.cache();
  cache.PrepareForEvaluation(false, true);
  EXPECT_EQ(cache.value_passes(), 1);
  EXPECT_EQ(cache.jet_passes(), 0);
  std::vector<double> values;
  for (int o = 0; o < cache.size(); ++o) {
    values.insert(values.end(), {cache[o].undistorted[0], cache[o].undistorted[1],
                                 cache[o].point[0], cache[o].point[1], cache[o].point[2]});
  }
  cache.PrepareForEvaluation(false, false);
  EXPECT_EQ(cache.value_passes(), 1);
  cache.PrepareForEvaluation(true, false);  // accepted step: Jacobian at the same point
  EXPECT_EQ(cache.jet_passes(), 1);
  cache.PrepareForEvaluation(true, false);
  cache.PrepareForEvaluation(false, false);
  EXPECT_EQ(cache.jet_passes(), 1);
  EXPECT_EQ(cache.value_passes(), 1);
  for (int o = 0; o < cache.size(); ++o) {
    EXPECT_NEAR(cache[o].undistorted[0], values[5 * o], 1e-9);
    EXPECT_NEAR(cache[o].point[2], values[5 * o + 4], 1e-9);
  }
  cache.PrepareForEvaluation(true, true);
  EXPECT_EQ(cache.jet_passes(), 2);
  cache.PrepareForEvaluation(false, true);
  EXPECT_EQ(cache.value_passes(), 2);
}

}  // namespace
}  // namespace raytime
