#include "refine/solve/cross_projection_cost.h"

namespace raytime {

namespace {

// r = K_t·proj(R_j^T (X - O_j)) - û_t for the world point X (TargetResidual), with `pinhole` the
// target's fx, fy, cx, cy (kFx..kCy, the start of an intrinsics block). With `derivatives`, also
// ∂r/∂X and, when `target_pose_jacobian` is not null, the 2x7 Jacobian in the target pose:
// d(R^T v)/dq for the quaternion formula of RotationFromQuaternion (rows p0..p2, columns x, y, z,
// w), d(R^T v)/dO = -R^T.
void ProjectIntoTarget(const double* point, const double* target_pose, const double* pinhole,
                       const double* target_undistorted, double* residuals,
                       TargetResidualDerivative* derivatives, double* target_pose_jacobian) {
  double R[9];
  RotationFromQuaternion(target_pose, R);
  double v[3], p[3];  // X - O, R^T v
  TargetResidual(R, target_pose + kPoseCentreOffset, pinhole, point, target_undistorted, v, p,
                 residuals);
  if (derivatives == nullptr) return;
  *derivatives = DifferentiateTargetResidual(R, pinhole, p);
  if (target_pose_jacobian == nullptr) return;
  const double(&du_dp)[2][3] = derivatives->du_dp;
  const double x = target_pose[0], y = target_pose[1], z = target_pose[2], w = target_pose[3];
  const double dp_dq[3][4] = {
      {2 * (y * v[1] + z * v[2]), 2 * (-2 * y * v[0] + x * v[1] - w * v[2]),
       2 * (-2 * z * v[0] + w * v[1] + x * v[2]), 2 * (z * v[1] - y * v[2])},
      {2 * (y * v[0] - 2 * x * v[1] + w * v[2]), 2 * (x * v[0] + z * v[2]),
       2 * (-w * v[0] - 2 * z * v[1] + y * v[2]), 2 * (-z * v[0] + x * v[2])},
      {2 * (z * v[0] - w * v[1] - 2 * x * v[2]), 2 * (w * v[0] + z * v[1] - 2 * y * v[2]),
       2 * (x * v[0] + y * v[1]), 2 * (y * v[0] - x * v[1])}};
  double* J = target_pose_jacobian;
  for (int a = 0; a < 2; ++a) {
    for (int q = 0; q < 4; ++q) {
      J[kPoseBlockSize * a + q] =
          du_dp[a][0] * dp_dq[0][q] + du_dp[a][1] * dp_dq[1][q] + du_dp[a][2] * dp_dq[2][q];
    }
    for (int r = 0; r < 3; ++r) {
      J[kPoseBlockSize * a + kPoseCentreOffset + r] = -derivatives->du_dX[a][r];
    }
  }
}

// Chain rule of r = K_t·proj(R_j^T (X - O_j)) - û_t with X and û_t (and their derivatives) from
// the cache: the residual's local derivatives are the 2x3 projection derivative times the cached
// 3x16 ray-point derivative (source intrinsics, source pose, ray time), minus the cached 2x8
// derivative of the target's undistortion (target intrinsics), plus the direct terms of the target
// pose and of K_t. With one block (kTwoCameras false) the intrinsics terms are summed into one
// Jacobian; parameters and Jacobians are in the order of the variant's blocks.
template <bool kTwoCameras>
bool EvaluateCached(const ObservationCache& cache, int source_index, int target_index,
                    double const* const* parameters, double* residuals, double** jacobians) {
  constexpr int kSourceIntrinsics = 0;
  constexpr int kSourcePose = 1;
  constexpr int kRayTime = 2;
  constexpr int kTargetIntrinsics = kTwoCameras ? 3 : 0;
  constexpr int kTargetPose = kTwoCameras ? 4 : 3;
  const CachedObservation& source = cache[source_index];
  const CachedObservation& target = cache[target_index];
  TargetResidualDerivative target_side;
  ProjectIntoTarget(source.point, parameters[kTargetPose], parameters[kTargetIntrinsics],
                    target.undistorted, residuals, jacobians ? &target_side : nullptr,
                    jacobians ? jacobians[kTargetPose] : nullptr);
  if (jacobians == nullptr) return true;
  const double(&du_dX)[2][3] = target_side.du_dX;
  // Cached dX/d(local) columns [offset, offset + n) mapped through du/dX.
  const auto through_point = [&](int a, int column) {
    return du_dX[a][0] * source.d_point[column] +
           du_dX[a][1] * source.d_point[kCacheNumLocal + column] +
           du_dX[a][2] * source.d_point[2 * kCacheNumLocal + column];
  };

  // The projection's own derivative in K_t: d(fx xn + cx)/d(fx, cx) = (xn, 1), and in y.
  const auto add_projection_terms = [xn = target_side.xn, yn = target_side.yn](double* J) {
    J[kFx] += xn;
    J[kNumIntrinsics + kFy] += yn;
    J[kCx] += 1.0;
    J[kNumIntrinsics + kCy] += 1.0;
  };
  if constexpr (kTwoCameras) {
    if (jacobians[kSourceIntrinsics] != nullptr) {
      double* J = jacobians[kSourceIntrinsics];
      for (int a = 0; a < 2; ++a) {
        for (int c = 0; c < kNumIntrinsics; ++c) {
          J[kNumIntrinsics * a + c] = through_point(a, kCacheIntrinsicsOffset + c);
        }
      }
    }
    if (jacobians[kTargetIntrinsics] != nullptr) {
      double* J = jacobians[kTargetIntrinsics];
      for (int k = 0; k < 2 * kNumIntrinsics; ++k) J[k] = -target.d_undistorted[k];
      add_projection_terms(J);
    }
  } else if (jacobians[kSourceIntrinsics] != nullptr) {
    double* J = jacobians[kSourceIntrinsics];
    for (int a = 0; a < 2; ++a) {
      for (int c = 0; c < kNumIntrinsics; ++c) {
        J[kNumIntrinsics * a + c] = through_point(a, kCacheIntrinsicsOffset + c) -
                                    target.d_undistorted[kNumIntrinsics * a + c];
      }
    }
    add_projection_terms(J);
  }
  if (jacobians[kSourcePose] != nullptr) {
    for (int a = 0; a < 2; ++a) {
      for (int c = 0; c < kPoseBlockSize; ++c) {
        jacobians[kSourcePose][kPoseBlockSize * a + c] = through_point(a, kCachePoseOffset + c);
      }
    }
  }
  if (jacobians[kRayTime] != nullptr) {
    for (int a = 0; a < 2; ++a) jacobians[kRayTime][a] = through_point(a, kCacheRayTimeOffset);
  }
  return true;
}

}  // namespace

template <bool kTwoBlocks>
bool CachedCrossProjectionCostOf<kTwoBlocks>::Evaluate(double const* const* parameters,
                                                       double* residuals,
                                                       double** jacobians) const {
  return EvaluateCached<kTwoBlocks>(*cache_, source_, target_, parameters, residuals, jacobians);
}

template class CachedCrossProjectionCostOf<false>;
template class CachedCrossProjectionCostOf<true>;

FixedIntrinsicsCrossProjectionCost::FixedIntrinsicsCrossProjectionCost(
    const Eigen::Vector3d& source_ray, const Eigen::Vector2d& target_undistorted,
    const double* target_intrinsics)
    : source_ray_{source_ray[0], source_ray[1], source_ray[2]},
      target_undistorted_{target_undistorted[0], target_undistorted[1]},
      target_pinhole_{target_intrinsics[kFx], target_intrinsics[kFy], target_intrinsics[kCx],
                      target_intrinsics[kCy]} {}

// X = O_i + t·w with w = R_i·d (RayPoint, so the values are the cached variant's bit for bit);
// dX/dO_i = I, dX/dt = w, dX/dq_i = t·d(R(q)·d)/dq for the quaternion
// formula of RotationFromQuaternion (rows w0..w2, columns x, y, z, w).
bool FixedIntrinsicsCrossProjectionCost::Evaluate(double const* const* parameters,
                                                  double* residuals, double** jacobians) const {
  const double* source_pose = parameters[0];
  const double t = parameters[1][0];
  const double* d = source_ray_;
  double R[9];
  RotationFromQuaternion(source_pose, R);
  double point[3], w[3];
  RayPoint(R, source_pose + kPoseCentreOffset, t, d, w, point);
  TargetResidualDerivative target_side;
  ProjectIntoTarget(point, parameters[2], target_pinhole_, target_undistorted_, residuals,
                    jacobians ? &target_side : nullptr, jacobians ? jacobians[2] : nullptr);
  if (jacobians == nullptr) return true;
  const double(&du_dX)[2][3] = target_side.du_dX;
  if (jacobians[0] != nullptr) {
    const double x = source_pose[0], y = source_pose[1], z = source_pose[2], qw = source_pose[3];
    const double dw_dq[3][4] = {
        {2 * (y * d[1] + z * d[2]), 2 * (-2 * y * d[0] + x * d[1] + qw * d[2]),
         2 * (-2 * z * d[0] - qw * d[1] + x * d[2]), 2 * (-z * d[1] + y * d[2])},
        {2 * (y * d[0] - 2 * x * d[1] - qw * d[2]), 2 * (x * d[0] + z * d[2]),
         2 * (qw * d[0] - 2 * z * d[1] + y * d[2]), 2 * (z * d[0] - x * d[2])},
        {2 * (z * d[0] + qw * d[1] - 2 * x * d[2]), 2 * (-qw * d[0] + z * d[1] - 2 * y * d[2]),
         2 * (x * d[0] + y * d[1]), 2 * (-y * d[0] + x * d[1])}};
    double* J = jacobians[0];
    for (int a = 0; a < 2; ++a) {
      for (int q = 0; q < 4; ++q) {
        J[kPoseBlockSize * a + q] =
            t * (du_dX[a][0] * dw_dq[0][q] + du_dX[a][1] * dw_dq[1][q] + du_dX[a][2] * dw_dq[2][q]);
      }
      for (int r = 0; r < 3; ++r) J[kPoseBlockSize * a + kPoseCentreOffset + r] = du_dX[a][r];
    }
  }
  if (jacobians[1] != nullptr) {
    for (int a = 0; a < 2; ++a) {
      jacobians[1][a] = du_dX[a][0] * w[0] + du_dX[a][1] * w[1] + du_dX[a][2] * w[2];
    }
  }
  return true;
}

}  // namespace raytime
