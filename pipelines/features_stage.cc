// The `features` stage: SIFT keypoints and descriptors of every image (SPEC §5, paper §4.1).
// Images come from the `images` artifact (the dataset stage's image list), or from a video file
// whose sampled frames this stage writes to WORKDIR/frames and lists itself.
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <limits>
#include <map>

#include "core/content_hash.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/timing.h"
#include "frontend/feature_extraction.h"
#include "frontend/video_frames.h"
#include "pipelines/stages.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

constexpr const char* kFramesFolder = "frames";
// JSON document beside the features: per image (in the order of /features) the content key its
// features were computed under and whether its scale space was upsampled, so the next run reuses
// them image by image.
constexpr const char* kFeatureKeysJson = "feature_keys";

// The features of the previous run in this work directory, by content key.
struct PreviousFeatures {
  std::map<std::string, int> row_of_key;
  std::vector<ImageFeatures> features;
  std::vector<bool> upsampled;
};

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
    const auto start = std::chrono::steady_clock::now();
    const int num_images = static_cast<int>(images.images.size());
    // Images whose key the previous run's output holds are not read again (issue 34: a capture
    // that grows costs only its new frames).
    FeatureExtractionOptions extraction_options = options_.extraction;
    const std::string options_key = OptionsToJson(extraction_options).dump();
    std::vector<std::string> keys(num_images);
    for (int i = 0; i < num_images; ++i) keys[i] = FeatureKey(images, i, options_key);
    const PreviousFeatures previous = ReadPrevious(context);
    std::vector<ImageFeatures> features(num_images);
    std::vector<bool> upsampled(num_images, false);
    ImageSet to_extract = images;
    to_extract.images.clear();
    std::vector<int> extracted_index;
    for (int i = 0; i < num_images; ++i) {
      const auto found = previous.row_of_key.find(keys[i]);
      if (found == previous.row_of_key.end()) {
        to_extract.images.push_back(images.images[i]);
        extracted_index.push_back(i);
        continue;
      }
      features[i] = previous.features[found->second];
      upsampled[i] = previous.upsampled[found->second];
    }
    const int num_reused = num_images - static_cast<int>(extracted_index.size());
    if (num_reused > 0) {
      spdlog::info(fmt::format(
          "features: {} of {} images unchanged since the previous run here, their features reused",
          num_reused, num_images));
    }
    FeatureExtractionSummary extraction;
    if (!extracted_index.empty()) {
      std::vector<ImageFeatures> extracted;
      extraction = ExtractFeatures(to_extract, options_.extraction, &extracted);
      for (size_t k = 0; k < extracted_index.size(); ++k) {
        features[extracted_index[k]] = std::move(extracted[k]);
        upsampled[extracted_index[k]] = extraction.upsampled[k];
      }
    }
    // The summary describes every image, reused or extracted.
    FeatureExtractionSummary total;
    total.num_images = num_images;
    total.num_upsampled = static_cast<int>(std::count(upsampled.begin(), upsampled.end(), true));
    total.min_keypoints = num_images > 0 ? std::numeric_limits<int>::max() : 0;
    for (const ImageFeatures& f : features) {
      const int count = static_cast<int>(f.keypoints.rows());
      total.num_keypoints += count;
      total.min_keypoints = std::min(total.min_keypoints, count);
      total.max_keypoints = std::max(total.max_keypoints, count);
    }
    total.seconds = SecondsSince(start);
    spdlog::info(fmt::format(
        "features: {} keypoints in {} images ({} extracted, {} reused; {} to {} per image, budget "
        "{}; {} upsampled), {:.2f} s",
        total.num_keypoints, total.num_images, extracted_index.size(), num_reused,
        total.min_keypoints, total.max_keypoints, options_.extraction.max_features,
        total.num_upsampled, total.seconds));
    Hdf5Writer writer(context.output_path);
    // A video's frames exist only here: this file is where later stages find the image list.
    if (FromVideo()) writer.WriteImages(images);
    writer.WriteFeatures(features, MakeProvenance(*this));
    writer.WriteJson(kFeatureKeysJson, {{"keys", keys}, {"upsampled", upsampled}});
    writer.Commit();
    summary.update(total.ToJson());
    summary["num_images_extracted"] = extracted_index.size();
    summary["num_images_reused"] = num_reused;
    summary["extraction_seconds"] = extraction.seconds;
    return summary;
  }

 private:
  // What an image's features are a function of: its file's bytes, the size the image list gives
  // it (checked against the file when extracted), the extraction options (`options_key`, their
  // JSON) and this executable.
  static std::string FeatureKey(const ImageSet& images, int i, const std::string& options_key) {
    const ImageInfo& info = images.images[i];
    const nlohmann::json material = {
        {"executable", ExecutableHash()},
        {"options", options_key},
        {"image", HashFileContents((fs::path(images.image_root) / info.name).string())},
        {"width", info.width},
        {"height", info.height}};
    return HashBytes(material.dump());
  }

  // The previous run's features by key; none when there is no previous output, it predates the
  // keys, or it does not read (then everything is extracted, and the log says why).
  static PreviousFeatures ReadPrevious(const StageContext& context) {
    PreviousFeatures previous;
    const bool read = context.ReadPreviousOutput(
        [&](const Hdf5Reader& reader) {
          if (!reader.HasJson(kFeatureKeysJson) || !reader.HasFeatures()) return;
          const nlohmann::json index = reader.ReadJson(kFeatureKeysJson);
          const auto keys = index.at("keys").get<std::vector<std::string>>();
          previous.upsampled = index.at("upsampled").get<std::vector<bool>>();
          previous.features = reader.ReadFeatures();
          if (keys.size() != previous.features.size() || keys.size() != previous.upsampled.size()) {
            throw InputError(std::to_string(keys.size()) + " keys for " +
                             std::to_string(previous.features.size()) + " images");
          }
          for (size_t r = 0; r < keys.size(); ++r) {
            previous.row_of_key[keys[r]] = static_cast<int>(r);
          }
        },
        "extracting every image");
    return read ? previous : PreviousFeatures();
  }
};

}  // namespace

std::unique_ptr<Stage> CreateFeaturesStage() { return std::make_unique<FeaturesStage>(); }

}  // namespace raytime
