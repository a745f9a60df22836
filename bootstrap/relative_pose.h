// Two-view relative pose of one verified pair: OpenGV five-point essential matrix in RANSAC on the
// stored inlier correspondences, then a non-linear polish (SPEC §4; paper §4.8 "Refinement without
// an external prior": "five-point essential matrices on the stored inlier correspondences").
#pragma once

#include <Eigen/Core>
#include <string>
#include <vector>
#include "core/options.h"

#include "bootstrap/view_graph.h"

namespace raytime {

struct RelativePoseOptions {
  // Minimal solver inside RANSAC: "stewenius" or "nister" (both five-point, OpenGV).
  std::string algorithm = "stewenius";
  // Inlier threshold in pixels at the focal length passed in; converted to OpenGV's bearing
  // criterion (1 - cos a1) + (1 - cos a2) with a = atan(max_error_px / focal).
  double max_error_px = 2.0;
  int max_iterations = 1000;  // RANSAC iterations at most (adaptive below that)
  double confidence = 0.999;  // RANSAC success probability for the adaptive stop
  // Fewer five-point inliers than this: PairStatus::kTooFewInliers, not used by any averaging.
  int min_inliers = 30;
  // Near-pure rotation (PairStatus::kPureRotation: the rotation is sound, the translation
  // direction is not) when a rotation-only model (infinite homography) explains at least
  // pure_rotation_ratio times as many correspondences as the essential matrix, or when the median
  // parallax of the essential inliers (angle between ray 1 and the rotated ray 2, degrees) is
  // below min_parallax_deg.
  double pure_rotation_ratio = 0.9;
  double min_parallax_deg = 1.0;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("algorithm", algorithm, "Five-point minimal solver inside RANSAC (OpenGV)",
      OneOf({"stewenius", "nister"}));
    v("max_error_px", max_error_px, "Five-point RANSAC inlier threshold, pixels at the focal",
      Positive(), AtMost(1000));
    v("max_iterations", max_iterations, "Five-point RANSAC iterations at most", Positive(),
      AtMost(1e7));
    v("confidence", confidence, "Five-point RANSAC success probability for the adaptive stop",
      Positive(), Below(1));
    v("min_inliers", min_inliers,
      "Pairs with fewer five-point inliers are unusable (8 = OpenGV's sample)", AtLeast(8),
      AtMost(1e6));
    v("pure_rotation_ratio", pure_rotation_ratio,
      "Near-pure rotation when a rotation-only model explains this share of the essential "
      "inliers",
      Positive(), AtMost(1));
    v("min_parallax_deg", min_parallax_deg,
      "Near-pure rotation below this median parallax of the essential inliers, degrees",
      NonNegative(), AtMost(180));
  }
};

struct RelativePoseResult {
  PairStatus status = PairStatus::kFailed;
  // cam2_from_cam1 (see ViewGraphEdge); translation is unit length, zero when the rotation-only
  // model was chosen.
  Eigen::Matrix3d rotation = Eigen::Matrix3d::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  std::vector<int> inliers;   // column indices of the correspondences
  int essential_inliers = 0;  // five-point model (after the polish)
  int rotation_inliers = 0;   // rotation-only model
  double median_parallax_deg = 0.0;
  int ransac_iterations = 0;
  bool polished = false;  // the non-linear polish was kept (it did not lose inliers)
};

// `bearings1.col(k)` and `bearings2.col(k)` are the unit rays (camera frame: x right, y down,
// z forward) of correspondence k. `focal_px` converts the pixel threshold into ray angles.
// Deterministic: RANSAC runs with OpenGV's fixed seed.
RelativePoseResult EstimateRelativePose(const Eigen::Matrix3Xd& bearings1,
                                        const Eigen::Matrix3Xd& bearings2, double focal_px,
                                        const RelativePoseOptions& options);

}  // namespace raytime
