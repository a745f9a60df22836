// The ray-time geometry of paper §3.2, templated on the scalar so that the evaluation cache (jets
// over 16 local parameters), the uncached automatic-differentiation residual (jets over 23) and
// plain doubles all run the same arithmetic, which is what makes the cached and uncached Jacobians
// identical rather than merely close.
//
// Pose blocks are 7-vectors `world_from_cam`: the rotation R_i (camera to world) as a unit
// quaternion in Eigen memory order (x, y, z, w), then the centre O_i (ray origin) in world
// coordinates (SPEC §2).
#pragma once

#include "core/camera.h"

namespace raytime {

inline constexpr int kPoseBlockSize = 7;     // quaternion x, y, z, w + centre
inline constexpr int kPoseCentreOffset = 4;  // index of O_i in the pose block
// Paper §3.3: a ray time is a positive depth, bounded below at 1e-9 (both solvers).
inline constexpr double kRayTimeLowerBound = 1e-9;

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

// X = O + t * R * ray(û) (paper eq. raypoint): the point an observation implies at ray time t,
// from its undistorted pixel û.
template <typename T>
void RayPointInWorld(const T* intrinsics, const T* world_from_cam, const T& ray_time,
                     const T* undistorted_pixel, T* point) {
  T ray[3];
  PixelToUnitRay(intrinsics, undistorted_pixel, ray);
  T R[9];
  RotationFromQuaternion(world_from_cam, R);
  const T* centre = world_from_cam + kPoseCentreOffset;
  for (int r = 0; r < 3; ++r) {
    point[r] =
        centre[r] + ray_time * (R[3 * r] * ray[0] + R[3 * r + 1] * ray[1] + R[3 * r + 2] * ray[2]);
  }
}

// p = R^T (X - O): a world point in the camera frame.
template <typename T>
void CamFromWorldPoint(const T* world_from_cam, const T* point, T* p_cam) {
  T R[9];
  RotationFromQuaternion(world_from_cam, R);
  const T* centre = world_from_cam + kPoseCentreOffset;
  const T v[3] = {point[0] - centre[0], point[1] - centre[1], point[2] - centre[2]};
  for (int c = 0; c < 3; ++c) p_cam[c] = R[c] * v[0] + R[3 + c] * v[1] + R[6 + c] * v[2];
}

// π_j(X): plain pinhole projection of a world point into camera j (paper §3.2), undistorted
// pixels; distortion enters only through the undistortion of observations.
template <typename T>
void ProjectWorldPoint(const T* intrinsics, const T* world_from_cam, const T* point, T* pixel) {
  T p_cam[3];
  CamFromWorldPoint(world_from_cam, point, p_cam);
  ProjectPinhole(intrinsics, p_cam, pixel);
}

}  // namespace raytime
