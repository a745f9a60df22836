// The `evaluate` stage: errors of pose sets against the dataset's ground truth under each
// requested alignment (SPEC §6). Its summary becomes the run's metrics. Without ground truth it
// scores nothing and says so ("scored": false). A phone capture has no ground truth: with
// `reference` set to another pose set (e.g. classical@mapper) the same numbers measure how far
// two estimates agree, which is how solutions of a real capture are compared.
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
  std::string reference = "ground_truth";                  // the pose set scored against

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("poses", poses, "Pose sets to score against the reference (e.g. prior, refined@gnc)",
      NonEmpty());
    v("alignments", alignments,
      "Alignments: Sim(3) on centres (standard), SE(3), none (the prior's frame, §4.9)",
      OneOf({"sim3", "se3", "none"}));
    v("success_rotation_deg", success_rotation_deg,
      "Success: mean rotation error below this, degrees (§4.8: 1°)", Positive(), AtMost(180));
    v("reference", reference,
      "Pose set scored against: ground_truth, or another estimate (e.g. classical@mapper) to "
      "measure agreement on a capture without ground truth",
      NonEmpty());
  }
};

class EvaluateStage : public StageWithOptions<EvaluateStageOptions> {
 public:
  std::string type() const override { return "evaluate"; }
  // Scores are for people measuring; a scene they cannot be computed for (two images: no Sim(3))
  // must not keep the refined poses from being exported.
  bool FailureStopsRun() const override { return false; }
  std::string description() const override {
    return "Score pose sets against the ground truth or a reference pose set (Sim(3), SE(3), "
           "absolute frame)";
  }
  std::vector<std::string> Inputs() const override {
    std::vector<std::string> inputs = {PoseArtifact(options_.reference)};
    for (const auto& name : options_.poses) inputs.push_back(PoseArtifact(name));
    return inputs;
  }

  nlohmann::json Run(const StageContext& context) override {
    nlohmann::json metrics = nlohmann::json::object();
    // Ground truth is optional everywhere (a phone capture has none): then nothing is scored,
    // and the summary and the log say so. Any other reference must exist (Require names it).
    const bool against_truth = options_.reference == "ground_truth";
    if (against_truth && !context.artifacts.count(PoseArtifact("ground_truth"))) {
      spdlog::info("evaluate: the dataset has no ground truth; nothing scored");
      Hdf5Writer writer(context.output_path);
      writer.WriteJson("metrics", metrics);
      writer.Commit();
      return {
          {"metrics", metrics}, {"scored", false}, {"reason", "the dataset has no ground truth"}};
    }
    const PoseSet reference = Hdf5Reader(context.Require(PoseArtifact(options_.reference)))
                                  .ReadPoseSet(options_.reference);
    for (const auto& name : options_.poses) {
      const PoseSet estimate = Hdf5Reader(context.Require(PoseArtifact(name))).ReadPoseSet(name);
      for (const auto& alignment : options_.alignments) {
        PoseErrorOptions error_options;
        error_options.alignment = alignment;
        error_options.success_rotation_deg = options_.success_rotation_deg;
        const PoseErrorSummary errors = ComputePoseErrors(estimate, reference, error_options);
        spdlog::info(
            fmt::format("evaluate: {}{} ({}): rotation mean {:.4f}°{} median {:.4f}°, centre mean "
                        "{:.4f} m median {:.4f} m, relative rotation median {:.4f}°{}",
                        name, against_truth ? "" : " vs " + options_.reference, alignment,
                        errors.mean_rotation_deg,
                        alignment == "none" ? std::string()
                                            : fmt::format(" (fit's own rotation ±{:.4f}°)",
                                                          errors.alignment_rotation_sigma_deg),
                        errors.median_rotation_deg, errors.mean_centre_m, errors.median_centre_m,
                        errors.median_relative_rotation_deg,
                        errors.only_in_estimate.empty() && errors.only_in_ground_truth.empty()
                            ? ""
                            : " (some names did not join: see summary)"));
        metrics[name][alignment] = errors.ToJson();
      }
    }
    Hdf5Writer writer(context.output_path);
    writer.WriteJson("metrics", metrics);
    writer.Commit();
    // Agreement with another estimate is not an error: it goes to the run's `agreement` section
    // (one entry per reference), so sweeps and campaign reports, which read `metrics` as errors
    // against the ground truth, never mix the two.
    if (!against_truth) {
      return {{"agreement", {{options_.reference, metrics}}},
              {"scored", true},
              {"reference", options_.reference}};
    }
    return {{"metrics", metrics}, {"scored", true}, {"reference", options_.reference}};
  }
};

}  // namespace

std::unique_ptr<Stage> CreateEvaluateStage() { return std::make_unique<EvaluateStage>(); }

}  // namespace raytime
