// The cross-projection residual of paper eqs. (rij)/(rji): r = π_j(X_ik) - û_jl, the ray point of
// a source observation (camera i, keypoint k) projected with the plain pinhole model into the
// camera j of a target observation, minus the target's undistorted pixel. Parameter blocks, in
// order: shared intrinsics (8), source pose (7), source ray time (1), target pose (7).
//
// Two implementations of the same function:
// - CachedCrossProjectionCost reads û and X with their derivatives from the ObservationCache and
//   only projects ("gradient surgery", §3.7);
// - CrossProjectionAutoDiffCost computes the whole chain (undistort both pixels, unproject,
//   project) with automatic differentiation, for use_evaluation_cache = false and as the
//   reference the cached Jacobians are tested against.
#pragma once

#include <ceres/autodiff_cost_function.h>
#include <ceres/sized_cost_function.h>

#include <Eigen/Core>

#include "core/camera.h"
#include "refine/evaluation_cache.h"
#include "refine/ray_geometry.h"

namespace raytime {

class CachedCrossProjectionCost
    : public ceres::SizedCostFunction<2, kNumIntrinsics, kPoseBlockSize, 1, kPoseBlockSize> {
 public:
  CachedCrossProjectionCost(const ObservationCache* cache, int source, int target)
      : cache_(cache), source_(source), target_(target) {}

  static ceres::CostFunction* Create(const ObservationCache* cache, int source, int target) {
    return new CachedCrossProjectionCost(cache, source, target);
  }

  // Thread-safe: reads the cache, which Ceres fills before the parallel residual loop.
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  const ObservationCache* cache_;
  int source_;
  int target_;
};

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
    const T source_pixel[2] = {T(source_pixel_[0]), T(source_pixel_[1])};
    const T target_pixel[2] = {T(target_pixel_[0]), T(target_pixel_[1])};
    T source_undistorted[2], target_undistorted[2];
    UndistortPixel(intrinsics, source_pixel, source_undistorted);
    UndistortPixel(intrinsics, target_pixel, target_undistorted);
    T point[3];
    RayPointInWorld(intrinsics, source_pose, ray_time[0], source_undistorted, point);
    T projected[2];
    ProjectWorldPoint(intrinsics, target_pose, point, projected);
    residual[0] = projected[0] - target_undistorted[0];
    residual[1] = projected[1] - target_undistorted[1];
    return true;
  }

 private:
  Eigen::Vector2d source_pixel_;
  Eigen::Vector2d target_pixel_;
};

}  // namespace raytime
