// Which intrinsics parameter blocks a solve has. The paper's cameras share one set of 2 + 2 + 4
// intrinsics (§3.1, §3.4); phone captures carry intrinsics per frame (MobileBrick's focal drifts
// 0.9–2.9 % per scene, §4.7 "Ablation"), and a shared set forces that drift into the poses. One
// block per camera of the input, every image on its own camera's block (images that share a
// camera share its block, so a single-camera capture has the paper's one block).
#pragma once

#include <vector>

#include "core/camera.h"
#include "refine/refine.h"

namespace raytime {

struct CameraBlocks {
  std::vector<CameraIntrinsics> cameras;  // one per block: its (initial) intrinsics
  std::vector<int> camera_of_image;       // per image: its block

  const CameraIntrinsics& Of(int image) const { return cameras[camera_of_image[image]]; }
};

// The input's cameras and camera indices as they are.
CameraBlocks PerCameraBlocks(const RefineInput& input);

// Per camera of the input: the intrinsics of the block of `solved` its images use; a camera no
// image uses keeps the input's values.
std::vector<CameraIntrinsics> InputCameras(const RefineInput& input, const CameraBlocks& solved);

}  // namespace raytime
