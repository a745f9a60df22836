// Undistortion for trainers that take only pinhole cameras (the Inria 3DGS code accepts PINHOLE and
// SIMPLE_PINHOLE alone; SPEC §7, issue 11): the pinhole camera `colmap image_undistorter` (COLMAP
// 3.8) gives a distorted camera, and the image resampled into it with OpenCV.
//
// The new camera keeps the focal lengths and the principal point's relative position; only the
// image size changes, scaled so that (blank_pixels = 0, COLMAP's default) no pixel of the new image
// falls outside the distorted one, or (blank_pixels = 1) every distorted pixel lands inside it, by
// a scale clipped to [min_scale, max_scale]. The scale comes from the undistorted positions of the
// distorted image's border pixels, one per row and column. Pixels here follow OpenCV (centre of
// the top-left pixel at (0, 0)); the rule itself is stated in COLMAP's convention, and the
// functions convert at the boundary (SPEC §2).
#pragma once

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "core/camera.h"
#include "core/options.h"

namespace raytime {

struct UndistortionOptions {
  // 0: crop to the region every new pixel sees (no black borders, COLMAP's default); 1: keep
  // every distorted pixel (black borders); between: interpolated.
  double blank_pixels = 0.0;
  // Bounds on the change of the image size (COLMAP's defaults).
  double min_scale = 0.2;
  double max_scale = 2.0;
  // Crop the new image symmetrically about the principal point so that it is the image centre:
  // the Inria code and OpenSplat's CPU path place it there whatever the camera says (issue 33), so
  // an off-centre one (7 px on the Strecha scenes at 1536 px) shifts every training ray.
  bool centre_principal_point = true;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("undistort_blank_pixels", blank_pixels,
      "3dgs: undistorted image: 0 = no black borders (crop), 1 = keep every distorted pixel (as "
      "colmap "
      "image_undistorter --blank_pixels)",
      NonNegative(), AtMost(1.0));
    v("undistort_min_scale", min_scale,
      "3dgs: smallest change of the undistorted image's size, factor (colmap --min_scale)",
      Positive(), AtMost(1));
    v("undistort_max_scale", max_scale,
      "3dgs: largest change of the undistorted image's size, factor (colmap --max_scale)",
      Positive(), AtMost(100));
    v("centre_principal_point", centre_principal_point,
      "3dgs: crop each image symmetrically so its principal point is the image centre (trainers "
      "that ignore cx, cy: Inria, OpenSplat on CPU)");
  }
  void CheckRelations(const Requirement& require) const {
    require(min_scale <= max_scale, "undistort_min_scale must not exceed undistort_max_scale");
  }
};

// Distortion this small is none: COLMAP's test (`Camera::IsUndistorted`, |k1|, |k2|, |p1|,
// |p2| <= 1e-8), under which image_undistorter copies the image and keeps the camera.
constexpr double kNoDistortion = 1e-8;
bool IsUndistorted(const CameraIntrinsics& camera);

// The pinhole camera (zero distortion) of `distorted`'s undistorted image, sized as above, then
// (centre_principal_point) cropped to the largest image centred on the principal point: in COLMAP's
// convention width = floor(2 min(cx, width - cx)), cx = width / 2, the same for y.
// Otherwise a camera that IsUndistorted comes back unchanged but for its (tiny) distortion set to
// zero; IsResampled says whether the image must be resampled into the camera or can be copied.
// Throws InputError when the distortion folds the border over (no finite scale) or when the
// camera has no image size.
CameraIntrinsics UndistortedCamera(const CameraIntrinsics& distorted,
                                   const UndistortionOptions& options);

// Whether `pinhole` (from UndistortedCamera) differs from `distorted` by more than its tiny
// distortion: its image is resampled, not copied.
bool IsResampled(const CameraIntrinsics& distorted, const CameraIntrinsics& pinhole);

// `image` (of `distorted`'s size) resampled into `pinhole`: each new pixel takes the bilinear
// interpolation of the distorted image at where `distorted` images its ray
// (cv::initUndistortRectifyMap + cv::remap), black where that falls outside the image.
// Throws InputError when the image's size is not the camera's.
cv::Mat UndistortImage(const cv::Mat& image, const CameraIntrinsics& distorted,
                       const CameraIntrinsics& pinhole);

// A pixel observed in `distorted` (e.g. a keypoint) in `pinhole`'s image.
Eigen::Vector2d UndistortedPixel(const CameraIntrinsics& distorted, const CameraIntrinsics& pinhole,
                                 const Eigen::Vector2d& pixel);

}  // namespace raytime
