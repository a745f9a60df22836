// The `prior` stage: the pose prior the refiner starts from. Either the dataset's ground truth
// perturbed by the paper's protocol (§4.8 "Basin of convergence"), the capture app's own poses
// that came with the dataset (ARKit/ARCore: pose set "capture"), a pose file (a COLMAP model, a
// capture app's files, ...), or the ground truth itself; or the prior-free bootstrap's poses,
// which can also repair a given coarse prior (§4.8 "Basin of convergence").
#include <spdlog/spdlog.h>

#include <filesystem>

#include "bootstrap/prior_repair.h"
#include "core/geometry.h"
#include "core/hdf5_store.h"
#include "core/warnings.h"
#include "evaluate/perturbation.h"
#include "formats/dataset.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

struct PriorOptions {
  // "perturb": ground truth perturbed with the options below; "capture": the poses the capture
  // app recorded, read with the dataset (pose set "capture"); "file": read `path` in `format`;
  // "ground_truth": the ground truth unchanged (a 0° control that skips the perturbation);
  // "bootstrap": the pose set "bootstrap" of the bootstrap stage (prior-free, SPEC §4);
  // "pose_set": the pose set `pose_set` of an earlier stage (e.g. "prior"), to be repaired.
  std::string source = "perturb";
  std::string format = "colmap";  // for source "file": one of kPoseFileFormats
  std::string path;               // for source "file"
  std::string pose_set;           // for source "pose_set"
  // A repair of poses given in another convention (core/geometry.h PoseConvention), applied to
  // each pose as read: the refine stage's convention check names the value that fits the matches.
  std::string convention = "native";
  PerturbationOptions perturbation;
  // Repair of the prior above with the bootstrap's poses (paper §4.8): "none"; "rotations"
  // (averaged rotations in the prior's frame, prior centres kept: recovers 32° priors);
  // "replace" (bootstrap poses Sim(3)-fitted onto the prior centres: recovers 64° priors);
  // "auto" (RepairIfCoarse: a prior whose rotations are further than
  // repair_min_rotation_change_deg from the averaged ones is replaced, or gets the averaged
  // rotations when the graph does not support the bootstrap's positions; otherwise unchanged).
  std::string repair = "none";
  // Above the width the basin solve recovers alone: the ladder of preset auto succeeds 12/12 at
  // 16° and 8/12 at 32°; a median change of 13.5–16.9° at 16° and 27–34° at 32° (one level's
  // perturbation about random axes). Repairing at 8–16° costs castle-P19 accuracy (its fragile
  // graph's averaged rotations: 0.14–0.16° instead of 0.04–0.07°); at 32° replacement takes the
  // ladder to 12/12 (2026-11-26, issue 12).
  double repair_min_rotation_change_deg = 20.0;
  // Images without a prior pose, and prior poses without an image, are reported and left out
  // (warnings missing_prior, missing_frames); strict makes either an error.
  bool strict = false;
  // The prior's accuracy per frame as its maker knows it (a survey, a phone's tracking quality):
  // the refine stage trusts a prior stated so to place the frames its matches do not hold, when
  // they agree with it within 3 sigma (refine/checks/frame_verdicts.h). 0 = not stated.
  double sigma_deg = 0.0;
  double sigma_m = 0.0;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("source", source,
      "Prior: ground truth perturbed (below), the capture app's poses that came with the dataset, "
      "a pose file, the ground truth, the bootstrap's poses, or an earlier stage's pose set",
      OneOf({"perturb", "capture", "file", "ground_truth", "bootstrap", "pose_set"}));
    v("format", format, "Pose file format for source 'file'", OneOf(kPoseFileFormats));
    v("path", path, "Pose file or folder for source 'file'");
    v("pose_set", pose_set,
      "Pose set of an earlier stage for source 'pose_set' (e.g. prior, to repair it)");
    v("convention", convention,
      "Pose convention of the source's poses: native (the format's own), or applied to each pose "
      "as read: inverted (camera-to-world <-> world-to-camera), flipped_axes (OpenGL <-> OpenCV "
      "camera axes), inverted_flipped_axes (both)",
      OneOf(PoseConventionNames()));
    v("repair", repair,
      "Repair the prior with the bootstrap: averaged rotations, all poses, or the rotations "
      "when the prior's are far from them (§4.8)",
      OneOf({"none", "rotations", "replace", "auto"}));
    v("repair_min_rotation_change_deg", repair_min_rotation_change_deg,
      "Repair 'auto' repairs when the prior's rotations are further than this from the averaged "
      "ones (median over images), degrees",
      Positive(), AtMost(180));
    v("strict", strict,
      "Refuse a prior that lacks some images or has poses of images not in the dataset");
    v("sigma_deg", sigma_deg,
      "Stated accuracy of the prior's rotations per frame, degrees: trusted to place frames the "
      "matches do not hold (0 = not stated)",
      NonNegative(), AtMost(180));
    v("sigma_m", sigma_m,
      "Stated accuracy of the prior's centres per frame, in its length unit: trusted to place "
      "frames the matches do not hold (0 = not stated)",
      NonNegative(), AtMost(1e9));
    perturbation.VisitFields(v);  // flat keys: prior.level_deg, prior.seed, ...
  }
  void CheckRelations(const Requirement& require) const {
    perturbation.CheckRelations(require);
    require(source != "file" || !path.empty(), "prior.source is 'file' but prior.path is not set");
    require(source != "pose_set" || !pose_set.empty(),
            "prior.source is 'pose_set' but prior.pose_set is not set");
    require(source != "bootstrap" || convention == "native",
            "prior.convention '" + convention +
                "' repairs poses read in another convention; the bootstrap's poses are raytime's "
                "own (prior.source 'bootstrap')");
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

// Whether the bootstrap stage found its view graph unable to support its positions (its
// `/json/bootstrap_support`, docs/hdf5_schema.md).
bool BootstrapIsWeak(const Hdf5Reader& reader) {
  if (!reader.HasJson("bootstrap_support")) {
    throw InputError(
        "prior.repair 'auto': the bootstrap's file has no /json/bootstrap_support (written by "
        "raytime since 2026-11-26); run the bootstrap stage again");
  }
  const nlohmann::json support = reader.ReadJson("bootstrap_support");
  if (!support.is_object() || !support.contains("weak") || !support["weak"].is_boolean()) {
    throw InputError(reader.path() +
                     ": /json/bootstrap_support has no boolean 'weak'; run the bootstrap stage "
                     "again");
  }
  return support["weak"].get<bool>();
}

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

  // A pose that is not finite (a file with nan or inf, or a perturbation beyond floating point)
  // is refused with its name: a solve started from it returns NaN poses.
  void RefuseNonFinite(const PoseSet& prior) const {
    for (const auto& [name, pose] : prior.world_from_cam) {
      if (pose.rotation.coeffs().allFinite() && pose.translation.allFinite()) continue;
      const std::string message = "the prior pose of " + name + " (from " + SourceName() +
                                  ") is not finite; every pose must be finite numbers";
      if (options_.source == "file") ThrowInput(options_.path, 0, message);
      throw InputError("prior: " + message);
    }
  }

  // `poses` read in options_.convention.
  PoseSet WithConvention(PoseSet poses) const {
    const PoseConvention convention = ParsePoseConvention(options_.convention);
    for (auto& [name, pose] : poses.world_from_cam) pose = ApplyPoseConvention(pose, convention);
    return poses;
  }

  std::string type() const override { return "prior"; }
  std::string description() const override {
    return "Make the pose prior: perturbed ground truth, the capture's poses, a pose file, the "
           "ground truth or the bootstrap's poses; repair a coarse prior from the bootstrap";
  }
  std::vector<std::string> Inputs() const override {
    std::vector<std::string> inputs = {kArtifactImages};
    if (options_.source == "perturb" || options_.source == "ground_truth") {
      inputs.push_back(PoseArtifact("ground_truth"));
    }
    if (options_.source == "capture") inputs.push_back(PoseArtifact("capture"));
    if (options_.source == "pose_set") inputs.push_back(PoseArtifact(options_.pose_set));
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
    Warnings warnings;
    nlohmann::json summary = {{"source", options_.source}};
    // 1. The poses of the chosen source, in the convention they were read with.
    PoseSet prior = SourcePoses(context, images, &summary, &warnings);
    if (options_.source == "file" || options_.source == "capture" ||
        options_.source == "pose_set") {
      prior = WithConvention(prior);
    }
    if (options_.convention != "native") {
      summary["convention"] = options_.convention;
      spdlog::info(fmt::format("prior: poses read with convention {}", options_.convention));
    }
    // 2. The repair from the bootstrap's poses, if asked for.
    if (options_.repair != "none") Repair(context, &prior, &summary);
    // 3. Checked and written, with what the refine stage reads beside it.
    ReportImagesWithoutPose(images, prior, &warnings);
    RefuseNonFinite(prior);
    Hdf5Writer writer(context.output_path);
    writer.WritePoseSet(context.OutputPoseSetName("prior"), prior, PoseRole::kPrior,
                        MakeProvenance(*this));
    // What the repair did, for the refine stage: rotations taken from the match graph must not be
    // held by the orientation prior (they add nothing but their own errors).
    if (summary.contains("repair")) {
      nlohmann::json record = summary["repair"];
      record["pose_set"] = context.OutputPoseSetName("prior");
      writer.WriteJson(kPriorRepairJson, record);
    }
    if (options_.sigma_deg > 0 || options_.sigma_m > 0) {
      summary["accuracy"] = {{"sigma_deg", options_.sigma_deg}, {"sigma_m", options_.sigma_m}};
      writer.WriteJson(kPriorAccuracyJson, summary["accuracy"]);
    }
    writer.Commit();
    summary["num_poses"] = prior.size();
    summary["warnings"] = WarningsToJson(warnings);
    return summary;
  }

 private:
  // The poses the source option names (a file, the capture's, another pose set, the bootstrap's,
  // the ground truth or a perturbation of it); poses of images not in the dataset dropped, with a
  // warning.
  PoseSet SourcePoses(const StageContext& context, const ImageSet& images, nlohmann::json* summary,
                      Warnings* warnings) const {
    PoseSet prior;
    if (options_.source == "file") {
      prior = ReadPoseFile(options_.format, options_.path, &images);
      DropPosesWithoutImages(images, &prior, warnings);
    } else if (options_.source == "capture") {
      if (!context.artifacts.count(PoseArtifact("capture"))) {
        throw InputError(
            "prior.source 'capture': this dataset has no capture poses (the dataset formats "
            "that bring the capture app's poses are " +
            std::string(kFormatsWithCapturePoses) +
            "); use prior.source 'file' with the poses' file, or 'perturb' on ground truth");
      }
      prior = Hdf5Reader(context.Require(PoseArtifact("capture"))).ReadPoseSet("capture");
      DropPosesWithoutImages(images, &prior, warnings);
    } else if (options_.source == "pose_set") {
      prior = Hdf5Reader(context.Require(PoseArtifact(options_.pose_set)))
                  .ReadPoseSet(options_.pose_set);
    } else if (options_.source == "bootstrap") {
      prior = Hdf5Reader(context.Require(PoseArtifact("bootstrap"))).ReadPoseSet("bootstrap");
    } else {
      if (!context.artifacts.count(PoseArtifact("ground_truth"))) {
        throw InputError("prior.source '" + options_.source + "': " + options_.source +
                         " needs ground truth; this dataset has none — use source: capture "
                         "(the capture app's poses, formats " +
                         kFormatsWithCapturePoses + ") or file");
      }
      const PoseSet ground_truth = WithConvention(
          Hdf5Reader(context.Require(PoseArtifact("ground_truth"))).ReadPoseSet("ground_truth"));
      if (options_.source == "ground_truth") {
        prior = ground_truth;
      } else {
        PerturbationSummary perturbation;
        prior = PerturbPoses(ground_truth, options_.perturbation, &perturbation);
        (*summary)["translation_m"] = perturbation.translation_m;
        (*summary)["scene_distance_m"] = perturbation.scene_distance_m;
        spdlog::info(fmt::format("prior: {} perturbation at {}° / {:.4f} m (seed {})",
                                 options_.perturbation.mode, options_.perturbation.level_deg,
                                 perturbation.translation_m, options_.perturbation.seed));
      }
    }
    return prior;
  }

  // Replaces the prior's rotations or poses by the bootstrap's (prior.repair), said in the
  // summary and the log.
  void Repair(const StageContext& context, PoseSet* prior_poses, nlohmann::json* summary) const {
    PoseSet& prior = *prior_poses;
    const Hdf5Reader bootstrap_reader(context.Require(PoseArtifact("bootstrap")));
    const PoseSet bootstrap = bootstrap_reader.ReadPoseSet("bootstrap");
    PriorRepairSummary repair;
    try {
      if (options_.repair == "rotations") {
        prior = RepairRotations(prior, bootstrap, &repair);
      } else if (options_.repair == "replace") {
        prior = ReplaceWithBootstrap(prior, bootstrap, &repair);
      } else {
        prior = RepairIfCoarse(prior, bootstrap, options_.repair_min_rotation_change_deg,
                               !BootstrapIsWeak(bootstrap_reader), &repair);
      }
    } catch (const std::exception& e) {  // InputError, or a repair's precondition
      throw InputError(std::string("prior.repair '") + options_.repair + "': " + e.what());
    }
    (*summary)["repair"] = {{"mode", repair.mode},
                            {"num_repaired", repair.num_repaired},
                            {"num_kept_prior", repair.num_kept_prior},
                            {"scale", repair.scale},
                            {"median_rotation_change_deg", repair.median_rotation_change_deg}};
    if (options_.repair == "auto") {
      (*summary)["repair"]["requested"] = "auto";
      (*summary)["repair"]["min_rotation_change_deg"] = repair.min_rotation_change_deg;
      const bool kept = repair.mode == "none";
      const std::string action =
          kept ? std::string("prior kept")
          : repair.mode == "replace"
              ? fmt::format("coarse: {} poses replaced by the bootstrap's, {} kept",
                            repair.num_repaired, repair.num_kept_prior)
              : fmt::format(
                    "coarse: rotations of {} images repaired (the graph does not "
                    "support the bootstrap's positions), {} kept",
                    repair.num_repaired, repair.num_kept_prior);
      spdlog::log(kept ? spdlog::level::info : spdlog::level::warn,
                  fmt::format("prior: the prior's rotations are {:.2f}° (median) from the "
                              "bootstrap's averaged ones, {} the threshold {}° -> {}",
                              repair.median_rotation_change_deg, kept ? "within" : "beyond",
                              repair.min_rotation_change_deg, action));
    } else {
      spdlog::info(
          fmt::format("prior: {} repair from the bootstrap: {} poses repaired, {} kept, median "
                      "rotation change {:.2f}°",
                      repair.mode, repair.num_repaired, repair.num_kept_prior,
                      repair.median_rotation_change_deg));
    }
  }
};

}  // namespace

std::unique_ptr<Stage> CreatePriorStage() { return std::make_unique<PriorStage>(); }

}  // namespace raytime
