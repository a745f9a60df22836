// Which intrinsics parameter blocks a solve has. The paper's cameras share one set of 2 + 2 + 4
// intrinsics (§3.1, §3.4); phone captures carry intrinsics per frame (MobileBrick's focal drifts
// 0.9–2.9 % per scene, §4.6 "Ablation"), and a shared set forces that drift into the poses.
// - Fixed intrinsics, and self-calibration `per_camera`: one block per camera of the input, every
//   image on its own camera's block (images that share a camera share its block, so a
//   single-camera capture has the paper's one block).
// - Self-calibration `shared`: one block for every image, started at the per-parameter median over
//   the images of their cameras (RefineOptions::intrinsics_sharing).
#pragma once

#include <vector>

#include "core/camera.h"
#include "refine/refine_types.h"

namespace raytime {

// Given cameras that disagree by more than this somewhere on the image (CameraDisagreementPx) are
// reported when a shared set replaces them: twice the 0.5 px keypoint noise the front end assumes,
// a focal difference of ~0.1 % on a 1400 px lens.
inline constexpr double kSharedCameraTolerancePx = 1.0;

struct CameraBlocks {
  std::vector<CameraIntrinsics> cameras;  // one per block: its (initial) intrinsics
  std::vector<int> camera_of_image;       // per image: its block

  const CameraIntrinsics& Of(int image) const { return cameras[camera_of_image[image]]; }
};

// The input's cameras and camera indices as they are (fixed intrinsics, per_camera).
CameraBlocks PerCameraBlocks(const RefineInput& input);

// One block for all images: each parameter the upper median over the images of their cameras'
// values (images, not cameras, are counted: the camera most frames were taken with weighs most,
// and the start is always values some file holds; one camera is taken unchanged, bit for bit).
// Throws InputError when the images' cameras have different image sizes (one set of intrinsics
// cannot describe both). `max_disagreement_px` receives the largest CameraDisagreementPx between
// an image's given camera and the start.
CameraBlocks SharedBlock(const RefineInput& input, double* max_disagreement_px);

// The largest distance, in pixels, between where `a` and `b` put the same ray, over a 5 x 5 grid
// of pixels spanning each camera's image (both directions: a pixel of one camera is undistorted
// and unprojected with it, then projected and distorted with the other). Zero for equal cameras.
// An image size of 0 is taken as twice the principal point.
double CameraDisagreementPx(const CameraIntrinsics& a, const CameraIntrinsics& b);

// Per camera of the input: the intrinsics of the block of `solved` its images use; a camera no
// image uses keeps the input's values.
std::vector<CameraIntrinsics> InputCameras(const RefineInput& input, const CameraBlocks& solved);

}  // namespace raytime
