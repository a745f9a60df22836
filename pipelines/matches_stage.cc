// The `matches` stage: pairwise descriptor matching, geometric verification and guided matching
// (SPEC §5, paper §4.1). Reads the image list and the features, writes the verified pairs.
#include <spdlog/spdlog.h>

#include "core/hdf5_store.h"
#include "frontend/matching.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

constexpr const char* kArtifactFeatures = "features";

class MatchesStage : public StageWithOptions<MatchingOptions> {
 public:
  std::string type() const override { return "matches"; }
  std::string description() const override {
    return "Match image pairs and verify them geometrically (ratio test, mutual check, guided "
           "matching)";
  }
  std::vector<std::string> Inputs() const override { return {kArtifactImages, kArtifactFeatures}; }

  nlohmann::json Run(const StageContext& context) override {
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    const std::vector<ImageFeatures> features =
        Hdf5Reader(context.Require(kArtifactFeatures)).ReadFeatures();
    std::vector<PairMatches> pairs;
    const MatchingSummary summary = MatchImages(images, features, options_, &pairs);
    spdlog::info(
        "matches: {} of {} pairs verified ({} dropped below {} inliers), {} inliers, "
        "{:.2f} s",
        summary.num_verified_pairs, summary.num_pairs, summary.num_dropped_pairs,
        options_.min_num_inliers, summary.num_inliers, summary.seconds);
    Hdf5Writer writer(context.output_path);
    writer.WriteMatches(pairs, MakeProvenance(*this));
    writer.Commit();
    return summary.ToJson();
  }
};

}  // namespace

std::unique_ptr<Stage> CreateMatchesStage() { return std::make_unique<MatchesStage>(); }

}  // namespace raytime
