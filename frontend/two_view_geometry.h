// Geometric verification of one image pair (SPEC §5, paper §4.1): a robust essential matrix when
// both cameras have known intrinsics, a fundamental matrix otherwise, estimated by OpenCV's
// RANSAC or USAC MAGSAC++ on point correspondences. No pose prior is used.
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>

#include "core/features.h"

namespace raytime {

using PointList = Eigen::Matrix<double, Eigen::Dynamic, 2>;  // rows: x, y (pixels)

enum class RobustEstimator {
  kMagsac,  // cv::USAC_MAGSAC (MAGSAC++; Barath et al. 2020)
  kRansac,  // cv::RANSAC (essential) / cv::FM_RANSAC (fundamental)
};
// "magsac", "ransac"; InputError naming `what` otherwise.
RobustEstimator ParseRobustEstimator(const std::string& name, const std::string& what);

struct GeometryEstimate {
  // E, F, config and cam2_from_cam1 filled; inlier_matches left empty (see `inliers`).
  TwoViewGeometry geometry;
  std::vector<int> inliers;  // indices into the correspondences, increasing
};

// Estimates the geometry of correspondences x1.row(k) <-> x2.row(k), given in undistorted pixels
// (OpenCV convention). The robust estimator runs at ransac_error_px, the polished model then
// takes as inliers every correspondence within max_error_px (Sampson distance, pixels): a tight
// estimation threshold separates the true model from near-degenerate ones (a dominant plane
// leaves a second essential matrix that explains a 4 px band), a looser inlier threshold keeps
// the correct matches that keypoint noise puts a few pixels off.
//
// With K1 and K2 (pinhole matrices of the two cameras; both null for the uncalibrated case):
// five-point essential matrix on normalized coordinates (thresholds divided by the mean focal
// length), the relative pose cam2_from_cam1 (x2 = R x1 + t, |t| = 1) by the cheirality test on
// the robust inliers (cv::recoverPose), polished by robust Levenberg-Marquardt on their Sampson
// residuals; E = [t]x R, F = K2^-T E K1^-1, config kCalibrated.
// Without: fundamental matrix in pixels polished by the eight-point fit to its inliers, config
// kUncalibrated, pose left at identity.
// Fewer than 8 correspondences or inliers, or a failed estimation, give config kUndefined and no
// inliers. Deterministic: OpenCV's estimators seed their generators with a constant.
GeometryEstimate EstimateTwoViewGeometry(const PointList& x1, const PointList& x2,
                                         const Eigen::Matrix3d* K1, const Eigen::Matrix3d* K2,
                                         RobustEstimator estimator, double ransac_error_px,
                                         double max_error_px, double confidence,
                                         int max_iterations);

// Sampson distance (pixels) of x2^T F x1 = 0 for each correspondence.
Eigen::VectorXd SampsonDistances(const Eigen::Matrix3d& F, const PointList& x1,
                                 const PointList& x2);

}  // namespace raytime
