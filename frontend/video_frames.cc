#include "frontend/video_frames.h"

#include <spdlog/spdlog.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <set>

#include "core/atomic_file.h"
#include "core/error.h"
#include "core/timing.h"

namespace fs = std::filesystem;

namespace raytime {

nlohmann::json VideoFramesSummary::ToJson() const { return *this; }

ImageSet ExtractVideoFrames(const VideoFramesOptions& options, const std::string& folder,
                            VideoFramesSummary* summary, std::vector<DecodedFrame>* frames) {
  ValidateOptions(options, "video");
  const auto start = std::chrono::steady_clock::now();
  if (!fs::is_regular_file(options.video)) ThrowInput(options.video, 0, "video file not found");
  cv::VideoCapture capture(options.video);
  if (!capture.isOpened()) {
    ThrowInput(options.video, 0, "cannot open the video (unsupported container or codec?)");
  }
  // Frames to keep: evenly spaced over the reported length, or every stride-th.
  const double reported = capture.get(cv::CAP_PROP_FRAME_COUNT);
  const int frame_count = reported > 0 ? static_cast<int>(reported) : 0;
  std::set<int> wanted;
  const bool by_count = options.num_frames > 0 && frame_count > 0;
  if (options.num_frames > 0 && frame_count == 0) {
    spdlog::warn(
        fmt::format("video: {} does not report its length; using stride {} instead of {} frames",
                    options.video, options.stride, options.num_frames));
  }
  if (by_count) {
    const int count = std::min(options.num_frames, frame_count);
    for (int k = 0; k < count; ++k) {
      wanted.insert(
          count == 1 ? 0
                     : static_cast<int>(std::lround(double(k) * (frame_count - 1) / (count - 1))));
    }
  }

  const double fps = capture.get(cv::CAP_PROP_FPS);
  ImageSet images;
  images.image_root = folder;
  std::vector<DecodedFrame> kept;
  bool container_times = true;  // false once a presentation time fails to increase
  double previous_time = -1.0;
  VideoFramesSummary local;
  WriteDirectoryAtomically(folder, [&](const std::string& dir) {
    fs::create_directories(dir);
    cv::Mat frame;
    for (int index = 0; capture.read(frame); ++index) {
      ++local.num_frames_read;
      const double time_s = capture.get(cv::CAP_PROP_POS_MSEC) / 1000.0;
      if (!(time_s > previous_time)) container_times = false;
      previous_time = time_s;
      const bool keep = by_count ? wanted.count(index) > 0 : index % options.stride == 0;
      if (!keep) continue;
      if (images.images.empty()) {
        CameraIntrinsics camera;
        camera.width = frame.cols;
        camera.height = frame.rows;
        camera.params[kFx] = camera.params[kFy] = options.focal_px;
        camera.params[kCx] = 0.5 * (frame.cols - 1);
        camera.params[kCy] = 0.5 * (frame.rows - 1);
        images.cameras.push_back(camera);
      } else if (frame.cols != images.cameras[0].width || frame.rows != images.cameras[0].height) {
        ThrowInput(options.video, 0, "frame " + std::to_string(index) + " changes size");
      }
      char name[32];
      std::snprintf(name, sizeof(name), "frame_%06d.jpg", index);
      if (!cv::imwrite((fs::path(dir) / name).string(), frame,
                       {cv::IMWRITE_JPEG_QUALITY, options.jpeg_quality})) {
        throw std::runtime_error("cannot write " + (fs::path(dir) / name).string());
      }
      images.images.push_back({name, frame.cols, frame.rows, 0});
      kept.push_back({index, time_s});
      ++local.num_frames_written;
      if (local.num_frames_written % 50 == 0) {
        spdlog::info(fmt::format("video: {} frames kept of {} read", local.num_frames_written,
                                 local.num_frames_read));
      }
    }
  });
  if (images.images.empty()) ThrowInput(options.video, 0, "no frames could be decoded");
  if (frames) {
    if (!container_times) {
      if (!(fps > 0)) {
        ThrowInput(options.video, 0,
                   "the video has neither increasing frame timestamps nor a frame rate");
      }
      spdlog::warn(
          fmt::format("video: {} has no increasing frame timestamps; using frame number / {} fps",
                      options.video, fps));
      for (DecodedFrame& frame : kept) frame.time_s = frame.number / fps;
    }
    *frames = std::move(kept);
  }
  local.seconds = SecondsSince(start);
  spdlog::info(fmt::format("video: kept {} of {} frames of {} in {}", local.num_frames_written,
                           local.num_frames_read, options.video, folder));
  if (summary) *summary = local;
  return images;
}

}  // namespace raytime
