#include "pipelines/stage.h"

#include "core/error.h"

namespace raytime {

const std::string& StageContext::Require(const std::string& artifact) const {
  const auto it = artifacts.find(artifact);
  if (it == artifacts.end()) {
    std::string have;
    for (const auto& [name, file] : artifacts) have += (have.empty() ? "" : ", ") + name;
    throw InputError(
        "this stage needs '" + artifact +
        "', which no earlier stage produced (available: " + (have.empty() ? "none" : have) + ")");
  }
  return it->second;
}

std::string StageContext::OutputPoseSetName(const std::string& base) const {
  const size_t at = stage_id.find('@');
  return at == std::string::npos ? base : base + stage_id.substr(at);
}

std::string StageTypeOfId(const std::string& stage_id) {
  return stage_id.substr(0, stage_id.find('@'));
}

}  // namespace raytime

#include "core/hdf5_store.h"
#include "pipelines/stages.h"

namespace raytime {

std::vector<std::string> StageTypes() {
  return {"dataset", "features", "matches",   "colmap_import", "bootstrap",
          "prior",   "refine",   "classical", "evaluate",      "export"};
}

std::unique_ptr<Stage> CreateStage(const std::string& type) {
  if (type == "dataset") return CreateDatasetStage();
  if (type == "features") return CreateFeaturesStage();
  if (type == "matches") return CreateMatchesStage();
  if (type == "colmap_import") return CreateColmapImportStage();
  if (type == "bootstrap") return CreateBootstrapStage();
  if (type == "prior") return CreatePriorStage();
  if (type == "refine") return CreateRefineStage();
  if (type == "classical") return CreateClassicalStage();
  if (type == "evaluate") return CreateEvaluateStage();
  if (type == "export") return CreateExportStage();
  throw InputError(UnknownKeyMessage("the pipeline", type, StageTypes(), "stage"));
}

Provenance MakeProvenance(Stage& stage) {
  Provenance provenance;
  provenance.stage = stage.type();
  provenance.options = stage.OptionsJson();
  return provenance;
}

}  // namespace raytime
