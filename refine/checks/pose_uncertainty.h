// How well the solve determines each camera (issue 32 "Per-camera uncertainty from the solve"):
// the first-order covariance of each pose at the solution under keypoint noise, propagated
// through the ray-time problem with the ray times eliminated (the reduced camera system the
// ray-time LM factorizes, §3.4) and expressed in the gauge the returned poses are in.
//
// Model: every observation's undistorted keypoint carries independent noise of σ px per
// coordinate. A residual r = π_t(O_s + t·R_s·d(u_s)) − u_t moves with its target keypoint (−I)
// and, through its ray, with its source keypoint (D = ∂r/∂u_s); the two residuals of a match, and
// all residuals of one observation, share that noise. At the solution, with the robust loss's
// weights a_k = w·ρ'(|r_k|²) and the pose priors' curvature Hp, the Gauss–Newton step is
// δx = −H⁻¹ g, so Cov(x) = H⁻¹ Cov(g) H⁻¹ (sandwich: Hp carries no noise); with the ray times
// eliminated, the cameras' block is S⁻¹ M S⁻¹, S the reduced camera matrix and M the reduced
// gradient's covariance. The match term does not see a global similarity (7 directions) and the
// returned poses are placed by the gauge polish (refine/solve/gauge_polish.h): a similarity fitted
// to the prior with weights λp on centres and λR (gauge_orientation_weight) on rotations. So the
// covariance is projected onto that gauge: P = I − G (GᵀWG)⁻¹ GᵀW over the similarity generators G.
//
// σ itself is estimated from the residuals at the solution: Σ a_k |r_k|² over its expectation per
// unit σ², Σ a_k tr(I + D_k D_kᵀ), times the share of scalar residuals left after the parameters
// (1 − p / 2K). Dense in the cameras: O((6n)³), so skipped above `max_cameras`.
#pragma once

#include <limits>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace raytime {

struct RayTimeLmProblem;        // refine/solve/ray_time_lm_solver.h
struct TrackAdjustmentProblem;  // refine/solve/track_adjustment.h

struct PoseUncertainty {
  static constexpr double kNone = std::numeric_limits<double>::quiet_NaN();
  // RMS size of the pose's error: sqrt(trace) of the 3×3 rotation (R ← Exp(φ)·R) and centre
  // blocks of its covariance, degrees and prior length units. NaN (JSON null) for a camera no
  // residual reaches.
  double rotation_deg = kNone;
  double centre = kNone;

  template <class Self, class Visitor>
  static void VisitFields(Self& self, Visitor&& v) {
    v("rotation_deg", self.rotation_deg);
    v("centre", self.centre);
  }
};
void to_json(nlohmann::json& json, const PoseUncertainty& uncertainty);
void from_json(const nlohmann::json& json, PoseUncertainty& uncertainty);

struct PoseUncertaintySummary {
  bool computed = false;
  // The estimator whose poses were returned and whose covariance this is: "ray_time" (the
  // solve's), or "track_adjustment" (the track finish's bundle adjustment, one point per track,
  // refine/recipes/track_finish.h).
  std::string estimator = "ray_time";
  std::string reason;     // why not, when not computed
  double sigma_px = 0.0;  // the keypoint noise used (estimated unless given)
  double sigma_px_estimated = 0.0;
  double median_rotation_deg = 0.0;  // over the cameras with a value
  double median_centre = 0.0;
  std::vector<PoseUncertainty> cameras;  // per image
  double seconds = 0.0;
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(PoseUncertaintySummary, computed, estimator, reason, sigma_px,
                                   sigma_px_estimated, median_rotation_deg, median_centre, cameras,
                                   seconds)

struct PoseUncertaintySettings {
  double scale_px2 = 1e2;              // the robust loss's scale at the solution (last stage)
  double gauge_position_weight = 1.0;  // the gauge polish's weights (relative)
  double gauge_orientation_weight = 1e3;
  double sigma_px = 0.0;  // > 0: use this keypoint noise instead of estimating
  int max_cameras = 600;  // above, not computed (dense O((6n)³))
  int num_threads = 1;    // the same bits on any count
};

// At the state held in `problem` (poses and ray times after the solve; the gauge polish applied or
// not: the projection does not depend on it).
PoseUncertaintySummary EstimatePoseUncertainty(const RayTimeLmProblem& problem,
                                               const PoseUncertaintySettings& settings);

// The same for the track finish's bundle adjustment at its solution (`problem` after AdjustTracks,
// plain least squares): the points eliminated instead of the ray times, each observation's
// residual moving with its own keypoint only (r = π(X) − û: the noise block is −I), σ² from
// Σ |r|² / (2K − p), p = 6 cameras + 3 points. estimator "track_adjustment"; settings.scale_px2
// unused.
PoseUncertaintySummary EstimateTrackPoseUncertainty(const TrackAdjustmentProblem& problem,
                                                    const PoseUncertaintySettings& settings);

}  // namespace raytime
