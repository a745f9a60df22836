// Stray Scanner (iOS, strayrobots/scanner) export (docs/formats.md): ROOT/rgb.mp4 (the camera's
// frames, presentation time = ARKit frame count / 60 s), ROOT/camera_matrix.csv (3 lines of 3
// comma-separated values: the 3x3 K at the capture resolution) and ROOT/odometry.csv (header
// `timestamp, frame, x, y, z, qx, qy, qz, qw`: ARKit's timestamp in seconds, the number of the
// video frame recorded with the pose, the camera centre and the camera-to-world quaternion, which
// the app already turns into OpenCV camera axes by q_WA * q_AC with q_AC a half turn about x).
//
// core decodes no video: ReadStray describes the video (Dataset::video) and the dataset stage
// extracts its frames and calls AttachVideoFrames, which joins them to the odometry by timestamp.
#pragma once

#include <string>
#include <vector>

#include "core/timestamps.h"
#include "formats/dataset.h"

namespace raytime {

// The dataset of a Stray Scanner export before its frames are decoded: `video` set, no images.
// Errors name the file and line.
Dataset ReadStray(const std::string& root);

// The odometry's poses named as AttachVideoFrames names frames (frame_NNNNNN.jpg after the
// `frame` column; the first row of a frame number wins), for ReadPoseFile.
PoseSet ReadStrayPoses(const std::string& path);

// Makes `dataset` (with `video` set) hold the decoded frames `frames` (image list of the frames
// written to disk, frames[i] decoded as decoded[i], one shared camera of the decoded size):
//  - intrinsics: K scaled from the capture resolution to the decoded size, by decoded width /
//    capture_width when capture_width > 0; otherwise unscaled when the principal point lies
//    within 10 % of the frames' centre, else scaled by the ratio the principal point shows
//    (warning "intrinsics_rescaled", which says the scale was estimated);
//  - clocks: the video's times map onto the trajectory's by the median over trajectory poses that
//    name a decoded frame of (pose time - that frame's video time); no such pose is an InputError;
//  - poses: JoinByTimestamp of the frames' times to the trajectory; frames left out are dropped
//    from the images and reported ("unjoined_frames"). The joined poses become `capture` and the
//    frames' times (trajectory clock) `timestamps`.
void AttachVideoFrames(const ImageSet& frames, const std::vector<DecodedFrame>& decoded,
                       int capture_width, const TimestampJoinOptions& options, Dataset* dataset);

}  // namespace raytime
