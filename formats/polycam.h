// Polycam "raw data" export (docs/formats.md; PolyCam/polyform README):
// ROOT/keyframes/images/<ts>.jpg with ROOT/keyframes/cameras/<ts>.json, and, when Polycam's
// on-device pose optimization ran, ROOT/keyframes/corrected_images and corrected_cameras
// (undistorted images, optimized poses), which are preferred. <ts> is the frame's timestamp in
// microseconds. A camera file holds `fx`, `fy`, `cx`, `cy`, `width`, `height` and `t_00` ...
// `t_23`, the top three rows of the 4x4 camera-to-world matrix (row-major) in ARKit camera axes. A
// camera file without its image is not a frame of the dataset.
#pragma once

#include <string>

#include "formats/capture.h"

namespace raytime {

// `path` is the export's folder (holding keyframes/) or its keyframes/ folder.
CaptureRecording ReadPolycam(const std::string& path);

}  // namespace raytime
