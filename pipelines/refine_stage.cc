// The `refine` stage: the ray-time refiner (refine/, SPEC §3) on the front end's verified matches
// from the pose set "prior" (option `prior`). Writes the pose set "refined" ("refined@NAME" for a
// stage id refine@NAME), the run summary as /json/refine_summary and, when self-calibrating, the
// refined intrinsics (a new /images + /cameras group, so later stages such as export use them, and
// /json/refined_intrinsics).
//
// Named presets are YAML files configs/presets/refine/<name>.yaml (directory RAYTIME_PRESET_DIR
// in the environment, else the source tree's configs/presets); keys given explicitly in the
// pipeline (or on the command line) override the preset's.
#include <spdlog/spdlog.h>

#include <cstdlib>
#include <filesystem>
#include <map>

#include "core/error.h"
#include "core/hdf5_store.h"
#include "pipelines/stages.h"
#include "refine/refine.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

struct RefineStageOptions {
  // plain | gnc | cap100 | anchored | room-staged | basin (files in the preset directory).
  std::string preset = "gnc";
  // Pose set the solve starts from, e.g. "prior@bootstrap" for a stage prior@bootstrap, so arms
  // seeded differently can share one run.
  std::string prior = "prior";
  RefineOptions refine;

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("preset", preset);
    v("prior", prior);
    refine.VisitFields(v);  // flat keys: refine.max_matches_per_pair, ...
  }
};

fs::path PresetDirectory() {
  const char* env = std::getenv("RAYTIME_PRESET_DIR");
  return fs::path(env != nullptr && *env != '\0' ? env : RAYTIME_DEFAULT_PRESET_DIR) / "refine";
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

class RefineStage : public StageWithOptions<RefineStageOptions> {
 public:
  std::string type() const override { return "refine"; }
  std::string description() const override {
    return "Refine the prior's poses with the ray-time GNC solver (preset " + options_.preset + ")";
  }

  // Preset first, then the explicit keys. Values already set before Configure (command-line
  // flags of `raytime refine`) count as explicit too.
  void Configure(const YAML::Node& node, const std::string& path) override {
    RefineStageOptions default_options;
    const nlohmann::json defaults = OptionsToJson(default_options);
    const nlohmann::json current = OptionsToJson(options_);
    RefineStageOptions probe = options_;
    ApplyYaml(node, probe, path, "stage 'refine'");

    RefineStageOptions merged;
    merged.preset = probe.preset;
    const fs::path preset_path = PresetPath(merged.preset);
    YAML::Node preset;
    try {
      preset = YAML::LoadFile(preset_path.string());
    } catch (const YAML::Exception& e) {
      ThrowInput(preset_path.string(), e.mark.line + 1, e.msg);
    }
    ApplyYaml(preset, merged.refine, preset_path.string(), "refine preset '" + merged.preset + "'");
    nlohmann::json explicit_values = nlohmann::json::object();
    for (const auto& [key, value] : current.items()) {
      if (value != defaults[key]) explicit_values[key] = value;
    }
    OptionsFromJson(explicit_values, merged);
    ApplyYaml(node, merged, path, "stage 'refine'");
    options_ = merged;
    Validate();
  }
  void Validate() override {
    options_.refine.Validate();
    if (options_.prior.empty()) throw InputError("refine.prior must name a pose set");
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
    const PoseSet prior =
        Hdf5Reader(context.Require(PoseArtifact(options_.prior))).ReadPoseSet(options_.prior);
    if (features.size() != images.images.size()) {
      throw InputError(context.Require("features") + ": features for " +
                       std::to_string(features.size()) + " images, but the image list has " +
                       std::to_string(images.images.size()));
    }
    for (const ImageInfo& image : images.images) {
      if (image.camera_index != images.images.front().camera_index) {
        throw InputError("refine: images " + images.images.front().name + " and " + image.name +
                         " have different cameras; the refiner needs shared intrinsics "
                         "(SPEC §2)");
      }
    }

    // The images with a prior pose take part; the others are reported and left out.
    RefineInput input;
    input.intrinsics = images.cameras.at(images.images.front().camera_index);
    std::vector<int> refine_index(images.images.size(), -1);
    std::vector<std::string> names;
    std::vector<std::string> without_prior;
    for (size_t i = 0; i < images.images.size(); ++i) {
      const auto it = prior.world_from_cam.find(images.images[i].name);
      if (it == prior.world_from_cam.end()) {
        without_prior.push_back(images.images[i].name);
        continue;
      }
      refine_index[i] = static_cast<int>(names.size());
      names.push_back(images.images[i].name);
      input.prior_world_from_cam.push_back(it->second);
      input.keypoints.push_back(features[i].keypoints.leftCols<2>().cast<double>());
    }
    if (!without_prior.empty()) {
      spdlog::warn("refine: {} image(s) have no prior pose and are left out (first: {})",
                   without_prior.size(), without_prior.front());
    }
    for (const PairMatches& pair : matches) {
      const int i = refine_index.at(pair.image1);
      const int j = refine_index.at(pair.image2);
      if (i < 0 || j < 0 || pair.geometry.inlier_matches.rows() == 0) continue;
      input.pairs.push_back({i, j, pair.geometry.inlier_matches});
    }

    RefineOutput output;
    const RefineSummary summary = RefinePoses(input, options_.refine, &output);

    PoseSet refined;
    for (size_t k = 0; k < names.size(); ++k)
      refined.world_from_cam[names[k]] = output.world_from_cam[k];
    const std::string pose_set = context.OutputPoseSetName("refined");
    Hdf5Writer writer(context.output_path);
    writer.WritePoseSet(pose_set, refined, PoseRole::kRefined, MakeProvenance(*this));
    nlohmann::json result = summary.ToJson();
    result["preset"] = options_.preset;
    result["pose_set"] = pose_set;
    result["num_images_without_prior"] = without_prior.size();
    if (options_.refine.SelfCalibrates()) {
      ImageSet refined_images = images;
      refined_images.cameras.at(images.images.front().camera_index) = output.intrinsics;
      writer.WriteImages(refined_images);
      const auto& p = output.intrinsics.params;
      result["refined_intrinsics"] = {{"fx", p[kFx]}, {"fy", p[kFy]}, {"cx", p[kCx]},
                                      {"cy", p[kCy]}, {"k1", p[kK1]}, {"k2", p[kK2]},
                                      {"p1", p[kP1]}, {"p2", p[kP2]}};
      writer.WriteJson("refined_intrinsics", result["refined_intrinsics"]);
    }
    writer.WriteJson("refine_summary", result);
    writer.Commit();
    spdlog::info("refine: {} poses, {} iterations in {:.2f} s{}", refined.size(),
                 summary.total_iterations, summary.total_seconds,
                 summary.returned_prior ? " (guardrail fired: prior returned)" : "");
    return result;
  }
};

}  // namespace

std::unique_ptr<Stage> CreateRefineStage() { return std::make_unique<RefineStage>(); }

}  // namespace raytime
