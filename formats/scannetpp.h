// ScanNet++ iPhone data (Yeshwanth et al., ICCV 2023; scannetpp/scannetpp common/scene_release.py)
// (docs/formats.md): SCENE/iphone/rgb/frame_NNNNNN.jpg (the frames of iphone/rgb.mkv, extracted
// with the ScanNet++ toolkit's iphone/prepare_iphone_data.py) and SCENE/iphone/
// pose_intrinsic_imu.json, an object keyed by frame_NNNNNN whose values hold `intrinsic` (3x3),
// `pose` (4x4 camera-to-world from ARKit: the capture prior), `aligned_pose` (4x4 camera-to-world
// registered to the laser scan, OpenCV camera axes: the ground truth) and `timestamp` (seconds).
// The toolkit does not document `pose`'s camera axes: they are taken as aligned_pose's (OpenCV)
// unless the frames' relative rotations agree clearly better with ARKit's axes (diag(1, -1, -1)).
#pragma once

#include <string>

#include "formats/capture.h"

namespace raytime {

// `path` is the scene folder (holding iphone/) or its iphone/ folder. Entries without an extracted
// frame are not frames of the dataset.
CaptureRecording ReadScanNetPPIphone(const std::string& path);

}  // namespace raytime
