// The cross-projection residual of paper eqs. (rij)/(rji): r = π_j(X_ik) - û_jl, the ray point of
// a source observation (camera i, keypoint k) projected with the plain pinhole model into the
// camera j of a target observation, minus the target's undistorted pixel. X_ik is undistorted and
// unprojected with the source image's intrinsics, π_j and û_jl use the target image's.
//
// Two variants by the intrinsics blocks (refine/solve/camera_blocks.h), because Ceres refuses a
// residual that holds one parameter block twice:
// - both images on one block (the paper's shared intrinsics, §3.1): blocks intrinsics (8), source
//   pose (7), source ray time (1), target pose (7);
// - on two blocks (per-image intrinsics): source intrinsics (8), source pose (7), source ray time
//   (1), target intrinsics (8), target pose (7). Its two intrinsics Jacobians sum to the
//   one-block variant's.
// With every intrinsic held (no self-calibration, the default) a third variant has no intrinsics
// block at all: blocks source pose (7), source ray time (1), target pose (7).
// Each in up to three implementations of the same function, whose value is computed by the
// arithmetic of refine/solve/ray_geometry.h that the ray-time LM's kernel also uses (RayPoint,
// TargetResidual; tests/refine_lm_solver_test.cc checks the values agree):
// - Cached*CrossProjectionCost reads û and X with their derivatives from the ObservationCache and
//   only projects ("gradient surgery", §3.7);
// - FixedIntrinsicsCrossProjectionCost holds the source's unit ray and the target's undistorted
//   pixel, which fixed intrinsics make constant for the whole solve (the problem computes them
//   once), and differentiates the rest in closed form: no per-evaluation cache, and one parameter
//   block less for Ceres to handle per residual (the profile of a full-match solve had the
//   cache's jets and its per-residual reads at ~45 % of the time);
// - *CrossProjectionAutoDiffCost computes the whole chain (undistort both pixels, unproject,
//   project) with automatic differentiation, for use_evaluation_cache = false and as the
//   reference the cached Jacobians are tested against.
#pragma once

#include <ceres/autodiff_cost_function.h>
#include <ceres/sized_cost_function.h>

#include <Eigen/Core>
#include <type_traits>

#include "core/camera.h"
#include "refine/solve/evaluation_cache.h"
#include "refine/solve/ray_geometry.h"

namespace raytime {

// The cached cost of one observation pair (source, target) in the ObservationCache: both images on
// one intrinsics block, or (kTwoBlocks) on two.
template <bool kTwoBlocks>
using CachedCostBase = std::conditional_t<
    kTwoBlocks,
    ceres::SizedCostFunction<2, kNumIntrinsics, kPoseBlockSize, 1, kNumIntrinsics, kPoseBlockSize>,
    ceres::SizedCostFunction<2, kNumIntrinsics, kPoseBlockSize, 1, kPoseBlockSize>>;

template <bool kTwoBlocks>
class CachedCrossProjectionCostOf : public CachedCostBase<kTwoBlocks> {
 public:
  CachedCrossProjectionCostOf(const ObservationCache* cache, int source, int target)
      : cache_(cache), source_(source), target_(target) {}

  static ceres::CostFunction* Create(const ObservationCache* cache, int source, int target) {
    return new CachedCrossProjectionCostOf(cache, source, target);
  }

  // Thread-safe: reads the cache, which Ceres fills before the parallel residual loop.
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  const ObservationCache* cache_;
  int source_;
  int target_;
};

using CachedCrossProjectionCost = CachedCrossProjectionCostOf<false>;
using CachedTwoCameraCrossProjectionCost = CachedCrossProjectionCostOf<true>;

// Every intrinsic held: the source observation's unit ray in its camera frame and the target's
// undistorted pixel, computed once, are constants of the residual.
class FixedIntrinsicsCrossProjectionCost
    : public ceres::SizedCostFunction<2, kPoseBlockSize, 1, kPoseBlockSize> {
 public:
  // `source_ray`: PixelToUnitRay of the source's undistorted pixel; `target_undistorted`: the
  // target's undistorted pixel; `target_intrinsics`: its image's intrinsics (fx, fy, cx, cy used).
  FixedIntrinsicsCrossProjectionCost(const Eigen::Vector3d& source_ray,
                                     const Eigen::Vector2d& target_undistorted,
                                     const double* target_intrinsics);

  static ceres::CostFunction* Create(const Eigen::Vector3d& source_ray,
                                     const Eigen::Vector2d& target_undistorted,
                                     const double* target_intrinsics) {
    return new FixedIntrinsicsCrossProjectionCost(source_ray, target_undistorted,
                                                  target_intrinsics);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  double source_ray_[3];
  double target_undistorted_[2];
  double target_pinhole_[4];  // fx, fy, cx, cy
};

// The residual of either variant: û_s and X with the source intrinsics, π and û_t with the
// target's (the one-block variant passes its block twice; the operations are the same).
template <typename T>
void CrossProjectionResidual(const T* source_intrinsics, const T* source_pose, const T& ray_time,
                             const T* target_intrinsics, const T* target_pose,
                             const Eigen::Vector2d& source_pixel_observed,
                             const Eigen::Vector2d& target_pixel_observed, T* residual) {
  const T source_pixel[2] = {T(source_pixel_observed[0]), T(source_pixel_observed[1])};
  const T target_pixel[2] = {T(target_pixel_observed[0]), T(target_pixel_observed[1])};
  T source_undistorted[2], target_undistorted[2];
  UndistortPixel(source_intrinsics, source_pixel, source_undistorted);
  UndistortPixel(target_intrinsics, target_pixel, target_undistorted);
  T point[3];
  RayPointInWorld(source_intrinsics, source_pose, ray_time, source_undistorted, point);
  TargetResidualAtPose(target_intrinsics, target_pose, point, target_undistorted, residual);
}

// Both observations' images on one intrinsics block.
class CrossProjectionAutoDiffCost {
 public:
  CrossProjectionAutoDiffCost(const Eigen::Vector2d& source_pixel,
                              const Eigen::Vector2d& target_pixel)
      : source_pixel_(source_pixel), target_pixel_(target_pixel) {}

  // Pixels are the observed (distorted) keypoints.
  static ceres::CostFunction* Create(const Eigen::Vector2d& source_pixel,
                                     const Eigen::Vector2d& target_pixel) {
    return new ceres::AutoDiffCostFunction<CrossProjectionAutoDiffCost, 2, kNumIntrinsics,
                                           kPoseBlockSize, 1, kPoseBlockSize>(
        new CrossProjectionAutoDiffCost(source_pixel, target_pixel));
  }

  template <typename T>
  bool operator()(const T* intrinsics, const T* source_pose, const T* ray_time,
                  const T* target_pose, T* residual) const {
    CrossProjectionResidual(intrinsics, source_pose, ray_time[0], intrinsics, target_pose,
                            source_pixel_, target_pixel_, residual);
    return true;
  }

 private:
  Eigen::Vector2d source_pixel_;
  Eigen::Vector2d target_pixel_;
};

// The observations' images on two intrinsics blocks.
class TwoCameraCrossProjectionAutoDiffCost {
 public:
  TwoCameraCrossProjectionAutoDiffCost(const Eigen::Vector2d& source_pixel,
                                       const Eigen::Vector2d& target_pixel)
      : source_pixel_(source_pixel), target_pixel_(target_pixel) {}

  // Pixels are the observed (distorted) keypoints.
  static ceres::CostFunction* Create(const Eigen::Vector2d& source_pixel,
                                     const Eigen::Vector2d& target_pixel) {
    return new ceres::AutoDiffCostFunction<TwoCameraCrossProjectionAutoDiffCost, 2, kNumIntrinsics,
                                           kPoseBlockSize, 1, kNumIntrinsics, kPoseBlockSize>(
        new TwoCameraCrossProjectionAutoDiffCost(source_pixel, target_pixel));
  }

  template <typename T>
  bool operator()(const T* source_intrinsics, const T* source_pose, const T* ray_time,
                  const T* target_intrinsics, const T* target_pose, T* residual) const {
    CrossProjectionResidual(source_intrinsics, source_pose, ray_time[0], target_intrinsics,
                            target_pose, source_pixel_, target_pixel_, residual);
    return true;
  }

 private:
  Eigen::Vector2d source_pixel_;
  Eigen::Vector2d target_pixel_;
};

}  // namespace raytime
