// One pipeline stage run in-process on HDF5 files, as the runner would run it, for the tests of a
// stage adapter.
#pragma once

#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "pipelines/stage.h"

namespace raytime {

// Runs a stage of `type` configured by `options` (YAML text) in `workdir`, reading `artifacts`
// (artifact -> HDF5 file) and writing WORKDIR/`output` (default <type>.h5); returns its summary.
inline nlohmann::json RunStageInProcess(const std::string& type, const std::string& options,
                                        const std::string& workdir,
                                        const std::map<std::string, std::string>& artifacts,
                                        const std::string& output = "") {
  std::unique_ptr<Stage> stage = CreateStage(type);
  stage->Configure(YAML::Load(options), "test");
  StageContext context;
  context.stage_id = type;
  context.workdir = workdir;
  context.output_path =
      (std::filesystem::path(workdir) / (output.empty() ? type + ".h5" : output)).string();
  context.artifacts = artifacts;
  return stage->Run(context);
}

}  // namespace raytime
