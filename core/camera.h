// Shared pinhole camera with OpenCV (k1, k2, p1, p2) distortion (SPEC §2, paper §3.1–3.2).
//
// Pixel convention: OpenCV's, the centre of the top-left pixel is (0, 0). COLMAP's is (0.5, 0.5);
// the COLMAP readers and writers convert at the boundary.
//
// The free functions are templated on the scalar so that Ceres jets pass through them; they take
// the 8 intrinsics as a plain array in the order of `CameraIntrinsics::params`.
#pragma once

#include <array>
#include <cmath>
#include <string>
#include <type_traits>

namespace raytime {

// Indices into the 8-vector of shared intrinsics.
enum IntrinsicIndex { kFx = 0, kFy, kCx, kCy, kK1, kK2, kP1, kP2, kNumIntrinsics };

struct CameraIntrinsics {
  int width = 0;   // pixels
  int height = 0;  // pixels
  // fx, fy, cx, cy (pixels, OpenCV convention), k1, k2, p1, p2 (OpenCV distortion).
  std::array<double, kNumIntrinsics> params{0, 0, 0, 0, 0, 0, 0, 0};

  double fx() const { return params[kFx]; }
  double fy() const { return params[kFy]; }
  double cx() const { return params[kCx]; }
  double cy() const { return params[kCy]; }
  bool HasDistortion() const {
    return params[kK1] != 0 || params[kK2] != 0 || params[kP1] != 0 || params[kP2] != 0;
  }
  bool operator==(const CameraIntrinsics& o) const {
    return width == o.width && height == o.height && params == o.params;
  }
};

// Newton iterations of the undistortion (paper §3.2: "up to 5 iterations").
constexpr int kUndistortIterations = 5;

// Forward OpenCV distortion in normalized coordinates: x_d = distort(x).
template <typename T>
void DistortNormalized(const T* intrinsics, const T* x, T* xd) {
  const T& k1 = intrinsics[kK1];
  const T& k2 = intrinsics[kK2];
  const T& p1 = intrinsics[kP1];
  const T& p2 = intrinsics[kP2];
  const T xx = x[0] * x[0], yy = x[1] * x[1], xy = x[0] * x[1];
  const T r2 = xx + yy;
  const T radial = T(1) + r2 * (k1 + k2 * r2);
  xd[0] = x[0] * radial + T(2) * p1 * xy + p2 * (r2 + T(2) * xx);
  xd[1] = x[1] * radial + p1 * (r2 + T(2) * yy) + T(2) * p2 * xy;
}

// Inverse of DistortNormalized by Newton's method with the analytic 2x2 Jacobian, started at the
// distorted point. A fixed iteration count keeps the function branch-free for jets, so the
// derivatives of the result are those of the converged fixed point.
template <typename T>
void UndistortNormalized(const T* intrinsics, const T* xd, T* x,
                         int iterations = kUndistortIterations) {
  const T& k1 = intrinsics[kK1];
  const T& k2 = intrinsics[kK2];
  const T& p1 = intrinsics[kP1];
  const T& p2 = intrinsics[kP2];
  x[0] = xd[0];
  x[1] = xd[1];
  // Without distortion the fixed point is the start, and every iteration leaves it as it is to the
  // bit (the residual is exactly zero): plain doubles skip them. Jets do not: their derivatives in
  // the coefficients are not zero there.
  if constexpr (std::is_same_v<T, double>) {
    if (k1 == 0.0 && k2 == 0.0 && p1 == 0.0 && p2 == 0.0) return;
  }
  for (int it = 0; it < iterations; ++it) {
    const T xx = x[0] * x[0], yy = x[1] * x[1], xy = x[0] * x[1];
    const T r2 = xx + yy;
    const T radial = T(1) + r2 * (k1 + k2 * r2);
    const T dradial_dr2 = k1 + T(2) * k2 * r2;
    const T fx = x[0] * radial + T(2) * p1 * xy + p2 * (r2 + T(2) * xx) - xd[0];
    const T fy = x[1] * radial + p1 * (r2 + T(2) * yy) + T(2) * p2 * xy - xd[1];
    // d(distort)/dx, using d(r2)/dx = 2x, d(r2)/dy = 2y.
    const T j00 = radial + T(2) * xx * dradial_dr2 + T(2) * p1 * x[1] + T(6) * p2 * x[0];
    const T j01 = T(2) * x[0] * x[1] * dradial_dr2 + T(2) * p1 * x[0] + T(2) * p2 * x[1];
    const T j10 = T(2) * x[0] * x[1] * dradial_dr2 + T(2) * p1 * x[0] + T(2) * p2 * x[1];
    const T j11 = radial + T(2) * yy * dradial_dr2 + T(6) * p1 * x[1] + T(2) * p2 * x[0];
    const T inv_det = T(1) / (j00 * j11 - j01 * j10);
    x[0] -= inv_det * (j11 * fx - j01 * fy);
    x[1] -= inv_det * (j00 * fy - j10 * fx);
  }
}

// Undistorted pixel -> distorted pixel.
template <typename T>
void DistortPixel(const T* intrinsics, const T* u, T* ud) {
  const T x[2] = {(u[0] - intrinsics[kCx]) / intrinsics[kFx],
                  (u[1] - intrinsics[kCy]) / intrinsics[kFy]};
  T xd[2];
  DistortNormalized(intrinsics, x, xd);
  ud[0] = intrinsics[kFx] * xd[0] + intrinsics[kCx];
  ud[1] = intrinsics[kFy] * xd[1] + intrinsics[kCy];
}

// Distorted (observed) pixel -> undistorted pixel (paper §3.2, û = undistort(u; f, c, d)).
template <typename T>
void UndistortPixel(const T* intrinsics, const T* ud, T* u, int iterations = kUndistortIterations) {
  const T xd[2] = {(ud[0] - intrinsics[kCx]) / intrinsics[kFx],
                   (ud[1] - intrinsics[kCy]) / intrinsics[kFy]};
  T x[2];
  UndistortNormalized(intrinsics, xd, x, iterations);
  u[0] = intrinsics[kFx] * x[0] + intrinsics[kCx];
  u[1] = intrinsics[kFy] * x[1] + intrinsics[kCy];
}

// Undistorted pixel -> unit ray in the camera frame (x right, y down, z forward).
template <typename T>
void PixelToUnitRay(const T* intrinsics, const T* u, T* ray) {
  ray[0] = (u[0] - intrinsics[kCx]) / intrinsics[kFx];
  ray[1] = (u[1] - intrinsics[kCy]) / intrinsics[kFy];
  ray[2] = T(1);
  using std::sqrt;
  const T inv_norm = T(1) / sqrt(ray[0] * ray[0] + ray[1] * ray[1] + T(1));
  ray[0] *= inv_norm;
  ray[1] *= inv_norm;
  ray[2] *= inv_norm;
}

// Distorted (observed) pixel -> unit ray in the camera frame: UndistortPixel, then
// PixelToUnitRay. `undistorted`, when given, receives the undistorted pixel between the two.
template <typename T>
void ObservedPixelToUnitRay(const T* intrinsics, const T* observed, T* ray,
                            T* undistorted = nullptr) {
  T u[2];
  UndistortPixel(intrinsics, observed, u);
  PixelToUnitRay(intrinsics, u, ray);
  if (undistorted != nullptr) {
    undistorted[0] = u[0];
    undistorted[1] = u[1];
  }
}

// Camera-frame point -> undistorted pixel (plain pinhole, paper §3.2 π_j).
template <typename T>
void ProjectPinhole(const T* intrinsics, const T* p_cam, T* u) {
  const T inv_z = T(1) / p_cam[2];
  u[0] = intrinsics[kFx] * p_cam[0] * inv_z + intrinsics[kCx];
  u[1] = intrinsics[kFy] * p_cam[1] * inv_z + intrinsics[kCy];
}

}  // namespace raytime
