// A Levenberg–Marquardt solver for the fixed-intrinsics ray-time problem (paper §3.2–3.5, §3.7)
// that eliminates the one-dimensional ray times in closed form, without Ceres.
//
// Why: with every intrinsic held the problem is poses (6 local parameters each) and ray times
// (one each, each in the residuals of one observation's matches only). The reduced camera system
// after eliminating the ray times is what Ceres' SPARSE_SCHUR factorizes too (§3.4), but Ceres
// reaches it through generic machinery that dominated the profile of a full-match solve (residual
// block bookkeeping, the 2x7·7x6 manifold products, a Schur eliminator without a 1x1
// specialization: ~0.43 s per iteration for 181k residuals where the arithmetic is a few ms).
// Here each ray time's residuals are linearized, reduced into the camera system and dropped: no
// Jacobian is stored, so memory is the problem's data (~60 bytes per residual) plus the reduced
// system, and the linearization runs on any number of threads with bit-identical results (fixed
// chunks summed in a fixed order).
//
// The objective is the one RayTimeProblem gives Ceres (its header): ½ Σ w ρ_a(|r|²) over the
// cross-projection residuals with ρ_a(s) = a·atan(s/a) and w = 2/S, plus ½ Σ |prior residual|²
// with the pose priors of refine/solve/pose_prior_cost.h. The step is Ceres' LM step (trust-region
// radius μ, diagonal D = diag(JᵀJ) clamped to [1e-6, 1e32], the robust loss as Ceres' corrector
// applies a loss with ρ'' < 0: J and r scaled by sqrt(w ρ')), so the iteration and function
// tolerance mean what they mean in ceres_gnc.h; the path differs (no Jacobi scaling, a rotation
// perturbation R ← Exp(φ)·R instead of Ceres' quaternion manifold, ray times updated in inverse
// depth: RetractRayTime), and the parameter tolerance looks at the poses only, not at far points'
// ray times.
//
// In PoseLib's split (lm_impl.h: a loop over a problem and an accumulator): the loop, Ceres' trust
// region around it, is this header's .cc; the problem (the point, the residual, the cost, the
// step) is ray_time_lm_kernel.h with its linearization in ray_time_lm_linearization.h; the
// accumulator, which eliminates the ray times and solves for a damping, is
// reduced_camera_system.h; the step's retraction is similarity_retraction.h and the loss's sum
// arctan_loss.h.
#pragma once

#include <Eigen/Core>
#include <vector>

#include "core/geometry.h"
#include "refine/refine_types.h"
#include "refine/solve/gnc.h"

namespace raytime {

// One cross-projection residual r = π_target(O_s + t·R_s·d) - û (paper eqs. rij, rji).
struct RayTimeLmResidual {
  int source_image = 0;
  int ray_time = 0;
  int target_image = 0;
  Eigen::Vector3d source_ray;          // unit ray d in the source camera frame
  Eigen::Vector2d target_undistorted;  // û, the target's undistorted pixel
  // The layout's observations the two come from (refine/checks/pose_uncertainty.h: residuals
  // sharing an observation share its keypoint's noise); -1 when unknown.
  int source_observation = -1;
  int target_observation = -1;
};

struct RayTimeLmProblem {
  // Variables: per image the pose world_from_cam (rotation camera to world, centre); `held`
  // images keep theirs (no residual reaches them). One ray time per entry, bounded below at
  // kRayTimeLowerBound.
  std::vector<Rigid3> world_from_cam;
  std::vector<bool> held;
  std::vector<double> ray_times;
  // Per image: fx, fy, cx, cy of the plain pinhole the residuals project with.
  std::vector<Eigen::Vector4d> pinhole;
  // Sorted by ray time (a ray time's residuals are contiguous): the solver reduces each ray time's
  // residuals together. A ray time lives on one observation, so its residuals share their
  // source_image and source_ray (the solver throws std::invalid_argument otherwise).
  std::vector<RayTimeLmResidual> residuals;
  double match_loss_weight = 0.0;  // w = 2/S (RayTimeProblem::match_loss_weight)
  // Pose priors (§3.3), per image: the anchor and the weights λp/N and λR/N.
  std::vector<Rigid3> prior_world_from_cam;
  double position_weight = 0.0;
  double orientation_weight = 0.0;
};

// Solves every stage of the schedule in place (the GNC driver, gnc.h, with this solver as its
// back-end); a stage fails when the reduced system could not be factorized at any damping.
std::vector<GncStageSummary> SolveGncRayTimeLm(RayTimeLmProblem* problem,
                                               const GncSettings& settings);

}  // namespace raytime
