// The `prior` stage: the pose prior the refiner starts from. Either the dataset's ground truth
// perturbed by the paper's protocol (§4.8 "Basin of convergence"), the capture app's own poses
// that came with the dataset (ARKit/ARCore: pose set "capture"), a pose file (a COLMAP model, a
// capture app's files, ...), or the ground truth itself; or the prior-free bootstrap's poses,
// which can also repair a given coarse prior (§4.8 "Basin of convergence").
#include <spdlog/spdlog.h>

#include <filesystem>

#include "bootstrap/prior_repair.h"
#include "core/formats/dataset.h"
#include "core/hdf5_store.h"
#include "core/warnings.h"
#include "evaluate/perturbation.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

struct PriorOptions {
  // "perturb": ground truth perturbed with the options below; "capture": the poses the capture
  // app recorded, read with the dataset (pose set "capture"); "file": read `path` in `format`;
  // "ground_truth": the ground truth unchanged (a 0° control that skips the perturbation);
  // "bootstrap": the pose set "bootstrap" of the bootstrap stage (prior-free, SPEC §4).
  std::string source = "perturb";
  std::string format = "colmap";  // for source "file": one of kPoseFileFormats
  std::string path;               // for source "file"
  PerturbationOptions perturbation;
  // Repair of the prior above with the bootstrap's poses (paper §4.8): "none"; "rotations"
  // (averaged rotations in the prior's frame, prior centres kept: recovers 32° priors);
  // "replace" (bootstrap poses Sim(3)-fitted onto the prior centres: recovers 64° priors).
  std::string repair = "none";
  // Images without a prior pose, and prior poses without an image, are reported and left out
  // (warnings missing_prior, missing_frames); strict makes either an error.
  bool strict = false;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("source", source,
      "Prior: ground truth perturbed (below), the capture app's poses that came with the dataset, "
      "a pose file, the ground truth, or the bootstrap's poses",
      OneOf({"perturb", "capture", "file", "ground_truth", "bootstrap"}));
    v("format", format, "Pose file format for source 'file'", OneOf(kPoseFileFormats));
    v("path", path, "Pose file or folder for source 'file'");
    v("repair", repair,
      "Repair the prior with the bootstrap: averaged rotations, or all poses (§4.8)",
      OneOf({"none", "rotations", "replace"}));
    v("strict", strict,
      "Refuse a prior that lacks some images or has poses of images not in the dataset");
    perturbation.VisitFields(v);  // flat keys: prior.level_deg, prior.seed, ...
  }
  void CheckRelations(const Requirement& require) const {
    require(source != "file" || !path.empty(), "prior.source is 'file' but prior.path is not set");
    require(source != "bootstrap" || repair == "none",
            "prior.repair '" + repair +
                "' repairs a given prior with the bootstrap; with prior.source 'bootstrap' there "
                "is nothing to repair");
  }
};

// The dataset formats that bring the capture app's poses (pose set "capture").
const char* kFormatsWithCapturePoses =
    "record3d, polycam, stray, scanner3d, nerfcapture, scannetpp_iphone, lamar, and "
    "mobilebrick with PoRF's cameras_arkit.npz";

class PriorStage : public StageWithOptions<PriorOptions> {
 public:
  // Where the prior's poses came from, for messages.
  std::string SourceName() const {
    if (options_.source == "file") return options_.path;
    if (options_.source == "capture") return "the capture's poses";
    return options_.source;
  }
  // Poses of images the dataset does not have (a capture app's poses for frames that were not
  // extracted, say) are dropped: missing_frames, or an error when strict.
  void DropPosesWithoutImages(const ImageSet& images, PoseSet* prior, Warnings* warnings) const {
    const NameJoin join = JoinNames(Names(*prior), Names(images));
    if (join.only_left.empty()) return;
    if (options_.strict) {
      const std::string message = "pose names do not match the dataset's images (prior.strict): " +
                                  join.Describe(SourceName(), "the dataset");
      if (options_.source == "file") ThrowInput(options_.path, 0, message);
      throw InputError("prior: " + message);
    }
    for (const auto& name : join.only_left) prior->world_from_cam.erase(name);
    warnings->push_back({"missing_frames",
                         std::to_string(join.only_left.size()) + " pose(s) in " + SourceName() +
                             " name no image of the dataset and are left out",
                         join.only_left,
                         {},
                         {}});
  }
  // Images without a prior pose are not refined: missing_prior, or an error when strict.
  void ReportImagesWithoutPose(const ImageSet& images, const PoseSet& prior,
                               Warnings* warnings) const {
    const NameJoin join = JoinNames(Names(prior), Names(images));
    if (join.only_right.empty()) return;
    const std::string message =
        std::to_string(join.only_right.size()) + " of " + std::to_string(images.images.size()) +
        " images have no prior pose (source " + options_.source + ") and will not be refined";
    if (options_.strict) throw InputError("prior (strict): " + message);
    warnings->push_back({"missing_prior", message, join.only_right, {}, {}});
  }

  std::string type() const override { return "prior"; }
  std::string description() const override {
    return "Make the pose prior: perturbed ground truth, the capture's poses, a pose file, or the "
           "ground truth";
  }
  std::vector<std::string> Inputs() const override {
    std::vector<std::string> inputs = {kArtifactImages};
    if (options_.source == "perturb" || options_.source == "ground_truth") {
      inputs.push_back(PoseArtifact("ground_truth"));
    }
    if (options_.source == "capture") inputs.push_back(PoseArtifact("capture"));
    if (options_.source == "bootstrap" || options_.repair != "none") {
      inputs.push_back(PoseArtifact("bootstrap"));
    }
    return inputs;
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
    Warnings warnings;
    nlohmann::json summary = {{"source", options_.source}};
    if (options_.source == "file") {
      prior = ReadPoseFile(options_.format, options_.path, &images);
      DropPosesWithoutImages(images, &prior, &warnings);
    } else if (options_.source == "capture") {
      if (!context.artifacts.count(PoseArtifact("capture"))) {
        throw InputError(
            "prior.source 'capture': this dataset has no capture poses (the dataset formats "
            "that bring the capture app's poses are " +
            std::string(kFormatsWithCapturePoses) +
            "); use prior.source 'file' with the poses' file, or 'perturb' on ground truth");
      }
      prior = Hdf5Reader(context.Require(PoseArtifact("capture"))).ReadPoseSet("capture");
      DropPosesWithoutImages(images, &prior, &warnings);
    } else if (options_.source == "bootstrap") {
      prior = Hdf5Reader(context.Require(PoseArtifact("bootstrap"))).ReadPoseSet("bootstrap");
    } else {
      if (!context.artifacts.count(PoseArtifact("ground_truth"))) {
        throw InputError("prior.source '" + options_.source + "': " + options_.source +
                         " needs ground truth; this dataset has none — use source: capture "
                         "(the capture app's poses, formats " +
                         kFormatsWithCapturePoses + ") or file");
      }
      const PoseSet ground_truth =
          Hdf5Reader(context.Require(PoseArtifact("ground_truth"))).ReadPoseSet("ground_truth");
      if (options_.source == "ground_truth") {
        prior = ground_truth;
      } else {
        PerturbationSummary perturbation;
        prior = PerturbPoses(ground_truth, options_.perturbation, &perturbation);
        summary["translation_m"] = perturbation.translation_m;
        summary["scene_distance_m"] = perturbation.scene_distance_m;
        spdlog::info(fmt::format("prior: {} perturbation at {}° / {:.4f} m (seed {})",
                                 options_.perturbation.mode, options_.perturbation.level_deg,
                                 perturbation.translation_m, options_.perturbation.seed));
      }
    }
    if (options_.repair != "none") {
      const PoseSet bootstrap =
          Hdf5Reader(context.Require(PoseArtifact("bootstrap"))).ReadPoseSet("bootstrap");
      PriorRepairSummary repair;
      try {
        prior = options_.repair == "rotations" ? RepairRotations(prior, bootstrap, &repair)
                                               : ReplaceWithBootstrap(prior, bootstrap, &repair);
      } catch (const std::invalid_argument& e) {
        throw InputError(std::string("prior.repair '") + options_.repair + "': " + e.what());
      }
      summary["repair"] = {{"mode", repair.mode},
                           {"num_repaired", repair.num_repaired},
                           {"num_kept_prior", repair.num_kept_prior},
                           {"scale", repair.scale},
                           {"median_rotation_change_deg", repair.median_rotation_change_deg}};
      spdlog::info(
          fmt::format("prior: {} repair from the bootstrap: {} poses repaired, {} kept, median "
                      "rotation change {:.2f}°",
                      repair.mode, repair.num_repaired, repair.num_kept_prior,
                      repair.median_rotation_change_deg));
    }
    ReportImagesWithoutPose(images, prior, &warnings);
    Hdf5Writer writer(context.output_path);
    writer.WritePoseSet(context.OutputPoseSetName("prior"), prior, PoseRole::kPrior,
                        MakeProvenance(*this));
    writer.Commit();
    summary["num_poses"] = prior.size();
    summary["warnings"] = WarningsToJson(warnings);
    return summary;
  }
};

}  // namespace

std::unique_ptr<Stage> CreatePriorStage() { return std::make_unique<PriorStage>(); }

}  // namespace raytime
