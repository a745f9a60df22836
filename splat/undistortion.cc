#include "splat/undistortion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>
#include <string>
#include <vector>

#include "core/error.h"

namespace raytime {
namespace {

// Newton iterations for the border pixels: the solver's 5 (paper §3.2) meet its accuracy near the
// keypoints; at the corners of a strongly distorted lens more are needed to converge to 1e-12.
constexpr int kBorderIterations = 20;

// Where `camera`'s distorted pixel (OpenCV convention) lands in the pinhole camera with the same
// focal lengths and principal point, in COLMAP's pixel convention (+0.5), as the size rule below
// is stated in it.
Eigen::Vector2d PinholeColmapPixel(const CameraIntrinsics& camera, double x, double y) {
  const double* p = camera.params.data();
  const double distorted[2] = {(x - p[kCx]) / p[kFx], (y - p[kCy]) / p[kFy]};
  double normalized[2];
  UndistortNormalized(p, distorted, normalized, kBorderIterations);
  return {p[kFx] * normalized[0] + p[kCx] + 0.5, p[kFy] * normalized[1] + p[kCy] + 0.5};
}

// One axis of the size rule: the factor by which the image's extent along the axis changes, from
// the extremes of the undistorted near border (`near_*`, at smaller coordinates) and far border,
// the principal point `c` and the size `size` (all COLMAP convention).
double AxisScale(double c, double size, double near_min, double near_max, double far_min,
                 double far_max, const UndistortionOptions& options) {
  // Factor keeping every distorted border pixel inside (blank pixels allowed) ...
  const double keep_all = std::min(c / (c - near_min), (size - 0.5 - c) / (far_max - c));
  // ... and factor whose image lies wholly inside the distorted one (no blank pixel).
  const double no_blank = std::max(c / (c - near_max), (size - 0.5 - c) / (far_min - c));
  const double scale =
      1.0 / (keep_all * options.blank_pixels + no_blank * (1.0 - options.blank_pixels));
  return scale;
}

// UndistortedCamera of a camera with distortion, before centring: COLMAP's size rule.
CameraIntrinsics ResizedPinhole(const CameraIntrinsics& distorted,
                                const UndistortionOptions& options) {
  CameraIntrinsics pinhole = distorted;
  for (const int k : {kK1, kK2, kP1, kP2}) pinhole.params[k] = 0.0;

  const double w = distorted.width, h = distorted.height;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double left_min = kInf, left_max = -kInf, right_min = kInf, right_max = -kInf;
  for (int y = 0; y < distorted.height; ++y) {
    const double left = PinholeColmapPixel(distorted, 0.0, y).x();
    const double right = PinholeColmapPixel(distorted, w - 1.0, y).x();
    left_min = std::min(left_min, left);
    left_max = std::max(left_max, left);
    right_min = std::min(right_min, right);
    right_max = std::max(right_max, right);
  }
  double top_min = kInf, top_max = -kInf, bottom_min = kInf, bottom_max = -kInf;
  for (int x = 0; x < distorted.width; ++x) {
    const double top = PinholeColmapPixel(distorted, x, 0.0).y();
    const double bottom = PinholeColmapPixel(distorted, x, h - 1.0).y();
    top_min = std::min(top_min, top);
    top_max = std::max(top_max, top);
    bottom_min = std::min(bottom_min, bottom);
    bottom_max = std::max(bottom_max, bottom);
  }
  const double cx = distorted.params[kCx] + 0.5, cy = distorted.params[kCy] + 0.5;
  double scale_x = AxisScale(cx, w, left_min, left_max, right_min, right_max, options);
  double scale_y = AxisScale(cy, h, top_min, top_max, bottom_min, bottom_max, options);
  if (!(std::isfinite(scale_x) && scale_x > 0 && std::isfinite(scale_y) && scale_y > 0)) {
    throw InputError(
        "undistortion: the distortion (k1, k2, p1, p2) = (" +
        std::to_string(distorted.params[kK1]) + ", " + std::to_string(distorted.params[kK2]) +
        ", " + std::to_string(distorted.params[kP1]) + ", " +
        std::to_string(distorted.params[kP2]) +
        ") folds the image border over or past the principal point: no undistorted image size");
  }
  scale_x = std::clamp(scale_x, options.min_scale, options.max_scale);
  scale_y = std::clamp(scale_y, options.min_scale, options.max_scale);
  // Whole pixels, rounded down, at least one; the principal point keeps its relative position
  // (in COLMAP's convention, where the image spans [0, size]).
  pinhole.width = static_cast<int>(std::max(1.0, scale_x * w));
  pinhole.height = static_cast<int>(std::max(1.0, scale_y * h));
  pinhole.params[kCx] = cx * pinhole.width / w - 0.5;
  pinhole.params[kCy] = cy * pinhole.height / h - 0.5;
  return pinhole;
}

}  // namespace

bool IsUndistorted(const CameraIntrinsics& camera) {
  for (const int k : {kK1, kK2, kP1, kP2}) {
    if (std::abs(camera.params[k]) > kNoDistortion) return false;
  }
  return true;
}

CameraIntrinsics UndistortedCamera(const CameraIntrinsics& distorted,
                                   const UndistortionOptions& options) {
  ValidateOptions(options, "undistortion");
  if (distorted.width <= 0 || distorted.height <= 0) {
    throw InputError("undistortion: camera has no image size (" + std::to_string(distorted.width) +
                     " x " + std::to_string(distorted.height) + ")");
  }
  CameraIntrinsics pinhole = distorted;
  for (const int k : {kK1, kK2, kP1, kP2}) pinhole.params[k] = 0.0;
  if (!IsUndistorted(distorted)) pinhole = ResizedPinhole(distorted, options);
  if (options.centre_principal_point) {
    // COLMAP convention (the image spans [0, size]); at least one pixel.
    const auto centre = [](double c, int* size, double* param) {
      const double half = std::min(c, *size - c);
      *size = static_cast<int>(std::max(1.0, std::floor(2.0 * half + 1e-9)));
      *param = 0.5 * *size - 0.5;
    };
    centre(pinhole.params[kCx] + 0.5, &pinhole.width, &pinhole.params[kCx]);
    centre(pinhole.params[kCy] + 0.5, &pinhole.height, &pinhole.params[kCy]);
  }
  return pinhole;
}

bool IsResampled(const CameraIntrinsics& distorted, const CameraIntrinsics& pinhole) {
  return !IsUndistorted(distorted) || pinhole.width != distorted.width ||
         pinhole.height != distorted.height || pinhole.params[kCx] != distorted.params[kCx] ||
         pinhole.params[kCy] != distorted.params[kCy] ||
         pinhole.params[kFx] != distorted.params[kFx] ||
         pinhole.params[kFy] != distorted.params[kFy];
}

cv::Mat UndistortImage(const cv::Mat& image, const CameraIntrinsics& distorted,
                       const CameraIntrinsics& pinhole) {
  if (image.cols != distorted.width || image.rows != distorted.height) {
    throw InputError("undistortion: image is " + std::to_string(image.cols) + " x " +
                     std::to_string(image.rows) + " but its camera is " +
                     std::to_string(distorted.width) + " x " + std::to_string(distorted.height));
  }
  const auto K = [](const CameraIntrinsics& camera) {
    cv::Mat k = cv::Mat::eye(3, 3, CV_64F);
    k.at<double>(0, 0) = camera.fx();
    k.at<double>(1, 1) = camera.fy();
    k.at<double>(0, 2) = camera.cx();
    k.at<double>(1, 2) = camera.cy();
    return k;
  };
  const cv::Mat coefficients =
      (cv::Mat_<double>(1, 4) << distorted.params[kK1], distorted.params[kK2],
       distorted.params[kP1], distorted.params[kP2]);
  cv::Mat map_x, map_y;
  cv::initUndistortRectifyMap(K(distorted), coefficients, cv::Mat(), K(pinhole),
                              cv::Size(pinhole.width, pinhole.height), CV_32FC1, map_x, map_y);
  cv::Mat out;
  cv::remap(image, out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar::all(0));
  return out;
}

Eigen::Vector2d UndistortedPixel(const CameraIntrinsics& distorted, const CameraIntrinsics& pinhole,
                                 const Eigen::Vector2d& pixel) {
  const double* p = distorted.params.data();
  const double xd[2] = {(pixel.x() - p[kCx]) / p[kFx], (pixel.y() - p[kCy]) / p[kFy]};
  double x[2];
  UndistortNormalized(p, xd, x, kBorderIterations);
  return {pinhole.fx() * x[0] + pinhole.cx(), pinhole.fy() * x[1] + pinhole.cy()};
}

}  // namespace raytime
