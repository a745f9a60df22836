// Issue 47 "nothing absurd is accepted", the run half of the option-bounds table
// (option_bounds_test.cc refuses NaN, infinity and huge values at configuration): every value 0
// and -1 (and a huge seed) that a numeric option of the stages below accepts is run end to end on
// a small copy of the sample scene, and must give a clean error (exit 2) or a valid run (exit 0,
// a finished summary) - never a crash, a hang or a record left at "running".
#include <gtest/gtest.h>
#include <unistd.h>
#include <yaml-cpp/yaml.h>

#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "core/atomic_file.h"
#include "core/error.h"
#include "pipelines/stage.h"
#include "pipelines/stages.h"
#include "tests/raytime_command.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace raytime {
namespace {

// Every stage a user's run can hold but the trainers' (splat needs a trainer), the COLMAP
// control and the import (their own integration tests run them).
constexpr char kPipeline[] = R"(name: bounds
dataset: {format: strecha, root: SCENE}
workdir: WORKDIR
stages:
  - features: {max_features: 2048}
  - matches: {pairs: exhaustive}
  - bootstrap: {positions: lud}
  - prior: {source: perturb, mode: iid, level_deg: 2, seed: 0, translation_per_deg: 0.0125}
  - refine: {preset: auto}
  - evaluate: {poses: [prior, refined, bootstrap]}
  - export: {poses: [refined], formats: [colmap_text, transforms_json]}
)";

struct Case {
  std::string key;  // STAGE.OPTION
  std::string value;
};

// The numeric options' values 0 and -1 the stages above accept, and a huge seed.
std::vector<Case> AcceptedCases() {
  std::vector<Case> cases;
  for (const char* type_name :
       {"dataset", "features", "matches", "bootstrap", "prior", "refine", "evaluate", "export"}) {
    const std::string type = type_name;
    std::unique_ptr<Stage> stage = CreateStage(type);
    for (const OptionDoc& doc : stage->OptionDocs()) {
      if (doc.type != "INT" && doc.type != "NUMBER") continue;
      for (const std::string value : {"0", "-1", "2147483647"}) {
        const std::string text = doc.is_list ? "[" + value + "]" : value;
        try {
          stage->Configure(YAML::Load("{" + std::string(type == "dataset" ? "root: x, " : "") +
                                      doc.key + ": " + text + "}"),
                           "t");
        } catch (const InputError&) {
          continue;
        }
        cases.push_back({type + "." + doc.key, text});
      }
    }
  }
  return cases;
}

class OptionBoundsRunTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::temp_directory_path() / ("raytime_bounds_" + std::to_string(::getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    const fs::path scene = dir_ / "scene";
    const CommandResult resized = RunRaytime(
        "resize-scene --format strecha --root data/sample/fountain-P11 --width 384 --out " +
        scene.string());
    ASSERT_EQ(resized.exit_code, 0) << resized.output;
    std::string yaml = kPipeline;
    yaml.replace(yaml.find("SCENE"), 5, scene.string());
    yaml.replace(yaml.find("WORKDIR"), 7, (dir_ / "base").string());
    WriteTextFileAtomically((dir_ / "bounds.yaml").string(), yaml);
    const CommandResult base = RunRaytime("run " + (dir_ / "bounds.yaml").string());
    ASSERT_EQ(base.exit_code, 0) << base.output;
  }
  static void TearDownTestSuite() { fs::remove_all(dir_); }

  static fs::path dir_;
};

fs::path OptionBoundsRunTest::dir_;

TEST_F(OptionBoundsRunTest, EveryAcceptedEdgeValueGivesAValidRunOrACleanError) {
  const std::vector<Case> cases = AcceptedCases();
  EXPECT_GT(cases.size(), 20u);
  int valid = 0, refused = 0;
  for (const Case& c : cases) {
    const std::string name = c.key + "=" + c.value;
    SCOPED_TRACE(name);
    // From the base run's results: only the stage the option belongs to and those after it run.
    const fs::path workdir = dir_ / "case";
    fs::remove_all(workdir);
    // cp -a: the records of what raytime wrote compare file times (core/written_files.h).
    ASSERT_EQ(RunShell("cp -a " + (dir_ / "base").string() + " " + workdir.string()).exit_code, 0);
    const CommandResult result =
        RunRaytime("run " + (dir_ / "bounds.yaml").string() + " --workdir " + workdir.string() +
                   " --set '" + name + "'");
    ASSERT_TRUE(result.exit_code == 0 || result.exit_code == 2)
        << "exit " << result.exit_code << "\n"
        << result.output;
    std::ifstream in(workdir / "summary.json");
    const json summary = json::parse(in, nullptr, false);
    if (result.exit_code == 0) {
      ++valid;
      EXPECT_TRUE(summary["status"] == "ok" || summary["status"] == "ok_with_warnings") << summary;
    } else {
      ++refused;
      EXPECT_NE(result.output.find("error"), std::string::npos) << result.output;
      if (summary.is_object()) {
        EXPECT_NE(summary["status"], "running") << summary;
      }
    }
  }
  std::cout << cases.size() << " accepted edge values: " << valid << " valid runs, " << refused
            << " clean errors\n";
}

}  // namespace
}  // namespace raytime
