// MobileBrick (Li et al., CVPR 2023; ActiveVisionLab/MobileBrick README) sequences
// (docs/formats.md): ROOT/image/NNNNNN.jpg, ROOT/intrinsic/NNNNNN.txt (3x3 K of that image) and
// ROOT/pose/NNNNNN.txt (4x4 camera-to-world, OpenCV camera axes, aligned to the LEGO model's
// ground truth). The public release has no ARKit poses per image (only ARKit depth), so the
// dataset has ground truth and no capture poses: give an ARKit prior with prior.source 'file'
// (e.g. a 3D Scanner App export of the raw capture, format scanner3d), or perturb the ground truth.
#pragma once

#include <string>

#include "core/formats/capture.h"

namespace raytime {

// `path` is the sequence folder. Errors name the file and what was expected.
CaptureRecording ReadMobileBrick(const std::string& path);

}  // namespace raytime
