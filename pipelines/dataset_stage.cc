// The `dataset` stage: reads images, intrinsics, ground truth and the capture app's own poses
// (each when the dataset has it) into the work directory, so every later stage reads one HDF5 file
// instead of the user's layout. A video dataset (stray) has its frames extracted here, to
// WORKDIR/dataset_frames, and joined to the capture's poses by timestamp (core decodes no video).
#include <spdlog/spdlog.h>

#include <algorithm>
#include <filesystem>

#include "core/hdf5_store.h"
#include "formats/dataset.h"
#include "formats/stray.h"
#include "frontend/video_frames.h"
#include "pipelines/stages.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

constexpr const char* kDatasetFramesFolder = "dataset_frames";

class DatasetStage : public StageWithOptions<DatasetOptions> {
 public:
  std::string type() const override { return "dataset"; }
  std::string description() const override {
    return "Read a dataset (images or a video's frames, intrinsics, ground truth, the capture's "
           "poses) into the work directory";
  }
  std::vector<std::string> Inputs() const override { return {}; }
  std::vector<std::string> ExtraOutputs() const override {
    if (options_.format == "stray") return {kDatasetFramesFolder};
    return {};
  }
  std::vector<std::string> ExternalFiles() const override { return LoadDataset(options_).files; }
  // A dataset that does not load lists none: the stage's run says what is wrong with it.
  std::vector<std::string> InputFolders() const override {
    try {
      const Dataset dataset = LoadDataset(options_);
      if (dataset.video || dataset.images.image_root.empty()) return {};
      return {dataset.images.image_root};
    } catch (const std::exception&) {
      return {};
    }
  }

  nlohmann::json Run(const StageContext& context) override {
    Dataset dataset = LoadDataset(options_);
    nlohmann::json summary = nlohmann::json::object();
    if (dataset.video) {
      VideoFramesOptions video;
      video.video = dataset.video->path;
      video.stride = options_.stride;
      video.num_frames = options_.num_frames;
      VideoFramesSummary extraction;
      std::vector<DecodedFrame> decoded;
      const ImageSet frames =
          ExtractVideoFrames(video, (fs::path(context.workdir) / kDatasetFramesFolder).string(),
                             &extraction, &decoded);
      AttachVideoFrames(frames, decoded, options_.capture_width, options_.timestamps, &dataset);
      summary["video"] = extraction.ToJson();
    }
    const size_t num_capture = dataset.capture ? dataset.capture->size() : 0;
    const size_t num_ground_truth = dataset.ground_truth ? dataset.ground_truth->size() : 0;
    spdlog::info(
        fmt::format("dataset: {} images, {} camera(s), ground truth: {}, capture poses: {}{}",
                    dataset.images.images.size(), dataset.images.cameras.size(),
                    dataset.ground_truth ? std::to_string(num_ground_truth) : "none",
                    dataset.capture ? std::to_string(num_capture) : "none",
                    dataset.num_poses_without_image > 0
                        ? " (+" + std::to_string(dataset.num_poses_without_image) +
                              " poses of frames without an image, not frames)"
                        : ""));
    Hdf5Writer writer(context.output_path);
    writer.WriteImages(dataset.images);
    if (dataset.ground_truth) {
      writer.WritePoseSet("ground_truth", *dataset.ground_truth, PoseRole::kGroundTruth,
                          MakeProvenance(*this));
    }
    if (dataset.capture) {
      writer.WritePoseSet("capture", *dataset.capture, PoseRole::kPrior, MakeProvenance(*this));
    }
    if (!dataset.transforms_path.empty()) {
      writer.WriteJson(kArtifactNerfstudioTransforms,
                       {{"path", dataset.transforms_path}, {"text", dataset.transforms_text}});
    }
    writer.Commit();
    summary["format"] = options_.format;
    summary["num_images"] = dataset.images.images.size();
    summary["num_cameras"] = dataset.images.cameras.size();
    summary["has_ground_truth"] = dataset.ground_truth.has_value();
    summary["num_ground_truth_poses"] = num_ground_truth;
    summary["has_capture_poses"] = dataset.capture.has_value();
    summary["num_capture_poses"] = num_capture;
    summary["num_poses_without_image"] = dataset.num_poses_without_image;
    summary["has_timestamps"] = !dataset.timestamps.empty();
    if (!dataset.timestamps.empty()) {
      const auto [first, last] =
          std::minmax_element(dataset.timestamps.begin(), dataset.timestamps.end(),
                              [](const auto& a, const auto& b) { return a.second < b.second; });
      summary["time_span_s"] = last->second - first->second;
    }
    summary["warnings"] = WarningsToJson(dataset.warnings);
    return summary;
  }
};

}  // namespace

std::unique_ptr<Stage> CreateDatasetStage() { return std::make_unique<DatasetStage>(); }

}  // namespace raytime
