#include "refine/camera_blocks.h"

namespace raytime {

CameraBlocks PerCameraBlocks(const RefineInput& input) {
  return {input.cameras, input.camera_index};
}

std::vector<CameraIntrinsics> InputCameras(const RefineInput& input, const CameraBlocks& solved) {
  std::vector<CameraIntrinsics> cameras = input.cameras;
  for (size_t i = 0; i < input.camera_index.size(); ++i) {
    cameras[input.camera_index[i]] = solved.Of(static_cast<int>(i));
  }
  return cameras;
}

}  // namespace raytime
