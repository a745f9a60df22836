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
#pragma once

#include <Eigen/Core>
#include <cmath>
#include <vector>

#include "core/geometry.h"
#include "refine/refine_types.h"
#include "refine/solve/gnc.h"
#include "refine/solve/ray_geometry.h"

namespace raytime {

// The match term's loss: Ceres' ArctanLoss(a) scaled by w (RayTimeProblem's), ρ(s) = w·a·atan(s/a)
// (summed by SumOfArctans) and ρ'(s) of s = |r|². The solver and the uncertainty at its solution
// (pose_uncertainty.h) weigh with it.
struct ScaledArctanLoss {
  double scale;   // a, px²
  double weight;  // w = 2/S
  double Derivative(double s) const { return weight * scale * scale / (s * s + scale * scale); }
};

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

// The residual and its Jacobians in the local parameters: source pose (φ, δO) with
// R_s ← Exp(φ)·R_s and O_s ← O_s + δO, the ray time, the target pose likewise. Plain arguments so
// it tests against numeric differentiation.
void CrossProjectionJacobian(const Eigen::Matrix3d& source_rotation,
                             const Eigen::Vector3d& source_centre, double ray_time,
                             const Eigen::Matrix3d& target_rotation,
                             const Eigen::Vector3d& target_centre, const Eigen::Vector4d& pinhole,
                             const Eigen::Vector3d& source_ray,
                             const Eigen::Vector2d& target_undistorted, Eigen::Vector2d* residual,
                             Eigen::Matrix<double, 2, 6>* source_jacobian,
                             Eigen::Vector2d* ray_time_jacobian,
                             Eigen::Matrix<double, 2, 6>* target_jacobian);

// The pose prior of one image (refine/solve/pose_prior_cost.h) and its Jacobian in the local
// parameters (φ, δO) of the pose, R ← Exp(φ)·R and O ← O + δO: residual rows in PosePriorCost's
// order (centre_scale·(O - O_prior), rotation_scale·Log(R_priorᵀ R)). Plain arguments so it tests
// against numeric differentiation and against the Ceres functor.
void PosePriorJacobian(const Rigid3& world_from_cam, const Rigid3& prior_world_from_cam,
                       double rotation_scale, double centre_scale,
                       Eigen::Matrix<double, 6, 1>* residual,
                       Eigen::Matrix<double, 6, 6>* jacobian);

// Σ atan(s_k / a) over s[0..n) (s_k ≥ 0, a > 0): the arctan loss's sum without its factor w·a
// (ScaledArctanLoss). Where the CPU has AVX2, four at a time with glibc's vector atan (libmvec,
// within a few ulp of atan): the scalar atan2 took 16 ns a call, 13 % of castle-P19 8°'s whole
// refine (perf), the vector one 1.6 ns. Deterministic on a machine, whatever the thread count;
// a CPU without AVX2 takes the scalar atan and may differ in the last bits.
double SumOfArctans(const double* s, int n, double scale);

// A camera's step (rotation φ, then centre) under an infinitesimal global similarity g = (ω, λ,
// τ) about a pivot, o the centre relative to it: φ = ω, δO = ω × o + λ·o + τ.
Eigen::Matrix<double, 6, 7> SimilarityTangent(const Eigen::Vector3d& o);

// The centroid of the cameras in the step (variable[i] >= 0): the similarity's pivot, so that a
// prior in far coordinates (a GPS prior's UTM metres) neither conditions the fit badly nor turns
// the cameras on arcs about a distant origin.
Eigen::Vector3d SimilarityPivot(const std::vector<Rigid3>& poses, const std::vector<int>& variable);

// The similarity part (about SimilarityPivot) of a step of the cameras (6 per camera, at
// 6·variable[i]; variable[i] < 0: not in the step): least squares over SimilarityTangent.
Eigen::Matrix<double, 7, 1> SimilarityPart(const std::vector<Rigid3>& poses,
                                           const std::vector<int>& variable,
                                           const Eigen::VectorXd& step);

// poses ⊕ step with the step's similarity part applied as a similarity: the rest taken as before
// (rotation by its exponential, centre added), then R ← Exp(ω)·R, O ← p + e^λ·Exp(ω)·(O - p) + τ
// with p the poses' SimilarityPivot. To first order this is the plain update; along the 7
// directions no match sees it is exact. Why: the match term is invariant under a global
// similarity (the ray times scaled with it), so along it only the weak prior terms curve the
// cost, and a linear step along it bends the shape by its second order, which the matches pull
// back: the solve crept along the similarity (Herz-Jesus-P8 8°: the anneal took 40 steps, each
// 99.8 % similarity, at a tenth of the model's length).
void RetractPoses(const std::vector<int>& variable, const Eigen::VectorXd& step,
                  const Eigen::Matrix<double, 7, 1>& similarity, std::vector<Rigid3>* poses);

// The ray time after a step δ of the linearized problem: t ← t / (1 - δ/t), the step taken in
// inverse depth (1/t ← 1/t - δ/t², the same first-order move), at most kMaxRayTimeGrowth times
// further per step and never below kRayTimeLowerBound. Why: a point's projection is nearly linear
// in its inverse depth and far from linear in its depth once the point is far, so t + δ
// overshoots far points (castle-P19 at 8°: the whole refine rejected 38 steps, 17 of them in the
// all-match finish, where a far point's step of millions dominated; with this retraction 3 and 0,
// and the finish takes 36 iterations instead of 53). A step toward the camera shrinks t by a
// factor and cannot cross it.
double RetractRayTime(double ray_time, double step);
inline constexpr double kMaxRayTimeGrowth = 10.0;

// Solves every stage of the schedule in place (the GNC driver, gnc.h, with this solver as its
// back-end); a stage fails when the reduced system could not be factorized at any damping.
std::vector<GncStageSummary> SolveGncRayTimeLm(RayTimeLmProblem* problem,
                                               const GncSettings& settings);

}  // namespace raytime
