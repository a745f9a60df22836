// Frames of a video file as an image list (issue 3: images from a video sampled at a stride or a
// target frame count). The frames are written as JPEG files so that later stages and COLMAP read
// them like any other image folder.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/options.h"
#include "core/timestamps.h"
#include "core/types.h"

namespace raytime {

struct VideoFramesOptions {
  std::string video;  // video file (anything cv::VideoCapture opens); "" = not a video input
  int stride = 1;     // keep every stride-th frame (frame 0 first)
  // Target number of frames spread evenly over the video; overrides `stride` when > 0 (needs a
  // container that reports its frame count, else `stride` is used).
  int num_frames = 0;
  // Focal length in pixels (fx = fy, principal point at the image centre, no distortion). 0 = not
  // known: the camera is written with focal 0 and matching estimates fundamental matrices.
  double focal_px = 0;
  int jpeg_quality = 95;  // of the written frames

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("video", video, "Video file to sample frames from; \"\" = the dataset's images");
    v("stride", stride, "Keep every stride-th frame (frame 0 first)", Positive(), AtMost(1e6));
    v("num_frames", num_frames, "Frames spread evenly over the video; overrides stride when > 0",
      NonNegative(), AtMost(1e6));
    v("focal_px", focal_px,
      "Video focal length, pixels (principal point at the centre); 0 = unknown", NonNegative(),
      AtMost(1e7));
    v("jpeg_quality", jpeg_quality, "JPEG quality of the written frames", AtLeast(1), AtMost(100));
  }
};

struct VideoFramesSummary {
  int num_frames_read = 0;     // decoded from the video
  int num_frames_written = 0;  // kept
  double seconds = 0;

  nlohmann::json ToJson() const;  // the fields by name
};
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(VideoFramesSummary, num_frames_read, num_frames_written, seconds)

// Decodes `options.video` and writes the kept frames to `folder`/frame_NNNNNN.jpg (NNNNNN = frame
// number in the video, so name order is time order), replacing the folder atomically. Returns
// the image list (image_root = folder, one shared camera). A video that cannot be opened or
// yields no frames is an InputError naming the file. `frames`, when given, receives each kept
// frame's number and presentation time (the container's timestamps; frame number / frame rate
// where those do not increase), in the order of the image list.
ImageSet ExtractVideoFrames(const VideoFramesOptions& options, const std::string& folder,
                            VideoFramesSummary* summary,
                            std::vector<DecodedFrame>* frames = nullptr);

}  // namespace raytime
