// NeRFCapture (iOS, jc211/NeRFCapture) offline export (docs/formats.md): ROOT/transforms.json in
// instant-ngp's layout plus ROOT/images/<n>.png. Each frame has `file_path` ("images/<n>", the
// extension left out by the app), `transform_matrix` (4x4 rows, camera-to-world in ARKit camera
// axes, as nerfstudio's), `timestamp` (seconds, ARKit's clock) and its own `fl_x`, `fl_y`, `cx`,
// `cy`, `w`, `h` (ARKit's intrinsics, taken as given like every ARKit reader's; nerfstudio's
// reader instead shifts cx, cy by 0.5). The poses are the capture's, not ground truth.
#pragma once

#include <string>

#include "formats/capture.h"

namespace raytime {

// `path` is the transforms.json file.
CaptureRecording ReadNerfCapture(const std::string& path);

}  // namespace raytime
