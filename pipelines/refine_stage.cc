// The `refine` stage: the ray-time refiner (refine/, SPEC §3) on the front end's verified matches
// from the pose set "prior" (option `prior`), each image with its own camera's intrinsics. Writes
// the pose set "refined" ("refined@NAME" for a stage id refine@NAME), beside it the solved
// observations and their ray times (/ray_times/<pose set>, for the 3DGS export's initial points;
// only of solves whose poses are returned), the run summary as /json/refine_summary and, when
// self-calibrating, the refined intrinsics per camera (a new /images + /cameras group, so later
// stages such as export use them, and /json/refined_intrinsics).
//
// Named presets are YAML files configs/presets/refine/<name>.yaml (directory RAYTIME_PRESET_DIR
// in the environment, else the installed share/raytime/configs/presets, else the source tree's:
// core/shipped_files.h); a key given explicitly in the pipeline, in --set or on the command line
// always overrides the preset's, whatever its value.
#include <fmt/ranges.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <limits>
#include <map>
#include <set>

#include "core/camera.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/json_fields.h"
#include "core/shipped_files.h"
#include "core/warnings.h"
#include "pipelines/stages.h"
#include "refine/scene.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

struct RefineStageOptions {
  // plain | gnc | cap100 | anchored | room-staged | basin | auto (files in the preset directory).
  std::string preset = "gnc";
  // Pose set the solve starts from, e.g. "prior@bootstrap" for a stage prior@bootstrap, so arms
  // seeded differently can share one run.
  std::string prior = "prior";
  // Refuse a prior that the matches' own relative poses say is in another convention (inverted,
  // OpenGL camera axes): refined as given it becomes a wrong answer that looks converged.
  bool check_prior_convention = true;
  // Start the passes on all matches from this stage's solution at its previous run in the work
  // directory (issue 34: a capture that grew or lost frames); the capped passes that decide and
  // the anneal run as without it. Off by default: on grown captures it saves little and makes the
  // result depend on the work directory's history (docs/refine_options.md).
  bool warm_start = false;
  RefineOptions refine;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("preset", preset,
      "Named preset (configs/presets/refine/NAME.yaml) applied before the explicit keys",
      NonEmpty());
    v("prior", prior, "Pose set the solve starts from (e.g. prior, prior@bootstrap)", NonEmpty());
    v("check_prior_convention", check_prior_convention,
      "Refuse a prior that another pose convention (inverted, flipped camera axes) explains far "
      "better than as given, judged by the verified pairs' own relative poses");
    v("warm_start", warm_start,
      "Start the all-match finish from this work directory's previous refine solution (frames "
      "added or removed since; fewer iterations, a result that depends on that history)");
    refine.VisitFields(v);  // flat keys: refine.max_matches_per_pair, ...
  }
  static std::vector<OptionAlias> DeprecatedAliases() { return RefineOptions::DeprecatedAliases(); }
  void CheckRelations(const Requirement& require) const { refine.CheckRelations(require); }
};

// InputError naming every place it looked when none holds the presets (an installed binary
// without its share/raytime, a moved build tree).
fs::path PresetDirectory() {
  const ShippedDirectory presets = FindShippedDirectory("RAYTIME_PRESET_DIR", "configs/presets");
  if (presets.path.empty()) {
    throw InputError("refine.preset: no preset folder found; looked in " + presets.Searched());
  }
  return presets.path / "refine";
}

std::vector<std::string> PresetNames() {
  std::vector<std::string> names;
  std::error_code error;
  for (const auto& entry : fs::directory_iterator(PresetDirectory(), error)) {
    if (entry.path().extension() == ".yaml") names.push_back(entry.path().stem().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

fs::path PresetPath(const std::string& name) {
  const fs::path path = PresetDirectory() / (name + ".yaml");
  if (name.empty() || name.find('/') != std::string::npos || !fs::is_regular_file(path)) {
    const std::vector<std::string> names = PresetNames();
    if (names.empty()) {
      throw InputError("refine.preset '" + name + "': no presets found in " +
                       PresetDirectory().string() + " (set RAYTIME_PRESET_DIR)");
    }
    throw InputError(UnknownKeyMessage("refine.preset", name, names, "preset") + " (in " +
                     PresetDirectory().string() + ")");
  }
  return path;
}

// Whether a prior pose set's rotations were made from the match graph: the bootstrap's own
// poses, a prior stage that took them (`source: bootstrap`), or a prior whose repair replaced
// them (kPriorRepairJson beside it says a mode other than "none").
bool RotationsFromMatches(const Hdf5Reader& reader, const std::string& pose_set,
                          const Provenance& provenance) {
  if (provenance.stage == "bootstrap") return true;
  if (provenance.stage != "prior" || !provenance.options.is_object()) return false;
  if (provenance.options.value("source", "") == "bootstrap") return true;
  if (!reader.HasJson(kPriorRepairJson)) return false;
  const nlohmann::json repair = reader.ReadJson(kPriorRepairJson);
  if (!repair.is_object() || !repair.contains("pose_set") || !repair["pose_set"].is_string() ||
      !repair.contains("mode") || !repair["mode"].is_string()) {
    throw InputError(reader.path() + ": /json/" + kPriorRepairJson +
                     " is not the prior stage's repair record (an object with the strings "
                     "pose_set and mode); run the prior stage again");
  }
  return repair["pose_set"] == pose_set && repair["mode"] != "none";
}

// The accuracy the prior's maker states (kPriorAccuracyJson beside its pose set), if any.
StatedPriorAccuracy StatedAccuracyOf(const Hdf5Reader& reader) {
  StatedPriorAccuracy stated;
  if (!reader.HasJson(kPriorAccuracyJson)) return stated;
  const nlohmann::json accuracy = reader.ReadJson(kPriorAccuracyJson);
  if (!accuracy.is_object()) {
    throw InputError(reader.path() + ": /json/" + kPriorAccuracyJson +
                     " is not an object {sigma_deg, sigma_m}; run the prior stage again");
  }
  if (accuracy.value("sigma_deg", 0.0) > 0) stated.rotation_deg = accuracy["sigma_deg"];
  if (accuracy.value("sigma_m", 0.0) > 0) stated.centre = accuracy["sigma_m"];
  return stated;
}

// JSON document beside a refined pose set: per pass name that an earlier run's solution may start
// (RefineWarmStart), per image name, its pose at the end of that pass: [qw, qx, qy, qz, x, y, z]
// (rotation world_from_cam, camera centre). Written by refine, read by its next run.
constexpr const char* kPassPosesJson = "pass_poses";

// The earlier solution in the stage's previous output; empty when it has none (an older output, or
// every solve returned the prior). Unreadable: empty, and the log says why.
EarlierSolution ReadEarlierSolution(const StageContext& context, const std::string& pose_set) {
  EarlierSolution earlier;
  const bool read = context.ReadPreviousOutput(
      [&](const Hdf5Reader& reader) {
        if (!reader.HasJson(kPassPosesJson) || !reader.HasRayTimes(pose_set)) return;
        earlier = EarlierSolutionOf(reader.ReadJson(kPassPosesJson), reader.ReadRayTimes(pose_set));
      },
      "starting from the prior");
  return read ? earlier : EarlierSolution();
}

class RefineStage : public StageWithOptions<RefineStageOptions> {
 public:
  std::string type() const override { return "refine"; }
  std::string description() const override {
    return "Refine the prior's poses with the ray-time GNC solver (preset " + options_.preset + ")";
  }

  // The preset's values, under the keys the pipeline gives explicitly (StageWithOptions).
  void ApplyPreset(const YAML::Node& node, const std::string& path) override {
    if (node && node.IsMap() && node["preset"]) {
      ReadYamlField(node["preset"], options_.preset, path, "preset");
    }
    const fs::path preset_path = PresetPath(options_.preset);
    const YAML::Node preset = LoadYamlFile(preset_path.string());
    ApplyYaml(preset, options_.refine, preset_path.string(),
              "refine preset '" + options_.preset + "'");
  }

  std::vector<std::string> Inputs() const override {
    return {kArtifactImages, "features", "matches", PoseArtifact(options_.prior)};
  }
  std::vector<std::string> ExternalFiles() const override {
    return {PresetPath(options_.preset).string()};
  }

  nlohmann::json Run(const StageContext& context) override {
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    const std::vector<ImageFeatures> features =
        Hdf5Reader(context.Require("features")).ReadFeatures();
    const std::vector<PairMatches> matches = Hdf5Reader(context.Require("matches")).ReadMatches();
    Provenance prior_provenance;
    const Hdf5Reader prior_reader(context.Require(PoseArtifact(options_.prior)));
    const PoseSet prior = prior_reader.ReadPoseSet(options_.prior, nullptr, &prior_provenance);
    SceneInput input;
    input.images = &images;
    input.features = &features;
    input.matches = &matches;
    input.prior = &prior;
    input.prior_source = "pose set '" + options_.prior + "' of " + prior_reader.path();
    input.features_source = context.Require("features");
    input.matches_source = context.Require("matches");
    input.prior_rotations_from_matches =
        RotationsFromMatches(prior_reader, options_.prior, prior_provenance);
    input.stated_prior = StatedAccuracyOf(prior_reader);
    input.check_prior_convention = options_.check_prior_convention;
    if (options_.warm_start) {
      input.earlier = ReadEarlierSolution(context, context.OutputPoseSetName("refined"));
    }
    const SceneResult scene = RefineScene(input, options_.refine);
    nlohmann::json result = scene.summary.ToJson();
    result["preset"] = options_.preset;
    result["prior_convention"] = scene.convention;
    result["num_images_without_prior"] = scene.num_images_without_prior;
    Write(context, scene, &result);
    return result;
  }

 private:
  // The refined pose set, its ray times, (self-calibrating) the refined cameras and the JSON
  // documents beside it, in one HDF5 commit; the summary's per-image lists by name.
  void Write(const StageContext& context, const SceneResult& scene, nlohmann::json* result) {
    const std::string pose_set = context.OutputPoseSetName("refined");
    Hdf5Writer writer(context.output_path);
    writer.WritePoseSet(pose_set, scene.refined, PoseRole::kRefined, MakeProvenance(*this));
    writer.WriteRayTimes(pose_set, scene.ray_times);
    (*result)["pose_set"] = pose_set;
    (*result)["num_refined"] = scene.refined.size();
    (*result)["frame_verdicts"] = scene.frame_verdicts;
    (*result)["uncertainty"]["cameras"] = scene.uncertainty;
    if (scene.refined_images) {
      writer.WriteImages(*scene.refined_images);
      (*result)["refined_intrinsics"] = scene.refined_intrinsics;
      writer.WriteJson("refined_intrinsics", scene.refined_intrinsics);
    }
    writer.WriteJson("refine_summary", *result);
    writer.WriteJson(kFrameVerdictsJson, scene.frame_verdicts);
    writer.WriteJson(kPoseUncertaintyJson, scene.uncertainty);
    writer.WriteJson(kSolveDiagnosticsJson, scene.diagnostics);
    writer.WriteJson(kPassPosesJson, scene.pass_poses);
    writer.Commit();
  }
};

}  // namespace

std::unique_ptr<Stage> CreateRefineStage() { return std::make_unique<RefineStage>(); }

}  // namespace raytime
