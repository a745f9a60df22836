// Strecha et al. (CVPR 2008) scenes, the layout of ../shared/data/strecha:
//   ROOT/images/NAME                 the images
//   ROOT/gt_dense_cameras/NAME.camera 26 numbers: K (3x3), radial distortion (3, zeros),
//                                    R camera-to-world (3x3), centre (3), width height.
// K uses the OpenCV pixel convention (pixel centres at integers). Rotations are orthonormalized.
#pragma once

#include <string>

#include "core/types.h"
#include "core/warnings.h"

namespace raytime {

struct StrechaCamera {
  CameraIntrinsics intrinsics;
  Rigid3 world_from_cam;
};

// Errors name the file, and for a wrong count say how many numbers were found and expected. K goes
// through IntrinsicsFromK (core/intrinsics.h): a negligible skew is dropped with a warning.
StrechaCamera ReadStrechaCamera(const std::string& path, Warnings* warnings = nullptr);
void WriteStrechaCamera(const std::string& path, const StrechaCamera& camera);  // atomic

// Reads every ROOT/gt_dense_cameras/*.camera; each must have its image in ROOT/images (a missing
// image is an InputError naming it, as is an image without a camera file). Images with
// identical intrinsics share one camera.
void ReadStrechaScene(const std::string& root, ImageSet* images, PoseSet* ground_truth,
                      Warnings* warnings = nullptr);

}  // namespace raytime
