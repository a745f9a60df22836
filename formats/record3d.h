// Record3D (iOS) "EXR + JPG" export (docs/formats.md): ROOT/metadata.json and ROOT/rgb/<i>.jpg.
// metadata.json holds `w`, `h` (the size K refers to), `K` (9 values, column-major), `poses`
// ([qx, qy, qz, qw, tx, ty, tz] camera-to-world in ARKit camera axes, one per frame),
// optionally `perFrameIntrinsicCoeffs` ([fx, fy, cx, cy] per frame, overriding K's),
// `frameTimestamps` (seconds) and `fps`. Frame i is image <i>.jpg (or <i>.png) below ROOT/rgb; a
// pose whose image is absent is not a frame of the dataset.
#pragma once

#include <string>

#include "formats/capture.h"

namespace raytime {

// `path` is the export's folder or its metadata.json. Errors name the file and the frame.
CaptureRecording ReadRecord3d(const std::string& path);

}  // namespace raytime
