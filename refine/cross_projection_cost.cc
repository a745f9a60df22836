#include "refine/cross_projection_cost.h"

namespace raytime {

namespace {

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
  const double* intrinsics = parameters[kTargetIntrinsics];
  const double* target_pose = parameters[kTargetPose];

  double R[9];
  RotationFromQuaternion(target_pose, R);
  const double* centre = target_pose + kPoseCentreOffset;
  const double v[3] = {source.point[0] - centre[0], source.point[1] - centre[1],
                       source.point[2] - centre[2]};
  double p[3];  // R^T v
  for (int c = 0; c < 3; ++c) p[c] = R[c] * v[0] + R[3 + c] * v[1] + R[6 + c] * v[2];
  const double fx = intrinsics[kFx];
  const double fy = intrinsics[kFy];
  const double inv_z = 1.0 / p[2];
  const double xn = p[0] * inv_z;
  const double yn = p[1] * inv_z;
  residuals[0] = fx * xn + intrinsics[kCx] - target.undistorted[0];
  residuals[1] = fy * yn + intrinsics[kCy] - target.undistorted[1];
  if (jacobians == nullptr) return true;

  // du/dp (2x3) and du/dX = du/dp · R^T (2x3).
  const double du_dp[2][3] = {{fx * inv_z, 0.0, -fx * xn * inv_z},
                              {0.0, fy * inv_z, -fy * yn * inv_z}};
  double du_dX[2][3];
  for (int a = 0; a < 2; ++a) {
    for (int r = 0; r < 3; ++r) {
      du_dX[a][r] =
          du_dp[a][0] * R[3 * r] + du_dp[a][1] * R[3 * r + 1] + du_dp[a][2] * R[3 * r + 2];
    }
  }
  // Cached dX/d(local) columns [offset, offset + n) mapped through du/dX.
  const auto through_point = [&](int a, int column) {
    return du_dX[a][0] * source.d_point[column] +
           du_dX[a][1] * source.d_point[kCacheNumLocal + column] +
           du_dX[a][2] * source.d_point[2 * kCacheNumLocal + column];
  };

  // The projection's own derivative in K_t: d(fx xn + cx)/d(fx, cx) = (xn, 1), and in y.
  const auto add_projection_terms = [xn, yn](double* J) {
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
  if (jacobians[kTargetPose] != nullptr) {
    // d(R^T v)/dq for the quaternion formula of RotationFromQuaternion (rows p0..p2, columns
    // x, y, z, w); d(R^T v)/dO = -R^T.
    const double x = target_pose[0], y = target_pose[1], z = target_pose[2], w = target_pose[3];
    const double dp_dq[3][4] = {
        {2 * (y * v[1] + z * v[2]), 2 * (-2 * y * v[0] + x * v[1] - w * v[2]),
         2 * (-2 * z * v[0] + w * v[1] + x * v[2]), 2 * (z * v[1] - y * v[2])},
        {2 * (y * v[0] - 2 * x * v[1] + w * v[2]), 2 * (x * v[0] + z * v[2]),
         2 * (-w * v[0] - 2 * z * v[1] + y * v[2]), 2 * (-z * v[0] + x * v[2])},
        {2 * (z * v[0] - w * v[1] - 2 * x * v[2]), 2 * (w * v[0] + z * v[1] - 2 * y * v[2]),
         2 * (x * v[0] + y * v[1]), 2 * (y * v[0] - x * v[1])}};
    double* J = jacobians[kTargetPose];
    for (int a = 0; a < 2; ++a) {
      for (int q = 0; q < 4; ++q) {
        J[kPoseBlockSize * a + q] =
            du_dp[a][0] * dp_dq[0][q] + du_dp[a][1] * dp_dq[1][q] + du_dp[a][2] * dp_dq[2][q];
      }
      for (int r = 0; r < 3; ++r) J[kPoseBlockSize * a + kPoseCentreOffset + r] = -du_dX[a][r];
    }
  }
  return true;
}

}  // namespace

bool CachedCrossProjectionCost::Evaluate(double const* const* parameters, double* residuals,
                                         double** jacobians) const {
  return EvaluateCached<false>(*cache_, source_, target_, parameters, residuals, jacobians);
}

bool CachedTwoCameraCrossProjectionCost::Evaluate(double const* const* parameters,
                                                  double* residuals, double** jacobians) const {
  return EvaluateCached<true>(*cache_, source_, target_, parameters, residuals, jacobians);
}

}  // namespace raytime
