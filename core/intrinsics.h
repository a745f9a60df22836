// Calibrations read from files turned into the camera model (core/camera.h), with tolerance where
// it costs nothing (issue 13): real datasets carry numerical noise that is not a property of the
// lens. DTU's calibration has a skew of 0.0002 px at fx = 2892, and its per-view K differ by
// 0.0005 px; refusing the first or keeping 49 "different" cameras for the second would make the
// data unusable for no gain in accuracy.
#pragma once

#include <Eigen/Core>
#include <string>

#include "core/types.h"
#include "core/warnings.h"

namespace raytime {

// A skew s is dropped when its largest effect over the image, |s| · height / fy pixels (x moves by
// s · y_normalized, and |y_normalized| <= height / fy while the principal point is inside the
// image), is at most this; a thousandth of the 0.5 px keypoint noise the front end assumes.
inline constexpr double kNegligibleSkewPx = 0.01;

// Intrinsics that differ by at most these are one camera: pixels on fx, fy, cx, cy (a thousandth
// of a pixel: text files' rounding, not a different lens), and unitless on k1, k2, p1, p2.
inline constexpr double kSameCameraPx = 1e-3;
inline constexpr double kSameCameraDistortion = 1e-9;

// The camera of a 3x3 K = [fx s cx; 0 fy cy; 0 0 1] (OpenCV pixel convention) and the image size,
// without distortion. A K of another shape, non-positive focal lengths, or a skew whose effect
// exceeds kNegligibleSkewPx is an InputError naming `path` (with the measured effect); a smaller
// skew is zeroed and reported in `warnings` (when given) as one "skew_ignored" warning that lists
// every image concerned (`image` is this one's name) and the largest skew and effect.
CameraIntrinsics IntrinsicsFromK(const Eigen::Matrix3d& K, int width, int height,
                                 const std::string& path, const std::string& image,
                                 Warnings* warnings);

// Makes cameras whose size is equal and whose intrinsics differ by at most kSameCameraPx and
// kSameCameraDistortion one camera. Each camera joins the first earlier camera within tolerance
// and takes its values unchanged (not the mean: the result is values some file holds, it does not
// depend on which other views were loaded, and exactly equal cameras are untouched bit for bit);
// a merged camera is therefore at most the tolerance from the one it joined. Merged cameras are
// removed (the others keep their order) and the images' camera indices renumbered. Reports a
// "cameras_merged" warning (when given) with how many cameras became how many, the images whose
// camera was merged and the largest difference.
void MergeNearlyEqualCameras(ImageSet* images, Warnings* warnings);

}  // namespace raytime
