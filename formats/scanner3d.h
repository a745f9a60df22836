// 3D Scanner App (iOS, Laan Labs) "All Data" export, also MobileBrick's raw ARKit data
// (docs/formats.md): ROOT/frame_NNNNN.json per ARKit frame with `cameraPoseARFrame` (16 values,
// row-major 4x4 camera-to-world in ARKit camera axes), `intrinsics` (9 values, row-major 3x3, at
// the image's resolution) and `time` (seconds); ROOT/frame_NNNNN.jpg for the frames whose image
// was kept (the app keeps about every third). Poses without an image are not frames.
#pragma once

#include <string>

#include "formats/capture.h"

namespace raytime {

// `path` is the export's folder. Errors name the frame file and what was expected.
CaptureRecording ReadScanner3d(const std::string& path);

}  // namespace raytime
