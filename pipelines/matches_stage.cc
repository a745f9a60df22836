// The `matches` stage: pairwise descriptor matching, geometric verification and guided matching
// (SPEC §5, paper §4.1). Reads the image list and the features, writes the verified pairs. With
// `pairs: prior` it also reads a pose set (the prior stage's) and matches only the pairs that pose
// set says overlap (pipelines/pair_selection.h): the poses choose the pairs here, in pipelines/,
// and the front end matches and verifies them without ever seeing a pose.
#include <spdlog/spdlog.h>

#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/warnings.h"
#include "frontend/matching.h"
#include "pipelines/pair_selection.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

constexpr const char* kArtifactFeatures = "features";

struct MatchesStageOptions {
  MatchingOptions matching;
  // pairs: prior: the pose set that chooses the pairs, "prior" (the prior stage's output) unless
  // the pipeline names its prior stage, e.g. "prior@arkit" for a stage prior@arkit.
  std::string prior_poses = "prior";
  PriorPairOptions prior_pairs;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    matching.VisitFields(v);  // flat keys: matches.pairs, matches.window, ...
    v("prior_poses", prior_poses,
      "pairs: prior: pose set choosing the pairs (written by an earlier prior stage)", NonEmpty());
    prior_pairs.VisitFields(v);  // matches.prior_neighbors, ...
  }
};

class MatchesStage : public StageWithOptions<MatchesStageOptions> {
 public:
  std::string type() const override { return "matches"; }
  std::string description() const override {
    return "Match image pairs and verify them geometrically (ratio test, mutual check, guided "
           "matching)";
  }
  bool PriorPairs() const { return options_.matching.pairs == "prior"; }
  std::vector<std::string> Inputs() const override {
    std::vector<std::string> inputs = {kArtifactImages, kArtifactFeatures};
    if (PriorPairs()) inputs.push_back(PoseArtifact(options_.prior_poses));
    return inputs;
  }

  nlohmann::json Run(const StageContext& context) override {
    // Checked first: the pipeline order is wrong, nothing has been read yet.
    const std::string poses_artifact = PoseArtifact(options_.prior_poses);
    if (PriorPairs() && context.artifacts.count(poses_artifact) == 0) {
      throw InputError(
          "matches: pairs 'prior' chooses the pairs to match from the pose set '" +
          options_.prior_poses +
          "', which no earlier stage wrote: put the prior stage before matches in the pipeline "
          "(features, prior, matches, refine), or use pairs: exhaustive or sequential");
    }
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    const std::vector<ImageFeatures> features =
        Hdf5Reader(context.Require(kArtifactFeatures)).ReadFeatures();
    nlohmann::json selection_json;
    Warnings warnings;
    std::vector<std::pair<int, int>> candidates;
    if (PriorPairs()) {
      const PoseSet poses =
          Hdf5Reader(context.Require(poses_artifact)).ReadPoseSet(options_.prior_poses);
      candidates = ChoosePriorPairs(images, poses, &selection_json, &warnings);
    } else {
      candidates = SelectPairs(static_cast<int>(images.images.size()), options_.matching);
    }
    std::vector<PairMatches> pairs;
    const MatchingSummary summary =
        MatchImagePairs(images, features, options_.matching, candidates, &pairs);
    spdlog::info(
        fmt::format("matches: {} of {} pairs verified ({} dropped below {} inliers), {} inliers, "
                    "{:.2f} s",
                    summary.num_verified_pairs, summary.num_pairs, summary.num_dropped_pairs,
                    options_.matching.min_num_inliers, summary.num_inliers, summary.seconds));
    Hdf5Writer writer(context.output_path);
    writer.WriteMatches(pairs, MakeProvenance(*this));
    writer.Commit();
    nlohmann::json out = summary.ToJson();
    if (PriorPairs()) out["pair_selection"] = selection_json;
    out["warnings"] = WarningsToJson(warnings);
    return out;
  }

 private:
  // The prior pairs, logged and summarized (pairs chosen against the exhaustive count).
  std::vector<std::pair<int, int>> ChoosePriorPairs(const ImageSet& images, const PoseSet& poses,
                                                    nlohmann::json* summary_json,
                                                    Warnings* warnings) const {
    const PriorPairOptions& o = options_.prior_pairs;
    PairSelectionSummary summary;
    const std::vector<std::pair<int, int>> pairs =
        SelectPriorPairs(PairSelectionViews(images, poses), o, &summary);
    const double percent = summary.num_exhaustive_pairs > 0
                               ? 100.0 * summary.num_pairs / summary.num_exhaustive_pairs
                               : 0.0;
    spdlog::info(fmt::format(
        "matches: prior pairs from pose set '{}': {} of {} exhaustive pairs ({:.1f} %), {} by "
        "view overlap (the {} best per image, axes within {}°, overlap >= {}), {} more by a "
        "window of {}; partners per image {} to {} (median {}); scene depth {:.3g} ({}); {} of "
        "{} images posed; {:.2f} s",
        options_.prior_poses, summary.num_pairs, summary.num_exhaustive_pairs, percent,
        summary.num_overlap_pairs, o.prior_neighbors, o.prior_max_angle_deg, o.prior_min_overlap,
        summary.num_window_pairs, o.prior_window, summary.min_partners, summary.max_partners,
        summary.median_partners, summary.median_scene_depth, summary.scene_depth_source,
        summary.num_images_with_pose, summary.num_images, summary.seconds));
    // Every image's partners, for the log reader who wants to see the choice.
    std::vector<std::vector<std::string>> partners(images.images.size());
    for (const auto& [i, j] : pairs) {
      partners[i].push_back(images.images[j].name);
      partners[j].push_back(images.images[i].name);
    }
    for (size_t i = 0; i < images.images.size(); ++i) {
      std::string list;
      for (const auto& name : partners[i]) list += (list.empty() ? "" : " ") + name;
      spdlog::debug(fmt::format("matches: prior pairs: {} <-> {}", images.images[i].name,
                                list.empty() ? "(none)" : list));
    }
    std::vector<std::string> unpaired;
    for (int i : summary.unpaired_images) unpaired.push_back(images.images[i].name);
    *summary_json = summary.ToJson();
    (*summary_json)["unpaired_images"] = unpaired;
    (*summary_json)["pose_set"] = options_.prior_poses;
    if (!unpaired.empty()) {
      warnings->push_back(
          {"unpaired_images",
           std::to_string(unpaired.size()) +
               " image(s) with a prior pose have no partner under the prior (no other camera "
               "passes the axis-angle, overlap and scale gates): not matched, so not refined; "
               "raise matches.prior_max_angle_deg, lower matches.prior_min_overlap or add "
               "matches.prior_window",
           unpaired,
           {},
           {{"prior_max_angle_deg", o.prior_max_angle_deg},
            {"prior_min_overlap", o.prior_min_overlap},
            {"prior_max_scale_ratio", o.prior_max_scale_ratio}}});
    }
    return pairs;
  }
};

}  // namespace

std::unique_ptr<Stage> CreateMatchesStage() { return std::make_unique<MatchesStage>(); }

}  // namespace raytime
