// Pose errors of an estimate against ground truth after Sim(3), SE(3) or no alignment
// (SPEC §6; paper §4.1 Setup, §4.9 "Refinement in the prior's own frame").
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/geometry.h"
#include "core/options.h"
#include "core/types.h"

namespace raytime {

struct PoseErrorOptions {
  // "sim3" (Umeyama on camera centres, with scale: the standard protocol), "se3", or "none"
  // (the prior's own metric frame).
  std::string alignment = "sim3";
  // Success: mean rotation error below this, degrees (paper §4.8: 1°).
  double success_rotation_deg = 1.0;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("alignment", alignment,
      "Alignment before scoring: Sim(3) on centres (standard), SE(3), or none (prior's frame)",
      OneOf({"sim3", "se3", "none"}));
    v("success_rotation_deg", success_rotation_deg,
      "Success: mean rotation error below this, degrees (§4.8: 1°)", Positive(), AtMost(180));
  }
};

struct FrameError {
  std::string name;
  double rotation_deg = 0.0;  // angle of R_gt^-1 R_est after alignment (atan2)
  double centre_m = 0.0;      // |C_est - C_gt| after alignment, ground-truth units
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(FrameError, name, rotation_deg, centre_m)

// The numbers of one pose set's errors under one alignment: what the evaluate stage reports and
// what a sweep's rows (report/sweep_row.h) and the campaign report read back. Field names are
// the JSON keys and a sweep's CSV columns (VisitFields).
struct PoseErrorStatistics {
  int num_frames = 0;
  double mean_rotation_deg = 0.0;
  double median_rotation_deg = 0.0;
  double mean_centre_m = 0.0;
  double median_centre_m = 0.0;
  // Centre errors divided by the scene scale (median distance of the ground-truth centres from
  // their centroid), so scenes of different size compare.
  double scene_scale_m = 0.0;
  double mean_centre_relative = 0.0;
  double median_centre_relative = 0.0;
  // Alignment-free: the angle between the estimated and the ground-truth relative rotation of
  // frame pairs (every pair up to kMaxRelativePairs, an even stride over them beyond). A world
  // rotation cancels, so it holds where the centre alignment is ill-conditioned: on a sweep with
  // nearly collinear centres a Sim(3) fit on centres can turn the frame by tenths of a degree
  // (docs/real_captures.md, the desk capture).
  int num_relative_pairs = 0;
  double mean_relative_rotation_deg = 0.0;
  double median_relative_rotation_deg = 0.0;
  // How far the fitted alignment's own rotation is determined (sim3, se3; 0 for none): the RMS
  // angle by which the centre fit turns the frame when the centres carry errors as large as
  // those left after it (AlignmentRotationSigma). Every aligned frame's rotation error carries
  // that turn, so Sim(3) rotation errors that differ by less than this are not told apart by the
  // fit: the Strecha scenes' cameras lie in a plane within centimetres, and at 0° the turn makes
  // most of their Sim(3) error (refine/README.md). Null (JSON) when the ground-truth centres are
  // collinear (no rotation about their line is fitted).
  double alignment_rotation_sigma_deg = 0.0;
  bool success = false;

  // Every field with its name, in declaration order.
  template <class Self, class Visitor>
  static void VisitFields(Self& self, Visitor&& v) {
    v("num_frames", self.num_frames);
    v("mean_rotation_deg", self.mean_rotation_deg);
    v("median_rotation_deg", self.median_rotation_deg);
    v("mean_centre_m", self.mean_centre_m);
    v("median_centre_m", self.median_centre_m);
    v("scene_scale_m", self.scene_scale_m);
    v("mean_centre_relative", self.mean_centre_relative);
    v("median_centre_relative", self.median_centre_relative);
    v("num_relative_pairs", self.num_relative_pairs);
    v("mean_relative_rotation_deg", self.mean_relative_rotation_deg);
    v("median_relative_rotation_deg", self.median_relative_rotation_deg);
    v("alignment_rotation_sigma_deg", self.alignment_rotation_sigma_deg);
    v("success", self.success);
  }
};
// A number that is not finite is written as null. Read back, a number absent or null (a summary
// written before the field existed, a collinear fit) is NaN, a count 0, success false.
void to_json(nlohmann::json& json, const PoseErrorStatistics& statistics);
void from_json(const nlohmann::json& json, PoseErrorStatistics& statistics);

struct PoseErrorSummary : PoseErrorStatistics {
  std::string alignment;
  Sim3 gt_from_estimate;  // the fitted alignment (identity for "none")
  std::vector<FrameError> frames;
  std::vector<std::string> only_in_estimate;  // reported, never silently dropped
  std::vector<std::string> only_in_ground_truth;

  // The statistics, alignment, frames and name lists by name; gt_from_estimate as {scale,
  // rotation_wxyz, translation}.
  nlohmann::json ToJson(bool with_frames = true) const;
};
inline void to_json(nlohmann::json& json, const PoseErrorSummary& summary) {
  json = summary.ToJson();
}

// Frame pairs scored by the relative rotation error at most (memory and time stay bounded on
// captures of thousands of frames).
inline constexpr size_t kMaxRelativePairs = 4'000'000;

AlignmentKind AlignmentKindFromName(const std::string& name);  // throws InputError

// The RMS rotation (radians) of a centre alignment's error when each aligned centre is off by
// independent isotropic noise: a small turn θ of the fit moves centre i by θ x (g_i - ḡ), so the
// least-squares θ has covariance σ² M⁻¹ with M = Σ (|d_i|² I - d_i d_iᵀ), d_i = g_i - ḡ (the
// target centres' inertia tensor), and the RMS angle is σ sqrt(trace M⁻¹). σ² per axis is
// estimated from the residuals left after the fit, Σ r_i² / (3n - fitted_parameters). Infinity
// when M is singular (collinear or coincident centres) and residuals are left; 0 when none are.
double AlignmentRotationSigma(const std::vector<Eigen::Vector3d>& target_centres,
                              const std::vector<double>& residual_norms, int fitted_parameters);

// Joins by image name; needs at least 3 common frames for sim3/se3 (InputError otherwise).
PoseErrorSummary ComputePoseErrors(const PoseSet& estimate, const PoseSet& ground_truth,
                                   const PoseErrorOptions& options);

}  // namespace raytime
