// Per-camera uncertainty from the solve (refine/checks/pose_uncertainty.h, issue 32): on a
// synthetic scene with known keypoint noise, the predicted σ of each camera's rotation and centre
// against the spread of the solutions over independent noise draws (same scene, same prior).
#include "refine/checks/pose_uncertainty.h"

#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/statistics.h"
#include "refine/refine.h"
#include "testing/synthetic_scene.h"
#include "tests/refine_test_util.h"

namespace raytime {
namespace {

struct Calibration {
  std::vector<double> predicted_rotation_deg, observed_rotation_deg;
  std::vector<double> predicted_centre, observed_centre;
  double sigma_px_estimated = 0.0;  // median over the draws
};

// `num_draws` solves of one scene whose keypoints carry fresh N(0, sigma_px²) noise each time.
Calibration Calibrate(const SyntheticSceneOptions& scene_options, double sigma_px, int num_draws,
                      double orientation_weight, RayTimeParameterization parameterization,
                      bool track_finish) {
  const SyntheticScene scene = MakeSyntheticScene(scene_options);
  const int n = static_cast<int>(scene.ground_truth.size());
  RefineOptions options;
  options.solver = RefineSolver::kRayTimeLm;
  options.orientation_weight = orientation_weight;
  options.parameterization = parameterization;
  options.trust_region = false;
  options.wander_test = false;
  options.inconsistent_pairs_test = false;
  options.track_finish = track_finish;
  std::vector<std::vector<Rigid3>> solutions;
  std::vector<std::vector<PoseUncertainty>> predictions;
  std::vector<double> sigmas;
  std::mt19937_64 rng(17);
  std::normal_distribution<double> noise(0.0, sigma_px);
  for (int d = 0; d < num_draws; ++d) {
    RefineInput input = scene.input;
    input.prior_world_from_cam = JitterPoses(scene.ground_truth, 2.0, 0.2, 5);
    for (auto& keypoints : input.keypoints) {
      for (Eigen::Index k = 0; k < keypoints.rows(); ++k) {
        keypoints(k, 0) += noise(rng);
        keypoints(k, 1) += noise(rng);
      }
    }
    RefineOutput output;
    const RefineSummary summary = RefinePoses(input, options, &output);
    EXPECT_TRUE(summary.uncertainty.computed) << summary.uncertainty.reason;
    // The estimator whose poses were returned (the finish is kept on these noise-only scenes).
    EXPECT_EQ(summary.uncertainty.estimator, track_finish ? "track_adjustment" : "ray_time");
    solutions.push_back(output.world_from_cam);
    predictions.push_back(summary.uncertainty.cameras);
    sigmas.push_back(summary.uncertainty.sigma_px_estimated);
  }
  Calibration out;
  out.sigma_px_estimated = Median(sigmas, 0.0);
  for (int i = 0; i < n; ++i) {
    // The spread about the draws' mean pose: rotations as Log(R̄ᵀ R) (R ← Exp(φ)·R: world side).
    const Eigen::Quaterniond reference = solutions[0][i].rotation;
    Eigen::Vector3d mean_phi = Eigen::Vector3d::Zero(), mean_centre = Eigen::Vector3d::Zero();
    std::vector<Eigen::Vector3d> phis;
    for (const auto& solution : solutions) {
      const Eigen::AngleAxisd log(solution[i].rotation * reference.conjugate());
      phis.push_back(log.angle() * log.axis());
      mean_phi += phis.back() / num_draws;
      mean_centre += solution[i].translation / num_draws;
    }
    double rotation_sq = 0.0, centre_sq = 0.0, predicted_rotation = 0.0, predicted_centre = 0.0;
    for (int d = 0; d < num_draws; ++d) {
      rotation_sq += (phis[d] - mean_phi).squaredNorm() / (num_draws - 1);
      centre_sq += (solutions[d][i].translation - mean_centre).squaredNorm() / (num_draws - 1);
      predicted_rotation += predictions[d][i].rotation_deg / num_draws;
      predicted_centre += predictions[d][i].centre / num_draws;
    }
    out.observed_rotation_deg.push_back(std::sqrt(rotation_sq) * 180.0 / M_PI);
    out.observed_centre.push_back(std::sqrt(centre_sq));
    out.predicted_rotation_deg.push_back(predicted_rotation);
    out.predicted_centre.push_back(predicted_centre);
  }
  return out;
}

double MedianRatio(const std::vector<double>& predicted, const std::vector<double>& observed) {
  std::vector<double> ratios;
  for (size_t i = 0; i < predicted.size(); ++i) ratios.push_back(predicted[i] / observed[i]);
  return Median(ratios, 0.0);
}

struct CalibrationCase {
  const char* name;
  int num_cameras;
  int num_points;
  double sigma_px;
  double orientation_weight;
  RayTimeParameterization parameterization;
  bool distortion;
  bool track_finish = false;
};

// Within 20 % (the bar), per case: the median over cameras of predicted / observed σ, for
// rotations and centres, and the keypoint noise estimated from the residuals. 40 draws put the
// observed σ within about ±11 % (1/sqrt(2·39)) of the true spread.
TEST(PoseUncertaintyTest, PredictedSigmaMatchesTheSpreadOverNoiseDraws) {
  const CalibrationCase cases[] = {
      {"8 cameras, 0.5 px, λR 0", 8, 300, 0.5, 0.0, RayTimeParameterization::kPerObservation,
       false},
      {"8 cameras, 0.5 px, λR 1e3", 8, 300, 0.5, 1e3, RayTimeParameterization::kPerObservation,
       false},
      {"12 cameras, 1 px, anchored", 12, 300, 1.0, 0.0, RayTimeParameterization::kAnchored, false},
      {"8 cameras, 0.3 px, distorted", 8, 300, 0.3, 0.0, RayTimeParameterization::kPerObservation,
       true},
      // Issue 50: the track finish's bundle adjustment, its own covariance (points eliminated).
      {"8 cameras, 0.5 px, track finish", 8, 300, 0.5, 0.0,
       RayTimeParameterization::kPerObservation, false, true},
      {"12 cameras, 1 px, track finish", 12, 300, 1.0, 0.0,
       RayTimeParameterization::kPerObservation, false, true},
  };
  for (const CalibrationCase& test : cases) {
    SCOPED_TRACE(test.name);
    SyntheticSceneOptions scene;
    scene.num_cameras = test.num_cameras;
    scene.num_points = test.num_points;
    scene.distortion = test.distortion;
    scene.seed = 3;
    const Calibration c = Calibrate(scene, test.sigma_px, 40, test.orientation_weight,
                                    test.parameterization, test.track_finish);
    const double rotation = MedianRatio(c.predicted_rotation_deg, c.observed_rotation_deg);
    const double centre = MedianRatio(c.predicted_centre, c.observed_centre);
    std::printf(
        "%s: median σ rotation predicted %.4f° observed %.4f° (ratio %.2f), centre "
        "predicted %.5f observed %.5f (ratio %.2f); keypoint noise estimated %.3f px "
        "(true %.2f)\n",
        test.name, Median(c.predicted_rotation_deg, 0.0), Median(c.observed_rotation_deg, 0.0),
        rotation, Median(c.predicted_centre, 0.0), Median(c.observed_centre, 0.0), centre,
        c.sigma_px_estimated, test.sigma_px);
    EXPECT_NEAR(c.sigma_px_estimated / test.sigma_px, 1.0, 0.2);
    EXPECT_NEAR(rotation, 1.0, 0.2);
    EXPECT_NEAR(centre, 1.0, 0.2);
  }
}

}  // namespace
}  // namespace raytime
