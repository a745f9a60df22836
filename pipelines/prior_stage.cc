// The `prior` stage: the pose prior the refiner starts from. Either the dataset's ground truth
// perturbed by the paper's protocol (§4.8 "Basin of convergence"), a pose file (a phone capture's
// ARKit/ARCore poses, a COLMAP model, ...), or the ground truth itself.
#include <spdlog/spdlog.h>

#include <filesystem>

#include "core/formats/dataset.h"
#include "core/hdf5_store.h"
#include "evaluate/perturbation.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

struct PriorOptions {
  // "perturb": ground truth perturbed with the options below; "file": read `path` in `format`;
  // "ground_truth": the ground truth unchanged (a 0° control that skips the perturbation).
  std::string source = "perturb";
  std::string format = "colmap";  // for source "file": colmap, nerfstudio, tum, strecha
  std::string path;               // for source "file"
  PerturbationOptions perturbation;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("source", source);
    v("format", format);
    v("path", path);
    perturbation.VisitFields(v);  // flat keys: prior.level_deg, prior.seed, ...
  }
};

class PriorStage : public StageWithOptions<PriorOptions> {
 public:
  std::string type() const override { return "prior"; }
  std::string description() const override {
    return "Make the pose prior: perturbed ground truth, a pose file, or the ground truth";
  }
  void Validate() override {
    const auto& o = options_;
    if (o.source != "perturb" && o.source != "file" && o.source != "ground_truth") {
      throw InputError(UnknownKeyMessage("prior.source", o.source,
                                         {"perturb", "file", "ground_truth"}, "source"));
    }
    if (o.source == "file" && o.path.empty()) {
      throw InputError("prior.source is 'file' but prior.path is not set");
    }
  }
  std::vector<std::string> Inputs() const override {
    if (options_.source == "file") return {kArtifactImages};
    return {kArtifactImages, PoseArtifact("ground_truth")};
  }
  std::vector<std::string> ExternalFiles() const override {
    if (options_.source != "file") return {};
    std::vector<std::string> files;
    if (std::filesystem::is_directory(options_.path)) {
      for (const auto& e : std::filesystem::recursive_directory_iterator(options_.path)) {
        if (e.is_regular_file()) files.push_back(e.path().string());
      }
      std::sort(files.begin(), files.end());
    } else {
      files.push_back(options_.path);
    }
    return files;
  }

  nlohmann::json Run(const StageContext& context) override {
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    PoseSet prior;
    nlohmann::json summary = {{"source", options_.source}};
    if (options_.source == "file") {
      prior = ReadPoseFile(options_.format, options_.path, &images);
    } else {
      const PoseSet ground_truth =
          Hdf5Reader(context.Require(PoseArtifact("ground_truth"))).ReadPoseSet("ground_truth");
      if (options_.source == "ground_truth") {
        prior = ground_truth;
      } else {
        PerturbationSummary perturbation;
        prior = PerturbPoses(ground_truth, options_.perturbation, &perturbation);
        summary["translation_m"] = perturbation.translation_m;
        summary["scene_distance_m"] = perturbation.scene_distance_m;
        spdlog::info("prior: {} perturbation at {}° / {:.4f} m (seed {})",
                     options_.perturbation.mode, options_.perturbation.level_deg,
                     perturbation.translation_m, options_.perturbation.seed);
      }
    }
    Hdf5Writer writer(context.output_path);
    writer.WritePoseSet(context.OutputPoseSetName("prior"), prior, PoseRole::kPrior,
                        MakeProvenance(*this));
    writer.Commit();
    summary["num_poses"] = prior.size();
    return summary;
  }
};

}  // namespace

std::unique_ptr<Stage> CreatePriorStage() { return std::make_unique<PriorStage>(); }

}  // namespace raytime
