// The `matches` stage: pairwise descriptor matching, geometric verification and guided matching
// (SPEC §5, paper §4.1). Reads the image list and the features, writes the verified pairs. With
// `pairs: prior` it also reads a pose set (the prior stage's) and matches only the pairs that pose
// set says overlap (pipelines/pair_selection.h): the poses choose the pairs here, in pipelines/,
// and the front end matches and verifies them without ever seeing a pose.
#include <spdlog/spdlog.h>

#include <chrono>
#include <map>

#include "core/content_hash.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/timing.h"
#include "core/warnings.h"
#include "frontend/matching.h"
#include "pipelines/pair_selection.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

constexpr const char* kArtifactFeatures = "features";
// JSON document beside the matches: per candidate pair matched, [content key, row in /matches or
// -1 when dropped, putative matches, first-pass inliers], so the next run reuses it pair by pair.
constexpr const char* kPairKeysJson = "pair_keys";

// A candidate pair's result from the previous run in this work directory.
struct PreviousPair {
  int row = -1;  // in `pairs`; -1: matched and dropped
  CandidatePairOutcome outcome;
};
struct PreviousMatches {
  std::map<std::string, PreviousPair> by_key;
  std::vector<PairMatches> pairs;
};

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
    const auto start = std::chrono::steady_clock::now();
    std::vector<PairMatches> pairs;
    std::vector<nlohmann::json> pair_keys;
    int num_matched = 0;
    const MatchingSummary summary =
        MatchOrReuse(context, images, features, candidates, &pairs, &pair_keys, &num_matched);
    const int num_reused = summary.num_pairs - num_matched;
    spdlog::info(fmt::format(
        "matches: {} of {} pairs verified ({} dropped below {} inliers; {} matched, {} reused), "
        "{} inliers, {:.2f} s",
        summary.num_verified_pairs, summary.num_pairs, summary.num_dropped_pairs,
        options_.matching.min_num_inliers, num_matched, num_reused, summary.num_inliers,
        SecondsSince(start)));
    Hdf5Writer writer(context.output_path);
    writer.WriteMatches(pairs, MakeProvenance(*this));
    writer.WriteJson(kPairKeysJson, pair_keys);
    writer.Commit();
    nlohmann::json out = summary.ToJson();
    out["num_pairs_matched"] = num_matched;
    out["num_pairs_reused"] = num_reused;
    out["seconds"] = SecondsSince(start);
    if (PriorPairs()) out["pair_selection"] = selection_json;
    out["warnings"] = WarningsToJson(warnings);
    return out;
  }

 private:
  // The candidates' verified pairs: those whose content key the previous run's output holds are
  // taken from it, the others matched (issue 34: a capture that grows matches only the pairs
  // that involve its new frames). `pair_keys` receives every candidate's entry of kPairKeysJson;
  // the summary counts every candidate, its thread times only the pairs matched now.
  MatchingSummary MatchOrReuse(const StageContext& context, const ImageSet& images,
                               const std::vector<ImageFeatures>& features,
                               const std::vector<std::pair<int, int>>& candidates,
                               std::vector<PairMatches>* pairs,
                               std::vector<nlohmann::json>* pair_keys, int* num_matched) const {
    std::vector<std::string> image_keys(images.images.size());
    for (size_t i = 0; i < images.images.size(); ++i) {
      image_keys[i] = ImageKey(features.at(i), images.cameras.at(images.images[i].camera_index));
    }
    MatchingOptions matching = options_.matching;
    nlohmann::json result_options = OptionsToJson(matching);
    // Which pairs are chosen does not change a pair's result.
    for (const char* choice : {"pairs", "window", "loop_stride"}) result_options.erase(choice);
    const std::string options_key = result_options.dump();
    std::vector<std::string> keys;
    for (const auto& [i, j] : candidates) {
      keys.push_back(HashBytes(nlohmann::json{
          {"executable", ExecutableHash()},
          {"options", options_key},
          {"image1", image_keys[i]},
          {"image2",
           image_keys[j]}}.dump()));
    }
    const PreviousMatches previous = ReadPrevious(context);
    std::vector<std::pair<int, int>> to_match;
    for (size_t p = 0; p < candidates.size(); ++p) {
      if (previous.by_key.count(keys[p]) == 0) to_match.push_back(candidates[p]);
    }
    *num_matched = static_cast<int>(to_match.size());
    if (to_match.size() < candidates.size()) {
      spdlog::info(fmt::format(
          "matches: {} of {} pairs unchanged since the previous run here (same features, cameras "
          "and options), their results reused; matching {}",
          candidates.size() - to_match.size(), candidates.size(), to_match.size()));
    }
    std::vector<PairMatches> matched;
    std::vector<CandidatePairOutcome> outcomes;
    MatchingSummary summary;
    if (!to_match.empty()) {
      summary = MatchImagePairs(images, features, options_.matching, to_match, &matched, &outcomes);
    }
    // Candidates in order, from the previous run or from this one; kept pairs stay sorted.
    summary.num_images = static_cast<int>(images.images.size());
    summary.num_pairs = static_cast<int>(candidates.size());
    summary.num_putative = summary.num_inliers = summary.num_inliers_first_pass = 0;
    pairs->clear();
    pair_keys->clear();
    size_t next_matched = 0, next_outcome = 0;
    for (size_t p = 0; p < candidates.size(); ++p) {
      const auto found = previous.by_key.find(keys[p]);
      CandidatePairOutcome outcome;
      if (found != previous.by_key.end()) {
        outcome = found->second.outcome;
        if (outcome.kept) {
          PairMatches pair = previous.pairs.at(found->second.row);
          pair.image1 = candidates[p].first;
          pair.image2 = candidates[p].second;
          pairs->push_back(std::move(pair));
        }
      } else {
        outcome = outcomes.at(next_outcome++);
        if (outcome.kept) pairs->push_back(std::move(matched.at(next_matched++)));
      }
      summary.num_putative += outcome.num_putative;
      summary.num_inliers_first_pass += outcome.kept ? outcome.num_inliers_first_pass : 0;
      if (outcome.kept) summary.num_inliers += pairs->back().geometry.inlier_matches.rows();
      pair_keys->push_back({keys[p], outcome.kept ? static_cast<int>(pairs->size()) - 1 : -1,
                            outcome.num_putative, outcome.num_inliers_first_pass});
    }
    summary.num_verified_pairs = static_cast<int>(pairs->size());
    summary.num_dropped_pairs = summary.num_pairs - summary.num_verified_pairs;
    return summary;
  }

  // What a pair's result depends on besides the options, per image: its keypoints, descriptors
  // and camera.
  static std::string ImageKey(const ImageFeatures& f, const CameraIntrinsics& camera) {
    std::string bytes(reinterpret_cast<const char*>(f.keypoints.data()),
                      f.keypoints.size() * sizeof(float));
    bytes.append(reinterpret_cast<const char*>(f.descriptors.data()), f.descriptors.size());
    const nlohmann::json rest = {f.keypoints.rows(), f.descriptors.cols(), camera.width,
                                 camera.height, camera.params};
    return HashBytes(HashBytes(bytes) + rest.dump());
  }

  // The previous run's pair results by key; none when there is no previous output, it predates
  // the keys, or it does not read (then every pair is matched, and the log says why).
  static PreviousMatches ReadPrevious(const StageContext& context) {
    PreviousMatches previous;
    const bool read = context.ReadPreviousOutput(
        [&](const Hdf5Reader& reader) {
          if (!reader.HasJson(kPairKeysJson) || !reader.HasMatches()) return;
          previous.pairs = reader.ReadMatches();
          for (const nlohmann::json& entry : reader.ReadJson(kPairKeysJson)) {
            PreviousPair pair;
            pair.row = entry.at(1).get<int>();
            if (pair.row >= static_cast<int>(previous.pairs.size())) {
              throw InputError("pair row " + std::to_string(pair.row) + " of " +
                               std::to_string(previous.pairs.size()));
            }
            pair.outcome = {pair.row >= 0, entry.at(2).get<int64_t>(), entry.at(3).get<int64_t>()};
            previous.by_key[entry.at(0).get<std::string>()] = pair;
          }
        },
        "matching every pair");
    return read ? previous : PreviousMatches();
  }

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
