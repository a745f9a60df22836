#include "bootstrap/relative_pose.h"

#include <opengv/relative_pose/CentralRelativeAdapter.hpp>
#include <opengv/sac/Ransac.hpp>
#include <opengv/sac_problems/relative_pose/CentralRelativePoseSacProblem.hpp>
#include <opengv/sac_problems/relative_pose/RotationOnlySacProblem.hpp>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <memory>
#include <stdexcept>

#include "core/error.h"
#include "core/geometry.h"
#include "core/statistics.h"

namespace raytime {
namespace {

using SacProblem = opengv::sac_problems::relative_pose::CentralRelativePoseSacProblem;
using RotationSacProblem = opengv::sac_problems::relative_pose::RotationOnlySacProblem;

SacProblem::algorithm_t AlgorithmFromName(const std::string& name) {
  if (name == "stewenius") return SacProblem::STEWENIUS;
  if (name == "nister") return SacProblem::NISTER;
  throw InputError("relative_pose.algorithm must be 'stewenius' or 'nister', got '" + name + "'");
}

// The five-point model fitted by RANSAC (with `inliers`) and whether it is usable. OpenGV's model
// is cam1_from_cam2 (X1 = R X2 + t). RANSAC does not polish (PLATFORM.md); the polish is kept only
// when it loses no inlier, since the non-linear step can wander on near-degenerate pairs.
struct EssentialFit {
  bool found = false;
  opengv::transformation_t model = opengv::transformation_t::Zero();
  std::vector<int> inliers;
};

EssentialFit FitEssential(opengv::relative_pose::CentralRelativeAdapter& adapter, double angle,
                          const RelativePoseOptions& options, RelativePoseResult* result) {
  auto problem = std::make_shared<SacProblem>(adapter, AlgorithmFromName(options.algorithm),
                                              /*randomSeed=*/false);
  opengv::sac::Ransac<SacProblem> ransac;
  ransac.sac_model_ = problem;
  ransac.threshold_ = 2.0 * (1.0 - std::cos(angle));
  ransac.max_iterations_ = options.max_iterations;
  ransac.probability_ = options.confidence;
  EssentialFit fit;
  if (!ransac.computeModel()) return fit;
  result->ransac_iterations = ransac.iterations_;
  fit.model = ransac.model_coefficients_;
  fit.inliers = ransac.inliers_;
  opengv::transformation_t polished;
  problem->optimizeModelCoefficients(fit.inliers, fit.model, polished);
  if (polished.allFinite() && polished.col(3).norm() > 0) {
    std::vector<int> polished_inliers;
    problem->selectWithinDistance(polished, ransac.threshold_, polished_inliers);
    if (polished_inliers.size() >= fit.inliers.size()) {
      fit.model = polished;
      fit.inliers = std::move(polished_inliers);
      result->polished = true;
    }
  }
  fit.found = fit.model.allFinite() && fit.model.col(3).norm() > 0;
  return fit;
}

// Rotation-only model: under a (near-)pure rotation the five-point problem is degenerate and its
// RANSAC scoring, which triangulates nearly parallel rays, is unreliable; this model needs no
// baseline. Its criterion is the single angle 1 - cos(ray 1, R ray 2), so the threshold allows the
// sum of the two per-image errors. Returns cam1_from_cam2 (identity when none) and its inliers.
Eigen::Matrix3d FitRotationOnly(opengv::relative_pose::CentralRelativeAdapter& adapter,
                                double angle, const RelativePoseOptions& options,
                                std::vector<int>* inliers) {
  auto problem = std::make_shared<RotationSacProblem>(adapter, /*randomSeed=*/false);
  opengv::sac::Ransac<RotationSacProblem> ransac;
  ransac.sac_model_ = problem;
  ransac.threshold_ = 1.0 - std::cos(2.0 * angle);
  ransac.max_iterations_ = options.max_iterations;
  ransac.probability_ = options.confidence;
  Eigen::Matrix3d model = Eigen::Matrix3d::Identity();
  if (ransac.computeModel()) {
    problem->optimizeModelCoefficients(ransac.inliers_, ransac.model_coefficients_, model);
    problem->selectWithinDistance(model, ransac.threshold_, *inliers);
    model = Orthonormalize(model);
  }
  return model;
}

// Median angle between ray 1 and the rotated ray 2 over the inliers, degrees. Independent of the
// (possibly arbitrary) translation: under a pure rotation every ray 1 coincides with its rotated
// ray 2, whatever the estimated t.
double MedianParallaxDeg(const opengv::bearingVectors_t& rays1,
                         const opengv::bearingVectors_t& rays2,
                         const Eigen::Matrix3d& cam1_from_cam2, const std::vector<int>& inliers) {
  std::vector<double> parallax;
  parallax.reserve(inliers.size());
  for (int k : inliers) {
    const Eigen::Vector3d r2 = cam1_from_cam2 * rays2[k];
    parallax.push_back(std::atan2(rays1[k].cross(r2).norm(), rays1[k].dot(r2)));
  }
  return DegreesFromRadians(FiniteUpperMedian(std::move(parallax)));
}

}  // namespace

RelativePoseResult EstimateRelativePose(const Eigen::Matrix3Xd& bearings1,
                                        const Eigen::Matrix3Xd& bearings2, double focal_px,
                                        const RelativePoseOptions& options) {
  ValidateOptions(options, "relative pose");
  if (bearings1.cols() != bearings2.cols()) {
    throw std::invalid_argument("EstimateRelativePose: bearing sets differ in size");
  }
  if (!(focal_px > 0)) throw std::invalid_argument("EstimateRelativePose: focal_px must be > 0");
  RelativePoseResult result;
  const int n = static_cast<int>(bearings1.cols());
  if (n < options.min_inliers) {
    result.status = PairStatus::kTooFewInliers;
    return result;
  }

  // The adapter keeps references (PLATFORM.md): these vectors outlive every use below.
  opengv::bearingVectors_t rays1(n), rays2(n);
  for (int k = 0; k < n; ++k) {
    rays1[k] = bearings1.col(k).normalized();
    rays2[k] = bearings2.col(k).normalized();
  }
  opengv::relative_pose::CentralRelativeAdapter adapter(rays1, rays2);
  const double angle = std::atan(options.max_error_px / focal_px);

  // 1. The five-point essential matrix, then the rotation-only model.
  EssentialFit essential = FitEssential(adapter, angle, options, &result);
  result.essential_inliers = essential.found ? static_cast<int>(essential.inliers.size()) : 0;
  std::vector<int> rotation_inliers;
  const Eigen::Matrix3d rotation_model =
      FitRotationOnly(adapter, angle, options, &rotation_inliers);
  result.rotation_inliers = static_cast<int>(rotation_inliers.size());

  // 2. The rotation-only model where it explains (nearly) every essential inlier.
  const bool rotation_explains_all =
      result.rotation_inliers > 0 &&
      result.rotation_inliers >= options.pure_rotation_ratio * result.essential_inliers;
  if (!essential.found && !rotation_explains_all) return result;
  Eigen::Matrix3d cam1_from_cam2;
  std::vector<int> inliers;
  if (rotation_explains_all) {
    cam1_from_cam2 = rotation_model;
    inliers = rotation_inliers;
    result.translation = Eigen::Vector3d::Zero();
  } else {
    cam1_from_cam2 = Orthonormalize(essential.model.leftCols<3>());
    result.translation = -(cam1_from_cam2.transpose() * essential.model.col(3)).normalized();
    inliers = std::move(essential.inliers);
  }
  result.rotation = cam1_from_cam2.transpose();
  result.inliers = inliers;

  // 3. The verdict: enough inliers, and parallax enough for a baseline.
  result.median_parallax_deg = MedianParallaxDeg(rays1, rays2, cam1_from_cam2, inliers);
  if (static_cast<int>(inliers.size()) < options.min_inliers) {
    result.status = PairStatus::kTooFewInliers;
  } else if (rotation_explains_all || result.median_parallax_deg < options.min_parallax_deg) {
    result.status = PairStatus::kPureRotation;
  } else {
    result.status = PairStatus::kValid;
  }
  return result;
}

}  // namespace raytime
