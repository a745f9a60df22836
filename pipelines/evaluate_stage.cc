// The `evaluate` stage: errors of pose sets against the dataset's ground truth under each
// requested alignment (SPEC §6). Its summary becomes the run's metrics. Without ground truth it
// scores nothing and says so ("scored": false).
#include <spdlog/spdlog.h>

#include "core/hdf5_store.h"
#include "evaluate/pose_errors.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

struct EvaluateStageOptions {
  std::vector<std::string> poses = {"prior"};              // pose sets to score
  std::vector<std::string> alignments = {"sim3", "none"};  // sim3, se3, none
  double success_rotation_deg = 1.0;                       // degrees (paper §4.8)

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("poses", poses, "Pose sets to score against the ground truth (e.g. prior, refined@gnc)",
      NonEmpty());
    v("alignments", alignments,
      "Alignments: Sim(3) on centres (standard), SE(3), none (the prior's frame, §4.9)",
      OneOf({"sim3", "se3", "none"}));
    v("success_rotation_deg", success_rotation_deg,
      "Success: mean rotation error below this, degrees (§4.8: 1°)", Positive());
  }
};

class EvaluateStage : public StageWithOptions<EvaluateStageOptions> {
 public:
  std::string type() const override { return "evaluate"; }
  std::string description() const override {
    return "Score pose sets against the ground truth (Sim(3), SE(3), absolute frame)";
  }
  std::vector<std::string> Inputs() const override {
    std::vector<std::string> inputs = {PoseArtifact("ground_truth")};
    for (const auto& name : options_.poses) inputs.push_back(PoseArtifact(name));
    return inputs;
  }

  nlohmann::json Run(const StageContext& context) override {
    nlohmann::json metrics = nlohmann::json::object();
    // Ground truth is optional everywhere (a phone capture has none): then nothing is scored,
    // and the summary and the log say so.
    if (!context.artifacts.count(PoseArtifact("ground_truth"))) {
      spdlog::info("evaluate: the dataset has no ground truth; nothing scored");
      Hdf5Writer writer(context.output_path);
      writer.WriteJson("metrics", metrics);
      writer.Commit();
      return {
          {"metrics", metrics}, {"scored", false}, {"reason", "the dataset has no ground truth"}};
    }
    const PoseSet ground_truth =
        Hdf5Reader(context.Require(PoseArtifact("ground_truth"))).ReadPoseSet("ground_truth");
    for (const auto& name : options_.poses) {
      const PoseSet estimate = Hdf5Reader(context.Require(PoseArtifact(name))).ReadPoseSet(name);
      for (const auto& alignment : options_.alignments) {
        PoseErrorOptions error_options;
        error_options.alignment = alignment;
        error_options.success_rotation_deg = options_.success_rotation_deg;
        const PoseErrorSummary errors = ComputePoseErrors(estimate, ground_truth, error_options);
        spdlog::info(
            "evaluate: {} ({}): rotation mean {:.4f}° median {:.4f}°, centre mean "
            "{:.4f} m median {:.4f} m, relative rotation median {:.4f}°{}",
            name, alignment, errors.mean_rotation_deg, errors.median_rotation_deg,
            errors.mean_centre_m, errors.median_centre_m, errors.median_relative_rotation_deg,
            errors.only_in_estimate.empty() && errors.only_in_ground_truth.empty()
                ? ""
                : " (some names did not join: see summary)");
        metrics[name][alignment] = errors.ToJson();
      }
    }
    Hdf5Writer writer(context.output_path);
    writer.WriteJson("metrics", metrics);
    writer.Commit();
    return {{"metrics", metrics}, {"scored", true}};
  }
};

}  // namespace

std::unique_ptr<Stage> CreateEvaluateStage() { return std::make_unique<EvaluateStage>(); }

}  // namespace raytime
