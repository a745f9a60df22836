// Every pipeline the repository ships (configs/, configs/paper/, bench/) loads and validates as
// `raytime run` would before running anything, and every refiner preset names only valid options
// (issue 10: the paper configs and capture.yaml use readers and options that landed later than
// most of the files; a renamed option must break this test, not a user's run).
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "pipelines/pipeline_spec.h"
#include "temp_dir.h"

namespace raytime {
namespace {

namespace fs = std::filesystem;

// The pipeline files under `folder` (recursively), presets excluded: those are option sets, not
// pipelines (PresetsNameOnlyValidOptions).
std::vector<std::string> PipelineFiles(const std::string& folder) {
  std::vector<std::string> files;
  for (const auto& entry :
       fs::recursive_directory_iterator(fs::path(RAYTIME_SOURCE_DIR) / folder)) {
    const fs::path& path = entry.path();
    if (path.extension() != ".yaml") continue;
    if (path.string().find("/presets/") != std::string::npos) continue;
    files.push_back(path.string());
  }
  std::sort(files.begin(), files.end());
  return files;
}

// Loads, validates and expands one shipped pipeline. Pipelines meant to be pointed at the user's
// data leave dataset.root empty; they get the sample scene's folder, as `--set dataset.root=...`
// would give them theirs.
void LoadAndValidate(const std::string& path) {
  PipelineSpec spec = LoadPipeline(path);
  if (spec.stages.front().options["root"].as<std::string>("").empty()) {
    ApplyOverride(&spec,
                  std::string("dataset.root=") + RAYTIME_SOURCE_DIR + "/data/sample/fountain-P11");
  }
  ValidatePipeline(spec);
  if (!spec.sweep.empty()) {
    EXPECT_FALSE(ExpandSweep(spec).empty()) << path;
  }
}

TEST(ShippedConfigs, EveryPipelineLoadsAndValidates) {
  std::vector<std::string> files = PipelineFiles("configs");
  const std::vector<std::string> bench = PipelineFiles("bench");
  files.insert(files.end(), bench.begin(), bench.end());
  // configs/ alone holds the demo, capture, ladder and one pipeline per paper table.
  ASSERT_GE(files.size(), 20u);
  for (const std::string& path : files) {
    SCOPED_TRACE(path);
    try {
      LoadAndValidate(path);
    } catch (const InputError& e) {
      ADD_FAILURE() << e.what();
    }
  }
}

TEST(ShippedConfigs, PresetsNameOnlyValidOptions) {
  const fs::path presets = fs::path(RAYTIME_SOURCE_DIR) / "configs/presets/refine";
  TempDir dir("presets");
  int count = 0;
  for (const auto& entry : fs::directory_iterator(presets)) {
    if (entry.path().extension() != ".yaml") continue;
    const std::string name = entry.path().stem().string();
    SCOPED_TRACE(name);
    const std::string path = dir / (name + ".yaml");
    std::ofstream(path) << "name: t\ndataset: {format: strecha, root: " << RAYTIME_SOURCE_DIR
                        << "/data/sample/fountain-P11}\nstages:\n  - refine: {preset: " << name
                        << "}\n";
    try {
      ValidatePipeline(LoadPipeline(path));
    } catch (const InputError& e) {
      ADD_FAILURE() << e.what();
    }
    ++count;
  }
  EXPECT_GE(count, 6);
}

}  // namespace
}  // namespace raytime
