// The track finish (issue 50): the bundle adjustment with one point per track
// (refine/solve/track_adjustment.h) against numeric differentiation and a known shape, and the
// finish in a refine (refine/recipes/track_finish.h): kept on a scene with noise and wrong matches,
// and, when its check rejects it, the ray-time solution returned bit for bit.
#include "refine/recipes/track_finish.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <string>
#include <vector>

#include "core/options.h"
#include "refine/refine.h"
#include "refine/solve/track_adjustment.h"
#include "testing/synthetic_scene.h"
#include "tests/numeric_jacobian.h"
#include "tests/refine_test_util.h"

namespace raytime {
namespace {

// The scene's tracks as a TrackAdjustmentProblem at the truth (no distortion: keypoints are the
// undistorted pixels), every point seen by at least two cameras.
TrackAdjustmentProblem ProblemAtTheTruth(const SyntheticScene& scene) {
  TrackAdjustmentProblem problem;
  problem.world_from_cam = scene.ground_truth;
  problem.anchor = scene.ground_truth;
  const CameraIntrinsics& camera = scene.input.cameras.front();
  for (size_t i = 0; i < scene.ground_truth.size(); ++i) {
    problem.pinhole.emplace_back(camera.fx(), camera.params[kFy], camera.params[kCx],
                                 camera.params[kCy]);
  }
  for (size_t p = 0; p < scene.points.size(); ++p) {
    int seen = 0;
    for (size_t i = 0; i < scene.ground_truth.size(); ++i)
      seen += scene.keypoint_of_point[i][p] >= 0;
    if (seen < 2) continue;
    const int k = static_cast<int>(problem.points.size());
    problem.points.push_back(scene.points[p]);
    for (size_t i = 0; i < scene.ground_truth.size(); ++i) {
      const int keypoint = scene.keypoint_of_point[i][p];
      if (keypoint < 0) continue;
      problem.observation_track.push_back(k);
      problem.observation_image.push_back(static_cast<int>(i));
      problem.observation_pixel.push_back(scene.input.keypoints[i].row(keypoint).transpose());
    }
  }
  return problem;
}

SyntheticScene Scene(double pixel_noise, double outlier_fraction) {
  SyntheticSceneOptions options;
  options.num_cameras = 8;
  options.num_points = 300;
  options.pixel_noise = pixel_noise;
  options.outlier_fraction = outlier_fraction;
  options.seed = 3;
  return MakeSyntheticScene(options);
}

TEST(TrackAdjustmentTest, JacobiansMatchNumericDifferentiation) {
  TrackAdjustmentProblem problem = ProblemAtTheTruth(Scene(0.0, 0.0));
  problem.world_from_cam = JitterPoses(problem.world_from_cam, 2.0, 0.3, 11);
  for (const int o : {0, 7, 40}) {
    SCOPED_TRACE(o);
    const int image = problem.observation_image[o];
    const int track = problem.observation_track[o];
    // x = (φ, δO, δX): R ← Exp(φ)·R, O ← O + δO, X ← X + δX.
    const auto residual = [&](const Eigen::VectorXd& x) {
      TrackAdjustmentProblem moved = problem;
      Rigid3& pose = moved.world_from_cam[image];
      const Eigen::Vector3d phi = x.head<3>();
      if (phi.norm() > 0) {
        pose.rotation =
            Eigen::Quaterniond(Eigen::AngleAxisd(phi.norm(), phi.normalized())) * pose.rotation;
      }
      pose.translation += x.segment<3>(3);
      moved.points[track] += x.tail<3>();
      return Eigen::Vector2d(TrackResidual(moved, o));
    };
    const Eigen::MatrixXd numeric = NumericJacobian(residual, Eigen::VectorXd::Zero(9), 1e-6);
    Eigen::Matrix<double, 2, 6> pose_jacobian;
    Eigen::Matrix<double, 2, 3> point_jacobian;
    TrackResidualJacobians(problem, o, &pose_jacobian, &point_jacobian);
    EXPECT_LT((numeric.leftCols<6>() - pose_jacobian).norm(), 1e-5 * pose_jacobian.norm());
    EXPECT_LT((numeric.rightCols<3>() - point_jacobian).norm(), 1e-5 * point_jacobian.norm());
  }
}

// Noise-free tracks from poses 1° and 0.3 m off and points 0.2 m off: the shape comes back exactly
// (the gauge is the held camera's, so compared after Sim(3)).
TEST(TrackAdjustmentTest, RecoversTheShapeFromAPerturbedStart) {
  const SyntheticScene scene = Scene(0.0, 0.0);
  TrackAdjustmentProblem problem = ProblemAtTheTruth(scene);
  problem.world_from_cam = JitterPoses(scene.ground_truth, 1.0, 0.3, 5);
  problem.anchor = problem.world_from_cam;
  for (size_t k = 0; k < problem.points.size(); ++k) {
    problem.points[k] += 0.2 * Eigen::Vector3d(std::sin(k), std::cos(3.0 * k), std::sin(7.0 * k));
  }
  const PoseErrorSummary start = Errors(problem.world_from_cam, scene.ground_truth, "sim3");
  const TrackAdjustmentSummary summary = AdjustTracks(&problem);
  EXPECT_TRUE(summary.converged) << summary.message;
  const PoseErrorSummary errors = Errors(problem.world_from_cam, scene.ground_truth, "sim3");
  EXPECT_GT(start.mean_rotation_deg, 0.3);
  EXPECT_LT(errors.mean_rotation_deg, 1e-6);
  EXPECT_LT(errors.mean_centre_relative, 1e-7);
  EXPECT_LT(summary.final_cost, 1e-14);
}

RefineOptions AutoPreset() {
  const std::string path = std::string(RAYTIME_SOURCE_DIR) + "/configs/presets/refine/auto.yaml";
  RefineOptions options;
  ApplyYaml(LoadYamlFile(path), options, path, "refine preset 'auto'");
  return options;
}

// 0.5 px noise and 5 % of every pair's matches wrong, from a 0.5° ladder prior: the finish runs on
// the matches the solution explains, leaves the wrong ones out, and lands within the bound's
// reach (the Cramér–Rao bound's RMS rotation on this scene is 0.027°, docs/efficiency.md).
TEST(TrackFinishTest, KeptOnNoisyTracksWithWrongMatches) {
  const SyntheticScene scene = Scene(0.5, 0.05);
  RefineInput input = scene.input;
  input.prior_world_from_cam = PerturbedPrior(scene, 0.5, 2);
  const RefineOptions options = AutoPreset();
  ASSERT_TRUE(options.track_finish);
  RefineOutput output;
  const RefineSummary summary = RefinePoses(input, options, &output);
  const TrackFinishSummary& finish = summary.track_finish;
  EXPECT_TRUE(finish.accepted) << finish.reason;
  EXPECT_EQ(summary.uncertainty.estimator, "track_adjustment");
  EXPECT_LT(finish.num_inliers, finish.num_matches * 0.97);  // the wrong 5 % left out
  EXPECT_GT(finish.num_inliers, finish.num_matches * 0.85);
  EXPECT_GT(finish.num_tracks, 250);
  EXPECT_NEAR(summary.uncertainty.sigma_px_estimated, 0.5, 0.1);
  EXPECT_LE(finish.max_move_sigma, options.track_finish_max_move_sigma);
  const PoseErrorSummary errors = Errors(output.world_from_cam, scene.ground_truth, "sim3");
  EXPECT_LT(errors.mean_rotation_deg, 0.06);
  EXPECT_EQ(output.pass_world_from_cam.count("track_finish"), 1u);
}

// A finish the check rejects (here: any move at all) returns exactly what the refine returns
// without it, and the summary says which test.
TEST(TrackFinishTest, RejectedFinishLeavesTheRayTimeSolution) {
  const SyntheticScene scene = Scene(0.5, 0.0);
  RefineInput input = scene.input;
  input.prior_world_from_cam = PerturbedPrior(scene, 0.5, 4);
  RefineOptions options = AutoPreset();
  options.track_finish_max_move_sigma = 1e-9;
  RefineOutput rejected;
  const RefineSummary summary = RefinePoses(input, options, &rejected);
  EXPECT_TRUE(summary.track_finish.ran);
  EXPECT_FALSE(summary.track_finish.accepted);
  EXPECT_NE(summary.track_finish.reason.find("moved frame"), std::string::npos)
      << summary.track_finish.reason;
  EXPECT_EQ(summary.uncertainty.estimator, "ray_time");

  options.track_finish = false;
  RefineOutput without;
  const RefineSummary plain = RefinePoses(input, options, &without);
  EXPECT_FALSE(plain.track_finish.enabled);
  ASSERT_EQ(rejected.world_from_cam.size(), without.world_from_cam.size());
  for (size_t i = 0; i < without.world_from_cam.size(); ++i) {
    EXPECT_EQ(rejected.world_from_cam[i].rotation.coeffs(),
              without.world_from_cam[i].rotation.coeffs());
    EXPECT_EQ(rejected.world_from_cam[i].translation, without.world_from_cam[i].translation);
  }
  EXPECT_EQ(summary.uncertainty.median_rotation_deg, plain.uncertainty.median_rotation_deg);
  EXPECT_EQ(rejected.solved_observations.ray_times, without.solved_observations.ray_times);
}

}  // namespace
}  // namespace raytime
