// The `bootstrap` stage: prior-free poses from the match graph (SPEC §4; paper §4.8 "Refinement
// without an external prior"). Reads images, features and verified matches; writes the pose set
// "bootstrap" (role prior; "bootstrap@NAME" for stage id "bootstrap@NAME"), the per-pair verdicts
// of the wrong-pair detector as JSON and, with `filter_matches`, the matches without the rejected
// pairs for the stages after it. A graph that cannot support its estimate gets the warning
// "weak_bootstrap" (issue 13).
#include <spdlog/spdlog.h>

#include <cmath>
#include <set>

#include "bootstrap/bootstrap.h"
#include "core/hdf5_store.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

struct BootstrapStageOptions {
  BootstrapOptions bootstrap;
  // Also write the verified matches minus the pairs judged wrong as this stage's /matches, so
  // later stages (refine, classical) read the filtered match graph through the "matches"
  // artifact (issue 5: "hand the filtered match graph to refine as an option").
  bool filter_matches = false;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    bootstrap.VisitFields(v);
    v("filter_matches", filter_matches,
      "Write the matches without the wrong pairs for the stages after this one");
  }
  void CheckRelations(const Requirement& require) const { bootstrap.CheckRelations(require); }
};

nlohmann::json Number(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

nlohmann::json PairsJson(const ImageSet& images, const BootstrapResult& result) {
  nlohmann::json pairs = nlohmann::json::array();
  for (size_t k = 0; k < result.edges.size(); ++k) {
    const ViewGraphEdge& e = result.edges[k];
    const PairScore& s = result.pairs.scores[k];
    pairs.push_back({{"image1", images.images[e.image1].name},
                     {"image2", images.images[e.image2].name},
                     {"status", PairStatusName(e.status)},
                     {"num_correspondences", e.num_correspondences},
                     {"num_inliers", e.num_inliers},
                     {"median_parallax_deg", Number(e.median_parallax_deg)},
                     {"fragility_residual_deg", Number(result.fragility_residual_deg[k])},
                     {"rotation_residual_deg", Number(s.rotation_residual_deg)},
                     {"direction_residual_deg", Number(s.direction_residual_deg)},
                     {"cycle_triplets", s.cycle_triplets},
                     {"cycle_consistent", s.cycle_consistent},
                     {"score", Number(s.score)},
                     {"verdict", PairVerdictName(s.verdict)}});
  }
  return pairs;
}

class BootstrapStage : public StageWithOptions<BootstrapStageOptions> {
 public:
  std::string type() const override { return "bootstrap"; }
  std::string description() const override {
    return "Prior-free poses from the match graph: relative poses, rotation and translation "
           "averaging, fragility flag, wrong-pair detection";
  }
  std::vector<std::string> Inputs() const override {
    return {kArtifactImages, "features", "matches"};
  }

  nlohmann::json Run(const StageContext& context) override {
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    const std::string& features_path = context.Require("features");
    const std::string& matches_path = context.Require("matches");
    const std::vector<ImageFeatures> features = Hdf5Reader(features_path).ReadFeatures();
    const std::vector<PairMatches> matches = Hdf5Reader(matches_path).ReadMatches();
    spdlog::info(
        fmt::format("bootstrap: {} images, {} pairs", images.images.size(), matches.size()));

    BootstrapResult result;
    try {
      result = RunBootstrap(images, features, matches, options_.bootstrap);
    } catch (const InputError& e) {
      throw InputError("bootstrap input (features " + features_path + ", matches " + matches_path +
                       "): " + e.what());
    }
    const int usable = result.support.num_usable_pairs;
    const int pure_rotation = result.support.num_pure_rotation_pairs;
    spdlog::info(
        fmt::format("bootstrap: relative poses of {} pairs in {:.2f} s: {} usable ({} near-pure "
                    "rotation)",
                    result.edges.size(), result.relative_pose_seconds, usable, pure_rotation));
    const char* verdict = FragilityVerdict(result);
    spdlog::log(
        result.fragility.fragile || result.support.weak ? spdlog::level::warn : spdlog::level::info,
        fmt::format(
            "bootstrap: fragility {:.2f}° mean pairwise rotation residual ({} pairs) -> {}{}",
            result.fragility.mean_residual_deg, result.fragility.num_pairs, verdict,
            result.support.weak ? ": the view graph cannot support the estimate, " +
                                      DescribeWeakness(result.support)
                                : std::string()));
    spdlog::info(
        fmt::format("bootstrap: wrong-pair detector rejects {} of {} usable pairs ({} rounds)",
                    result.pairs.num_wrong, usable, result.pairs.rounds));
    spdlog::info(fmt::format(
        "bootstrap: {} of {} images have a rotation; positions by {}: {} estimated, {} filled by "
        "the look-at fallback",
        result.num_rotations_registered, images.images.size(), options_.bootstrap.positions,
        result.num_positions_estimated, result.num_positions_filled));
    if (result.num_rotations_registered < static_cast<int>(images.images.size())) {
      spdlog::warn(
          fmt::format("bootstrap: {} images are outside the largest connected pair graph and get "
                      "no pose",
                      images.images.size() - result.num_rotations_registered));
    }

    const PoseSet poses = BootstrapPoses(images, result);
    Hdf5Writer writer(context.output_path);
    writer.WritePoseSet(context.OutputPoseSetName("bootstrap"), poses, PoseRole::kPrior,
                        MakeProvenance(*this));
    writer.WriteJson("bootstrap_pairs", PairsJson(images, result));
    writer.WriteJson("bootstrap_support", {{"weak", result.support.weak},
                                           {"fragile", result.fragility.fragile},
                                           {"fragility_deg", result.fragility.mean_residual_deg},
                                           {"graph_support", GraphSupportJson(result.support)}});
    int written_pairs = 0;
    if (options_.filter_matches) {
      std::set<std::pair<int, int>> wrong;
      for (size_t k = 0; k < result.edges.size(); ++k) {
        if (result.pairs.scores[k].verdict == PairVerdict::kWrong) {
          wrong.insert({result.edges[k].image1, result.edges[k].image2});
        }
      }
      std::vector<PairMatches> kept;
      for (const auto& pair : matches) {
        if (!wrong.count({pair.image1, pair.image2})) kept.push_back(pair);
      }
      written_pairs = static_cast<int>(kept.size());
      writer.WriteMatches(kept, MakeProvenance(*this));
    }
    writer.Commit();

    nlohmann::json summary =
        SummarizeBootstrap(static_cast<int>(images.images.size()), options_.bootstrap, result);
    summary["warnings"] = WarningsToJson(BootstrapWarnings(images, result));
    if (options_.filter_matches) summary["num_matches_pairs_written"] = written_pairs;
    return summary;
  }
};

}  // namespace

std::unique_ptr<Stage> CreateBootstrapStage() { return std::make_unique<BootstrapStage>(); }

}  // namespace raytime
