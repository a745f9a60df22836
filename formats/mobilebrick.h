// MobileBrick (Li et al., CVPR 2023; ActiveVisionLab/MobileBrick README) sequences
// (docs/formats.md): ROOT/image/NNNNNN.jpg, ROOT/intrinsic/NNNNNN.txt (3x3 K of that image) and
// ROOT/pose/NNNNNN.txt (4x4 camera-to-world, OpenCV camera axes, aligned to the LEGO model's
// ground truth). The public release has no ARKit poses per image (only ARKit depth); PoRF's copy
// of the evaluation scenes carries them as cameras_arkit.npz (IDR form: world_mat_<i> = K [R | t],
// world to image, per image in name order), read as the capture poses when it lies in ROOT.
// Without it the dataset has ground truth and no capture poses.
#pragma once

#include <string>

#include "formats/capture.h"

namespace raytime {

// `path` is the sequence folder. Errors name the file and what was expected.
CaptureRecording ReadMobileBrick(const std::string& path);

}  // namespace raytime
