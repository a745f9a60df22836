// The `features` stage: SIFT keypoints and descriptors of every image (SPEC §5, paper §4.1).
// Images come from the `images` artifact (the dataset stage's image list), or from a video file
// whose sampled frames this stage writes to WORKDIR/frames and lists itself.
#include <spdlog/spdlog.h>

#include <filesystem>

#include "core/hdf5_store.h"
#include "frontend/feature_extraction.h"
#include "frontend/video_frames.h"
#include "pipelines/stages.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

constexpr const char* kFramesFolder = "frames";

struct FeaturesStageOptions {
  FeatureExtractionOptions extraction;
  VideoFramesOptions video;  // used when video.video is set

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    extraction.VisitFields(v);  // flat keys: features.max_features, ...
    video.VisitFields(v);       // features.video, features.stride, ...
  }
};

class FeaturesStage : public StageWithOptions<FeaturesStageOptions> {
 public:
  std::string type() const override { return "features"; }
  std::string description() const override {
    return "Extract SIFT features of the images (or of a video's sampled frames)";
  }
  bool FromVideo() const { return !options_.video.video.empty(); }
  std::vector<std::string> Inputs() const override {
    if (FromVideo()) return {};
    return {kArtifactImages};
  }
  std::vector<std::string> ExtraOutputs() const override {
    if (FromVideo()) return {kFramesFolder};
    return {};
  }
  std::vector<std::string> ExternalFiles() const override {
    if (FromVideo()) return {options_.video.video};
    return {};
  }

  nlohmann::json Run(const StageContext& context) override {
    nlohmann::json summary = nlohmann::json::object();
    ImageSet images;
    if (FromVideo()) {
      VideoFramesSummary video;
      images = ExtractVideoFrames(options_.video,
                                  (fs::path(context.workdir) / kFramesFolder).string(), &video);
      summary["video"] = video.ToJson();
    } else {
      images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    }
    std::vector<ImageFeatures> features;
    const FeatureExtractionSummary extraction =
        ExtractFeatures(images, options_.extraction, &features);
    spdlog::info(fmt::format(
        "features: {} keypoints in {} images ({} to {} per image, budget {}; {} upsampled), "
        "{:.2f} s",
        extraction.num_keypoints, extraction.num_images, extraction.min_keypoints,
        extraction.max_keypoints, options_.extraction.max_features, extraction.num_upsampled,
        extraction.seconds));
    Hdf5Writer writer(context.output_path);
    // A video's frames exist only here: this file is where later stages find the image list.
    if (FromVideo()) writer.WriteImages(images);
    writer.WriteFeatures(features, MakeProvenance(*this));
    writer.Commit();
    summary.update(extraction.ToJson());
    return summary;
  }
};

}  // namespace

std::unique_ptr<Stage> CreateFeaturesStage() { return std::make_unique<FeaturesStage>(); }

}  // namespace raytime
