// The ray-time geometry of paper §3.2, templated on the scalar so that the evaluation cache (jets
// over 16 local parameters), the uncached automatic-differentiation residual (jets over 23) and
// plain doubles (the closed-form Jacobians of both back-ends) all run the same arithmetic, which is
// what makes their residuals identical rather than merely close.
//
// Pose blocks are 7-vectors `world_from_cam`: the rotation R_i (camera to world) as a unit
// quaternion in Eigen memory order (x, y, z, w), then the centre O_i (ray origin) in world
// coordinates (SPEC §2).
#pragma once

#include "core/camera.h"
#include "core/geometry.h"

namespace raytime {

inline constexpr int kPoseBlockSize = 7;     // quaternion x, y, z, w + centre
inline constexpr int kPoseCentreOffset = 4;  // index of O_i in the pose block
// Paper §3.3: a ray time is a positive depth, bounded below at 1e-9 (both solvers).
inline constexpr double kRayTimeLowerBound = 1e-9;

// A pose as a pose block (its rotation normalized) and back.
inline void ToPoseBlock(const Rigid3& pose, double* block) {
  const Eigen::Quaterniond q = pose.rotation.normalized();
  block[0] = q.x();
  block[1] = q.y();
  block[2] = q.z();
  block[3] = q.w();
  for (int r = 0; r < 3; ++r) block[kPoseCentreOffset + r] = pose.translation[r];
}

inline Rigid3 FromPoseBlock(const double* block) {
  Rigid3 pose;
  pose.rotation = Eigen::Quaterniond(block[3], block[0], block[1], block[2]).normalized();
  pose.translation = Eigen::Vector3d(block[kPoseCentreOffset], block[kPoseCentreOffset + 1],
                                     block[kPoseCentreOffset + 2]);
  return pose;
}

// Row-major rotation matrix of a unit quaternion (x, y, z, w), the formula Eigen's
// toRotationMatrix uses. Written out so the analytic derivative in the cached residual
// (cross_projection_cost.cc) differentiates exactly this expression.
template <typename T>
void RotationFromQuaternion(const T* q, T* R) {
  const T& x = q[0];
  const T& y = q[1];
  const T& z = q[2];
  const T& w = q[3];
  R[0] = T(1) - T(2) * (y * y + z * z);
  R[1] = T(2) * (x * y - z * w);
  R[2] = T(2) * (x * z + y * w);
  R[3] = T(2) * (x * y + z * w);
  R[4] = T(1) - T(2) * (x * x + z * z);
  R[5] = T(2) * (y * z - x * w);
  R[6] = T(2) * (x * z - y * w);
  R[7] = T(2) * (y * z + x * w);
  R[8] = T(1) - T(2) * (x * x + y * y);
}

// The cross-projection residual of paper eqs. (rij)/(rji), r = π_j(O_i + t·R_i·d) − û_jl, written
// once: every variant computes its value with RayPoint and TargetResidual below (the Ceres costs of
// refine/solve/cross_projection_cost.h, automatic or closed-form, cached or not; the ray-time LM's
// kernel; the statistics of a pass), so they agree bit for bit, and those with closed-form
// Jacobians carry ∂r/∂X from TargetResidualDerivative back to their own pose parametrization
// (quaternion blocks for Ceres, (φ, δO) for the LM). Rotations here are row-major 3×3 arrays,
// camera to world.

// X = O + t·w with w = R·d (paper eq. raypoint): the point an observation's unit ray d implies at
// ray time t. `direction` receives w (the derivative of X in t).
template <typename T>
void RayPoint(const T* R, const T* centre, const T& ray_time, const T* ray, T* direction,
              T* point) {
  for (int r = 0; r < 3; ++r) {
    direction[r] = R[3 * r] * ray[0] + R[3 * r + 1] * ray[1] + R[3 * r + 2] * ray[2];
    point[r] = centre[r] + ray_time * direction[r];
  }
}

// r = π(p) − û with p = Rᵀ(X − O): a world point X seen by the target camera (R, O), projected with
// the plain pinhole `pinhole` = (fx, fy, cx, cy) at kFx..kCy (distortion enters only through the
// undistorted pixels, paper §3.2), less the target's undistorted pixel û. `offset` receives X − O
// and `p_cam` p, which the derivatives need.
template <typename T>
void TargetResidual(const T* R, const T* centre, const T* pinhole, const T* point,
                    const T* undistorted, T* offset, T* p_cam, T* residual) {
  for (int r = 0; r < 3; ++r) offset[r] = point[r] - centre[r];
  for (int c = 0; c < 3; ++c) {
    p_cam[c] = R[c] * offset[0] + R[3 + c] * offset[1] + R[6 + c] * offset[2];
  }
  const T inv_z = T(1) / p_cam[2];
  residual[0] = pinhole[kFx] * (p_cam[0] * inv_z) + pinhole[kCx] - undistorted[0];
  residual[1] = pinhole[kFy] * (p_cam[1] * inv_z) + pinhole[kCy] - undistorted[1];
}

// The derivatives TargetResidual's callers chain: ∂u/∂p (2×3), ∂r/∂X = ∂u/∂p · Rᵀ (2×3), and the
// normalized projection (xn, yn) = (p₀/p₂, p₁/p₂), the residual's derivative in fx and fy.
struct TargetResidualDerivative {
  double du_dp[2][3];
  double du_dX[2][3];
  double xn, yn;
};

inline TargetResidualDerivative DifferentiateTargetResidual(const double* R, const double* pinhole,
                                                            const double* p_cam) {
  TargetResidualDerivative d;
  const double inv_z = 1.0 / p_cam[2];
  d.xn = p_cam[0] * inv_z;
  d.yn = p_cam[1] * inv_z;
  const double fx = pinhole[kFx];
  const double fy = pinhole[kFy];
  const double du_dp[2][3] = {{fx * inv_z, 0.0, -fx * d.xn * inv_z},
                              {0.0, fy * inv_z, -fy * d.yn * inv_z}};
  for (int a = 0; a < 2; ++a) {
    for (int c = 0; c < 3; ++c) d.du_dp[a][c] = du_dp[a][c];
    for (int r = 0; r < 3; ++r) {
      d.du_dX[a][r] =
          du_dp[a][0] * R[3 * r] + du_dp[a][1] * R[3 * r + 1] + du_dp[a][2] * R[3 * r + 2];
    }
  }
  return d;
}

// X = O + t·R·ray(û) for a pose block (quaternion, centre) and an undistorted pixel û.
template <typename T>
void RayPointInWorld(const T* intrinsics, const T* world_from_cam, const T& ray_time,
                     const T* undistorted_pixel, T* point) {
  T ray[3];
  PixelToUnitRay(intrinsics, undistorted_pixel, ray);
  T R[9];
  RotationFromQuaternion(world_from_cam, R);
  T direction[3];
  RayPoint(R, world_from_cam + kPoseCentreOffset, ray_time, ray, direction, point);
}

// TargetResidual for a pose block (quaternion, centre).
template <typename T>
void TargetResidualAtPose(const T* intrinsics, const T* world_from_cam, const T* point,
                          const T* undistorted, T* residual) {
  T R[9];
  RotationFromQuaternion(world_from_cam, R);
  T offset[3], p_cam[3];
  TargetResidual(R, world_from_cam + kPoseCentreOffset, intrinsics, point, undistorted, offset,
                 p_cam, residual);
}

}  // namespace raytime
