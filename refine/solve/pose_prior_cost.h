// The prior terms of paper eq. (energy) for one camera: sqrt(2λp/N)·(O_i - O_i^prior) and
// sqrt(2λR/N)·Log((R_i^prior)^-1 R_i), so that Ceres' cost ½|r|² is exactly
// λp/N |O_i - O_i^prior|² + λR/N |Log(...)|² (§3.3). The rotation log takes the shorter arc
// (ceres::QuaternionToAngleAxis folds w < 0), as the paper specifies.
#pragma once

#include <ceres/autodiff_cost_function.h>
#include <ceres/rotation.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>

#include "core/geometry.h"
#include "refine/solve/ray_geometry.h"

namespace raytime {

class PosePriorCost {
 public:
  // position_weight = λp/N, orientation_weight = λR/N.
  PosePriorCost(const Rigid3& prior_world_from_cam, double position_weight,
                double orientation_weight)
      : prior_rotation_(prior_world_from_cam.rotation.normalized()),
        prior_centre_(prior_world_from_cam.translation),
        position_scale_(std::sqrt(2.0 * position_weight)),
        orientation_scale_(std::sqrt(2.0 * orientation_weight)) {}

  static ceres::CostFunction* Create(const Rigid3& prior_world_from_cam, double position_weight,
                                     double orientation_weight) {
    return new ceres::AutoDiffCostFunction<PosePriorCost, 6, kPoseBlockSize>(
        new PosePriorCost(prior_world_from_cam, position_weight, orientation_weight));
  }

  template <typename T>
  bool operator()(const T* pose, T* residual) const {
    for (int r = 0; r < 3; ++r) {
      residual[r] = T(position_scale_) * (pose[kPoseCentreOffset + r] - T(prior_centre_[r]));
    }
    // (R^prior)^-1 R as the quaternion product conj(q_prior) ⊗ q, written in ceres' (w, x, y, z)
    // order; the pose block stores (x, y, z, w).
    const T aw = T(prior_rotation_.w());
    const T ax = T(-prior_rotation_.x());
    const T ay = T(-prior_rotation_.y());
    const T az = T(-prior_rotation_.z());
    const T& bx = pose[0];
    const T& by = pose[1];
    const T& bz = pose[2];
    const T& bw = pose[3];
    const T relative[4] = {
        aw * bw - ax * bx - ay * by - az * bz, aw * bx + bw * ax + ay * bz - az * by,
        aw * by + bw * ay + az * bx - ax * bz, aw * bz + bw * az + ax * by - ay * bx};
    T log[3];
    ceres::QuaternionToAngleAxis(relative, log);
    for (int r = 0; r < 3; ++r) residual[3 + r] = T(orientation_scale_) * log[r];
    return true;
  }

 private:
  Eigen::Quaterniond prior_rotation_;
  Eigen::Vector3d prior_centre_;
  double position_scale_;
  double orientation_scale_;
};

}  // namespace raytime
