// LaMAR (Sarlin et al., ECCV 2022; microsoft/lamar-benchmark CAPTURE.md) sessions in the Capture
// format (docs/formats.md): SESSION/sensors.txt, images.txt, trajectories.txt, optionally rigs.txt
// and proc/alignment_trajectories.txt, images below SESSION/raw_data/. Text files are comma
// separated with `#` comments, following Kapture with the pose direction reverted:
//  - sensors.txt `sensor_id, name, sensor_type, model, width, height, params...` (COLMAP camera
//    models and pixel convention; PINHOLE and SIMPLE_PINHOLE are read);
//  - images.txt `timestamp, sensor_id, image_path` (path relative to raw_data/);
//  - trajectories.txt `timestamp, device_id, qw, qx, qy, qz, tx, ty, tz[, covariance]`:
//    sensor-to-world (or rig-to-world) poses, OpenCV camera axes, from the device's own tracking
//    (the capture poses);
//  - rigs.txt `rig_id, sensor_id, qw, qx, qy, qz, tx, ty, tz`: sensor-to-rig;
//  - proc/alignment_trajectories.txt: the same as trajectories.txt, registered to the reference
//    (the ground truth).
// Timestamps are integers in microseconds; an image takes the pose of its device at its
// timestamp, or one joined by time (core/timestamps.h) when the trajectory has none there.
#pragma once

#include <string>

#include "core/timestamps.h"
#include "formats/capture.h"

namespace raytime {

// `path` is the session folder. Errors name the file and line.
CaptureRecording ReadLamar(const std::string& path, const TimestampJoinOptions& options);

}  // namespace raytime
