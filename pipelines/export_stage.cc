// The `export` stage: pose sets out of the work directory in the formats users train on
// (COLMAP model for 3DGS, nerfstudio transforms.json, TUM trajectory; SPEC §7).
#include <spdlog/spdlog.h>

#include <filesystem>

#include "core/formats/colmap_model.h"
#include "core/formats/nerfstudio.h"
#include "core/formats/tum.h"
#include "core/error.h"
#include "core/hdf5_store.h"
#include "core/warnings.h"
#include "pipelines/stages.h"

namespace fs = std::filesystem;

namespace raytime {
namespace {

const std::vector<std::string> kExportFormats = {"colmap_text", "colmap_binary", "transforms_json",
                                                 "tum"};

struct ExportStageOptions {
  std::vector<std::string> poses = {"prior"};
  // colmap_text -> WORKDIR/<poses>/ ; colmap_binary -> WORKDIR/<poses>_bin/ ;
  // transforms_json -> WORKDIR/<poses>_transforms.json ; tum -> WORKDIR/<poses>_tum.txt
  std::vector<std::string> formats = {"colmap_text", "transforms_json"};

  template <class Visitor>
  void VisitFields(Visitor&& v) {
    v("poses", poses, "Pose sets to write (e.g. refined)", NonEmpty());
    v("formats", formats,
      "colmap_text -> DIR/<poses>/, colmap_binary -> <poses>_bin/, transforms_json -> "
      "<poses>_transforms.json, tum -> <poses>_tum.txt",
      OneOf(kExportFormats));
  }
};

std::string ExportPath(const std::string& poses, const std::string& format) {
  if (format == "colmap_text") return poses;
  if (format == "colmap_binary") return poses + "_bin";
  if (format == "transforms_json") return poses + "_transforms.json";
  return poses + "_tum.txt";
}

// The poses of set `name` that may be exported under its name. A refined set leaves out the
// images a guardrail returned unrefined: users train on these files, and a prior pose under the
// name "refined" is a quiet wrong answer. Each left-out image is named in a warning; a set with
// nothing left is an error, so the run fails instead of writing an empty model.
PoseSet ExportablePoses(const StageContext& context, const std::string& name,
                        Warnings* warnings) {
  const Hdf5Reader reader(context.Require(PoseArtifact(name)));
  PoseRole role = PoseRole::kPrior;
  PoseSet poses = reader.ReadPoseSet(name, &role);
  if (role != PoseRole::kRefined || !reader.HasJson(kUnrefinedImagesJson)) return poses;
  std::vector<std::string> left_out;
  for (const auto& entry : reader.ReadJson(kUnrefinedImagesJson)) {
    const std::string image = entry.get<std::string>();
    if (poses.world_from_cam.erase(image)) left_out.push_back(image);
  }
  if (left_out.empty()) return poses;
  if (poses.world_from_cam.empty()) {
    throw InputError("export: no pose of '" + name +
                     "' was refined (a guardrail returned the prior for every image; see the "
                     "refine stage's warnings); nothing exported. Export the pose set 'prior' "
                     "explicitly if that is what you want to train on");
  }
  warnings->push_back({"unrefined_not_exported",
                       std::to_string(left_out.size()) + " image(s) of '" + name +
                           "' kept the prior's pose (guardrail) and are left out of its export",
                       left_out,
                       {},
                       {{"pose_set", name}}});
  spdlog::warn("export: {}", warnings->back().message);
  return poses;
}

class ExportStage : public StageWithOptions<ExportStageOptions> {
 public:
  std::string type() const override { return "export"; }
  std::string description() const override {
    return "Write pose sets as COLMAP models, transforms.json or TUM trajectories";
  }
  std::vector<std::string> Inputs() const override {
    std::vector<std::string> inputs = {kArtifactImages};
    for (const auto& name : options_.poses) inputs.push_back(PoseArtifact(name));
    return inputs;
  }
  std::vector<std::string> ExtraOutputs() const override {
    std::vector<std::string> outputs;
    for (const auto& name : options_.poses) {
      for (const auto& format : options_.formats) outputs.push_back(ExportPath(name, format));
    }
    return outputs;
  }

  nlohmann::json Run(const StageContext& context) override {
    const ImageSet images = Hdf5Reader(context.Require(kArtifactImages)).ReadImages();
    nlohmann::json written = nlohmann::json::array();
    Warnings warnings;
    for (const auto& name : options_.poses) {
      const PoseSet poses = ExportablePoses(context, name, &warnings);
      for (const auto& format : options_.formats) {
        const std::string path = (fs::path(context.workdir) / ExportPath(name, format)).string();
        if (format == "colmap_text") {
          WriteColmapModelText(ToColmapModel(images, poses), path);
        } else if (format == "colmap_binary") {
          WriteColmapModelBinary(ToColmapModel(images, poses), path);
        } else if (format == "transforms_json") {
          WriteTransformsJson(path, images, poses);
        } else {
          WriteTumTrajectory(path, poses);
        }
        spdlog::info("export: {} -> {}", name, path);
        written.push_back(path);
      }
    }
    // The HDF5 output records what was exported, so a skipped rerun can report it.
    Hdf5Writer writer(context.output_path);
    writer.WriteJson("exported", written);
    writer.Commit();
    return {{"written", written}, {"warnings", WarningsToJson(warnings)}};
  }
};

}  // namespace

std::unique_ptr<Stage> CreateExportStage() { return std::make_unique<ExportStage>(); }

}  // namespace raytime
