// The `export` stage: pose sets out of the work directory in the formats users train on
// (COLMAP model for 3DGS, nerfstudio transforms.json, TUM trajectory; SPEC §7).
#include <spdlog/spdlog.h>

#include <filesystem>

#include "core/formats/colmap_model.h"
#include "core/formats/nerfstudio.h"
#include "core/formats/tum.h"
#include "core/hdf5_store.h"
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
    for (const auto& name : options_.poses) {
      const PoseSet poses = Hdf5Reader(context.Require(PoseArtifact(name))).ReadPoseSet(name);
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
    return {{"written", written}};
  }
};

}  // namespace

std::unique_ptr<Stage> CreateExportStage() { return std::make_unique<ExportStage>(); }

}  // namespace raytime
