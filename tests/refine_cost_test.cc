// The refiner's objective (paper §3.2–3.3, §3.7): cross-projection residuals vanish at the ground
// truth, Ceres' total cost is exactly the energy of eq. (energy), and the shared evaluation
// cache's "gradient surgery" Jacobians (self-calibration) and the fixed-intrinsics residual's
// closed-form ones (every intrinsic held) equal both the uncached automatic derivatives and
// numeric differentiation, with and without distortion, and with per-image intrinsics (the
// two-block cost variant of cross_projection_cost.h).
#include <ceres/crs_matrix.h>
#include <ceres/numeric_diff_cost_function.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <string>

#include "core/geometry.h"
#include "refine/solve/cross_projection_cost.h"
#include "refine/solve/evaluation_cache.h"
#include "refine/solve/problem_layout.h"
#include "refine/solve/ray_time_problem.h"
#include "testing/synthetic_scene.h"
#include "tests/numeric_jacobian.h"
#include "tests/refine_test_util.h"

namespace raytime {
namespace {

// "pinhole", "distorted", or "per_image": distorted, each image with its own camera (focal 3 %,
// principal point 8 px apart), so every residual is of the two-block variant.
SyntheticSceneOptions SmallScene(const std::string& kind) {
  SyntheticSceneOptions options;
  options.num_cameras = 5;
  options.num_points = 120;
  options.distortion = kind != "pinhole";
  options.seed = kind == "pinhole" ? 3 : 7;
  if (kind == "per_image") {
    options.focal_drift = 0.03;
    options.principal_point_drift_px = 8.0;
  }
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

class RefineObjectiveTest : public ::testing::TestWithParam<const char*> {};  // SmallScene kind

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
                             PerCameraBlocks(scene.input), TrueRayTimes(scene, layout),
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
  RayTimeProblem problem(scene.input, layout, prior, start, PerCameraBlocks(scene.input), ray_times,
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
      double r[2];
      CrossProjectionResidual(problem.intrinsics_block(scene.input.camera_index[s.image]),
                              problem.pose_block(s.image), *problem.ray_time_block(s.ray_time),
                              problem.intrinsics_block(scene.input.camera_index[t.image]),
                              problem.pose_block(t.image),
                              scene.input.keypoints[s.image].row(s.keypoint).transpose(),
                              scene.input.keypoints[t.image].row(t.keypoint).transpose(), r);
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

INSTANTIATE_TEST_SUITE_P(Scenes, RefineObjectiveTest,
                         ::testing::Values("pinhole", "distorted", "per_image"),
                         [](const auto& info) { return std::string(info.param); });

// Jacobian checks of single residuals at a perturbed state.
struct JacobianCase {
  const char* name;
  const char* scene;        // SmallScene kind
  bool perturb_intrinsics;  // self-calibration: intrinsics away from their true values
};

class RefineJacobianTest : public ::testing::TestWithParam<JacobianCase> {};

double RelativeDifference(const std::vector<double>& a, const std::vector<double>& b) {
  double diff = 0.0, norm = 0.0;
  for (size_t k = 0; k < a.size(); ++k) {
    diff += (a[k] - b[k]) * (a[k] - b[k]);
    norm += b[k] * b[k];
  }
  return std::sqrt(diff) / std::max(std::sqrt(norm), 1e-300);
}

// The starting intrinsics of a case: the scene's, or every camera moved off its true values.
CameraBlocks CaseCameras(const SyntheticScene& scene, bool perturb) {
  CameraBlocks cameras = PerCameraBlocks(scene.input);
  if (!perturb) return cameras;
  for (CameraIntrinsics& camera : cameras.cameras) {
    auto& p = camera.params;
    p = {p[kFx] * 1.015, p[kFy] * 0.99, p[kCx] - 10.5, p[kCy] + 6.0, -0.05, 0.01, 1e-3, -5e-4};
  }
  return cameras;
}

// Residual and Jacobians of `costs` (same blocks) at `parameters`: one row per cost, one vector
// per parameter block.
struct Evaluation {
  double residual[2];
  std::vector<std::vector<double>> jacobians;
};

Evaluation Evaluate(const ceres::CostFunction& cost, const double* const* parameters) {
  Evaluation out;
  std::vector<double*> pointers;
  for (const int32_t size : cost.parameter_block_sizes()) {
    out.jacobians.emplace_back(2 * size, 0.0);
    pointers.push_back(out.jacobians.back().data());
  }
  EXPECT_TRUE(cost.Evaluate(parameters, out.residual, pointers.data()));
  return out;
}

// Ridders' default first step is 1 % of a parameter (an absolute 0.01 for a zero p1), far
// outside the lens range where 5 Newton iterations converge; start small instead.
ceres::NumericDiffOptions NumericOptions() {
  ceres::NumericDiffOptions options;
  options.ridders_relative_initial_step_size = 1e-4;
  return options;
}

TEST_P(RefineJacobianTest, CachedEqualsAutoDiffAndNumeric) {
  const JacobianCase& c = GetParam();
  const SyntheticScene scene = MakeSyntheticScene(SmallScene(c.scene));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  const CameraBlocks cameras = CaseCameras(scene, c.perturb_intrinsics);
  RayTimeProblem problem(scene.input, layout, scene.ground_truth,
                         JitterPoses(scene.ground_truth, 2.0, 0.3, 21), cameras,
                         JitterValues(TrueRayTimes(scene, layout), 0.2, 22),
                         Settings(true, c.perturb_intrinsics));
  // Self-calibration solves through the cache; held intrinsics through the fixed-intrinsics
  // residual, whose blocks are the others' source pose, ray time and target pose.
  const bool fixed = !c.perturb_intrinsics;
  ASSERT_EQ(problem.fixed_intrinsics_residuals(), fixed);
  ASSERT_EQ(problem.cache() == nullptr, fixed);
  if (!fixed)
    problem.cache()->PrepareForEvaluation(/*evaluate_jacobians=*/true, /*new_point=*/true);

  double worst_autodiff = 0.0, worst_numeric = 0.0;
  int two_block_residuals = 0;
  for (size_t n = 0; n < layout.residuals.size(); n += 7) {
    const CrossProjection& residual = layout.residuals[n];
    const LayoutObservation& s = layout.observations[residual.source];
    const LayoutObservation& t = layout.observations[residual.target];
    const Eigen::Vector2d source_pixel = scene.input.keypoints[s.image].row(s.keypoint);
    const Eigen::Vector2d target_pixel = scene.input.keypoints[t.image].row(t.keypoint);
    const int source_camera = cameras.camera_of_image[s.image];
    const int target_camera = cameras.camera_of_image[t.image];
    std::unique_ptr<ceres::CostFunction> cost[3];  // cached, autodiff, numeric
    std::vector<const double*> parameters;
    if (source_camera == target_camera) {
      cost[0].reset(
          CachedCrossProjectionCost::Create(problem.cache(), residual.source, residual.target));
      cost[1].reset(CrossProjectionAutoDiffCost::Create(source_pixel, target_pixel));
      cost[2].reset(
          new ceres::NumericDiffCostFunction<CrossProjectionAutoDiffCost, ceres::RIDDERS, 2,
                                             kNumIntrinsics, kPoseBlockSize, 1, kPoseBlockSize>(
              new CrossProjectionAutoDiffCost(source_pixel, target_pixel), ceres::TAKE_OWNERSHIP, 2,
              NumericOptions()));
      parameters = {problem.intrinsics_block(source_camera), problem.pose_block(s.image),
                    problem.ray_time_block(s.ray_time), problem.pose_block(t.image)};
    } else {
      ++two_block_residuals;
      cost[0].reset(CachedTwoCameraCrossProjectionCost::Create(problem.cache(), residual.source,
                                                               residual.target));
      cost[1].reset(TwoCameraCrossProjectionAutoDiffCost::Create(source_pixel, target_pixel));
      cost[2].reset(
          new ceres::NumericDiffCostFunction<TwoCameraCrossProjectionAutoDiffCost, ceres::RIDDERS,
                                             2, kNumIntrinsics, kPoseBlockSize, 1, kNumIntrinsics,
                                             kPoseBlockSize>(
              new TwoCameraCrossProjectionAutoDiffCost(source_pixel, target_pixel),
              ceres::TAKE_OWNERSHIP, 2, NumericOptions()));
      parameters = {problem.intrinsics_block(source_camera), problem.pose_block(s.image),
                    problem.ray_time_block(s.ray_time), problem.intrinsics_block(target_camera),
                    problem.pose_block(t.image)};
    }
    // The blocks cost[0] has, as indices into the autodiff variant's.
    std::vector<size_t> blocks(parameters.size());
    for (size_t b = 0; b < blocks.size(); ++b) blocks[b] = b;
    std::vector<const double*> own_parameters = parameters;
    if (fixed) {
      const double* source_intrinsics = problem.intrinsics_block(source_camera);
      const double* target_intrinsics = problem.intrinsics_block(target_camera);
      Eigen::Vector2d source_undistorted, target_undistorted;
      UndistortPixel(source_intrinsics, source_pixel.data(), source_undistorted.data());
      UndistortPixel(target_intrinsics, target_pixel.data(), target_undistorted.data());
      Eigen::Vector3d ray;
      PixelToUnitRay(source_intrinsics, source_undistorted.data(), ray.data());
      cost[0].reset(
          FixedIntrinsicsCrossProjectionCost::Create(ray, target_undistorted, target_intrinsics));
      blocks = {1, 2, parameters.size() - 1};
      own_parameters = {parameters[1], parameters[2], parameters.back()};
    }
    const Evaluation cached = Evaluate(*cost[0], own_parameters.data());
    const Evaluation autodiff = Evaluate(*cost[1], parameters.data());
    const Evaluation numeric = Evaluate(*cost[2], parameters.data());
    EXPECT_NEAR(cached.residual[0], autodiff.residual[0], 1e-9);
    EXPECT_NEAR(cached.residual[1], autodiff.residual[1], 1e-9);
    for (size_t k = 0; k < blocks.size(); ++k) {
      const size_t b = blocks[k];
      const double ad = RelativeDifference(cached.jacobians[k], autodiff.jacobians[b]);
      const double nd = RelativeDifference(cached.jacobians[k], numeric.jacobians[b]);
      worst_autodiff = std::max(worst_autodiff, ad);
      worst_numeric = std::max(worst_numeric, nd);
      EXPECT_LT(ad, 1e-10) << "block " << b << " residual " << n;
      EXPECT_LT(nd, 1e-6) << "block " << b << " residual " << n;
    }
  }
  if (std::string(c.scene) == "per_image") {
    EXPECT_GT(two_block_residuals, 50) << "every residual joins two cameras";
  } else {
    EXPECT_EQ(two_block_residuals, 0);
  }
  std::printf("%s: worst relative Jacobian difference %.2e vs autodiff, %.2e vs numeric\n", c.name,
              worst_autodiff, worst_numeric);
}

// The two-block variant on one camera's intrinsics given twice is the one-block variant: the same
// residual and pose and ray-time Jacobians bit for bit, and intrinsics Jacobians that sum to the
// one-block one (cached and automatic differentiation alike).
TEST(RefineTwoCameraCostTest, TwoBlocksOfOneCameraAreTheOneBlockVariant) {
  const SyntheticScene scene = MakeSyntheticScene(SmallScene("distorted"));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  const CameraBlocks cameras = CaseCameras(scene, true);
  RayTimeProblem problem(scene.input, layout, scene.ground_truth,
                         JitterPoses(scene.ground_truth, 2.0, 0.3, 23), cameras,
                         JitterValues(TrueRayTimes(scene, layout), 0.2, 24), Settings(true, true));
  problem.cache()->PrepareForEvaluation(true, true);
  for (size_t n = 0; n < layout.residuals.size(); n += 11) {
    const CrossProjection& residual = layout.residuals[n];
    const LayoutObservation& s = layout.observations[residual.source];
    const LayoutObservation& t = layout.observations[residual.target];
    const Eigen::Vector2d source_pixel = scene.input.keypoints[s.image].row(s.keypoint);
    const Eigen::Vector2d target_pixel = scene.input.keypoints[t.image].row(t.keypoint);
    const double* one[4] = {problem.intrinsics_block(0), problem.pose_block(s.image),
                            problem.ray_time_block(s.ray_time), problem.pose_block(t.image)};
    const double* two[5] = {problem.intrinsics_block(0), problem.pose_block(s.image),
                            problem.ray_time_block(s.ray_time), problem.intrinsics_block(0),
                            problem.pose_block(t.image)};
    for (const bool cached : {true, false}) {
      SCOPED_TRACE(cached ? "cached" : "autodiff");
      std::unique_ptr<ceres::CostFunction> one_block(
          cached
              ? CachedCrossProjectionCost::Create(problem.cache(), residual.source, residual.target)
              : CrossProjectionAutoDiffCost::Create(source_pixel, target_pixel));
      std::unique_ptr<ceres::CostFunction> two_blocks(
          cached ? CachedTwoCameraCrossProjectionCost::Create(problem.cache(), residual.source,
                                                              residual.target)
                 : TwoCameraCrossProjectionAutoDiffCost::Create(source_pixel, target_pixel));
      const Evaluation a = Evaluate(*one_block, one);
      const Evaluation b = Evaluate(*two_blocks, two);
      EXPECT_EQ(a.residual[0], b.residual[0]);
      EXPECT_EQ(a.residual[1], b.residual[1]);
      EXPECT_EQ(a.jacobians[1], b.jacobians[1]);  // source pose
      EXPECT_EQ(a.jacobians[2], b.jacobians[2]);  // ray time
      EXPECT_EQ(a.jacobians[3], b.jacobians[4]);  // target pose
      std::vector<double> sum(2 * kNumIntrinsics);
      for (size_t k = 0; k < sum.size(); ++k) sum[k] = b.jacobians[0][k] + b.jacobians[3][k];
      EXPECT_LT(RelativeDifference(sum, a.jacobians[0]), 1e-12) << "residual " << n;
    }
  }
}

// The whole problem, through Ceres (manifolds, constant blocks, loss): cached and uncached give
// the same cost, gradient and Jacobian.
TEST_P(RefineJacobianTest, CachedAndUncachedProblemsAgree) {
  const JacobianCase& c = GetParam();
  const SyntheticScene scene = MakeSyntheticScene(SmallScene(c.scene));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  const std::vector<Rigid3> start = JitterPoses(scene.ground_truth, 2.0, 0.3, 31);
  const std::vector<double> ray_times = JitterValues(TrueRayTimes(scene, layout), 0.2, 32);
  double cost[2];
  std::vector<double> gradient[2];
  ceres::CRSMatrix jacobian[2];
  for (int k = 0; k < 2; ++k) {
    RayTimeProblem problem(scene.input, layout, scene.ground_truth, start,
                           CaseCameras(scene, c.perturb_intrinsics), ray_times,
                           Settings(k == 0, c.perturb_intrinsics));
    // Held intrinsics: the fixed-intrinsics problem has no intrinsics blocks, the uncached one
    // has them constant; both are compared over the poses and ray times.
    ceres::Problem::EvaluateOptions options;
    if (!c.perturb_intrinsics) {
      for (size_t i = 0; i < start.size(); ++i)
        options.parameter_blocks.push_back(problem.pose_block(i));
      for (size_t t = 0; t < ray_times.size(); ++t) {
        options.parameter_blocks.push_back(problem.ray_time_block(static_cast<int>(t)));
      }
    }
    problem.problem().Evaluate(options, &cost[k], nullptr, &gradient[k], &jacobian[k]);
  }
  EXPECT_NEAR(cost[0], cost[1], 1e-12 * cost[1]);
  EXPECT_LT(RelativeDifference(gradient[0], gradient[1]), 1e-10);
  ASSERT_EQ(jacobian[0].num_cols, jacobian[1].num_cols);
  ASSERT_EQ(jacobian[0].rows, jacobian[1].rows);
  ASSERT_EQ(jacobian[0].cols, jacobian[1].cols);
  EXPECT_LT(RelativeDifference(jacobian[0].values, jacobian[1].values), 1e-10);
}

INSTANTIATE_TEST_SUITE_P(Cases, RefineJacobianTest,
                         ::testing::Values(JacobianCase{"pinhole", "pinhole", false},
                                           JacobianCase{"distorted", "distorted", false},
                                           JacobianCase{"self_calibration", "distorted", true},
                                           JacobianCase{"per_image", "per_image", false},
                                           JacobianCase{"per_image_self_calibration", "per_image",
                                                        true}),
                         [](const auto& info) { return std::string(info.param.name); });

// dû/d(intrinsics) from the cache's jets against central differences of the Newton
// undistortion (paper §3.2: differentiable, ≤ 5 iterations).
TEST(RefineCacheTest, UndistortionDerivativesMatchNumeric) {
  const SyntheticScene scene = MakeSyntheticScene(SmallScene("distorted"));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  CameraBlocks cameras = PerCameraBlocks(scene.input);
  CameraIntrinsics& intrinsics = cameras.cameras[0];
  intrinsics.params = {1390.0, 1405.0, 772.0, 505.0, -0.2, 0.06, 6e-4, -4e-4};
  RayTimeProblem problem(scene.input, layout, scene.ground_truth, scene.ground_truth, cameras,
                         TrueRayTimes(scene, layout), Settings(true, true));
  ObservationCache& cache = *problem.cache();
  cache.PrepareForEvaluation(true, true);
  double worst = 0.0;
  for (int o = 0; o < cache.size(); o += 5) {
    const LayoutObservation& obs = layout.observations[o];
    const double pixel[2] = {scene.input.keypoints[obs.image](obs.keypoint, 0),
                             scene.input.keypoints[obs.image](obs.keypoint, 1)};
    const auto undistort = [&](const Eigen::VectorXd& params) {
      Eigen::Vector2d u;
      UndistortPixel(params.data(), pixel, u.data());
      return u;
    };
    const Eigen::MatrixXd numeric = NumericJacobian(
        undistort, Eigen::Map<const Eigen::VectorXd>(intrinsics.params.data(), kNumIntrinsics),
        1e-6);
    for (int c = 0; c < kNumIntrinsics; ++c) {
      for (int r = 0; r < 2; ++r) {
        const double cached = cache[o].d_undistorted[kNumIntrinsics * r + c];
        const double error =
            std::abs(numeric(r, c) - cached) / std::max(1.0, std::abs(numeric(r, c)));
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
  const SyntheticScene scene = MakeSyntheticScene(SmallScene("distorted"));
  const ProblemLayout layout = BuildPerObservationLayout(scene.input, 0, 0);
  // Self-calibrating: with every intrinsic held the problem needs no cache.
  RayTimeProblem problem(
      scene.input, layout, scene.ground_truth, JitterPoses(scene.ground_truth, 1.0, 0.1, 41),
      PerCameraBlocks(scene.input), TrueRayTimes(scene, layout), Settings(true, true));
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
