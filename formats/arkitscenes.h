// ARKitScenes (Baruch et al., NeurIPS 2021 Datasets; apple/ARKitScenes DATA.md, threedod/README.md)
// (docs/formats.md): a video folder holding lowres_wide.traj, lowres_wide/<video>_<t>.png and
// lowres_wide_intrinsics/<video>_<t>.pincam (the raw layout; the 3DOD layout has them in
// <video>_frames/). Each .traj line is `t ax ay az tx ty tz`: the world-to-camera rotation as an
// axis-angle vector (radians) and translation (metres), OpenCV camera axes; these poses are the
// dataset's ground truth (estimated offline against laser scans, apple/ARKitScenes issue 15), so
// there are no capture poses. A .pincam is one line `width height fx fy cx cy`. Frames are named
// by their timestamp (seconds, 3 decimals) and joined to the trajectory by time.
#pragma once

#include <string>

#include "core/timestamps.h"
#include "formats/capture.h"

namespace raytime {

// `path` is the video folder (or its <video>_frames folder). Frames without a trajectory pose
// within options.max_time_gap_s are left out ("unjoined_frames").
CaptureRecording ReadArkitScenes(const std::string& path, const TimestampJoinOptions& options);

}  // namespace raytime
