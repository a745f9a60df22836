// Factories of the stage types the pipelines know. Each stage lives in its own file.
#pragma once

#include <memory>

#include "pipelines/stage.h"

namespace raytime {

std::unique_ptr<Stage> CreateDatasetStage();
std::unique_ptr<Stage> CreateFeaturesStage();
std::unique_ptr<Stage> CreateMatchesStage();
std::unique_ptr<Stage> CreateColmapImportStage();
std::unique_ptr<Stage> CreateBootstrapStage();
std::unique_ptr<Stage> CreatePriorStage();
std::unique_ptr<Stage> CreateRefineStage();
std::unique_ptr<Stage> CreateClassicalStage();
std::unique_ptr<Stage> CreateEvaluateStage();
std::unique_ptr<Stage> CreateExportStage();
std::unique_ptr<Stage> CreateSplatStage();

// Provenance for a pose set or group written by `stage`.
struct Provenance;
Provenance MakeProvenance(Stage& stage);

}  // namespace raytime
