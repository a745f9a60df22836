// The ray-time LM's problem (PoseLib's Problem; the loop is ray_time_lm_solver.h): the point it
// moves (poses and ray times), the cross-projection residual and its Jacobians, the pose priors'
// terms, the cost at a point and the point after a step. Its linearization into the reduced
// camera system is ray_time_lm_linearization.h.
#pragma once

#include <Eigen/Core>
#include <array>
#include <vector>

#include "core/geometry.h"
#include "refine/solve/ray_time_lm_solver.h"

namespace raytime {

class ReducedCameraPattern;  // reduced_camera_system.h
struct ReducedStep;

// A point of the problem: poses (with their rotation matrices, row-major, and centres as plain
// arrays for the hot loops) and ray times.
struct RayTimeLmPoint {
  std::vector<Rigid3> world_from_cam;
  std::vector<std::array<double, 9>> rotation;
  std::vector<std::array<double, 3>> centre;
  std::vector<double> ray_times;

  void UpdateRotations();
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

// The pose prior of one image in the local parameters (φ, δO): r = (sR·Log(R_priorᵀ R),
// sp·(O - O_prior)) with Jacobian blocks A = sR·Jr⁻¹(θ)·Rᵀ for φ and sp·I for δO
// (R ← Exp(φ)·R gives Log(R_priorᵀ Exp(φ) R) ≈ θ + Jr⁻¹(θ)·Rᵀφ).
struct PriorLinearization {
  Eigen::Vector3d rotation_residual;
  Eigen::Vector3d centre_residual;
  Eigen::Matrix3d rotation_jacobian;
  double centre_scale = 0.0;
};

// Every image's prior term at `world_from_cam`, with the weights of `problem` (λp/N, λR/N).
std::vector<PriorLinearization> LinearizePriors(const RayTimeLmProblem& problem,
                                                const std::vector<Rigid3>& world_from_cam);

// The objective at `point` (ray_time_lm_solver.h): the match term over the pattern's fixed chunks
// (summed in chunk order: the same bits on any thread count) plus the prior terms.
double RayTimeLmCost(const RayTimeLmProblem& problem, const RayTimeLmPoint& point, double scale_px2,
                     int num_threads, const ReducedCameraPattern& pattern);

// *out = base ⊕ α·δ: the cameras by RetractPoses (the step's similarity part `similarity` applied
// as a similarity), the ray times retracted in inverse depth (RetractRayTime) by their step less
// the similarity's scaling, then scaled with it.
void RetractPoint(const RayTimeLmPoint& base, const std::vector<int>& variables,
                  const ReducedStep& step, const Eigen::Matrix<double, 7, 1>& similarity,
                  double alpha, RayTimeLmPoint* out);

}  // namespace raytime
