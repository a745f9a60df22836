// Issue 47 "nothing absurd is accepted": every numeric option of every stage, set to 0, -1, a huge
// value, NaN and infinity. NaN and infinity are refused everywhere; a huge value everywhere but in
// a seed (any integer seeds a draw); 0 and -1 are refused or accepted by the option's rules, and
// the accepted ones are run end to end by option_bounds_run_test.cc. Every bounded option says its
// range in its help line.
#include <gtest/gtest.h>
#include <yaml-cpp/yaml.h>

#include <map>
#include <set>
#include <string>

#include "core/error.h"
#include "pipelines/stage.h"
#include "pipelines/stages.h"

namespace raytime {
namespace {

// Options a stage needs before any other can be configured.
std::string Required(const std::string& type) {
  if (type == "dataset") return "root: x, ";
  if (type == "colmap_import") return "path: x, ";
  return "";
}

// "" when `stage` takes `value` for `doc`, else the error.
std::string Configure(Stage& stage, const std::string& type, const OptionDoc& doc,
                      const std::string& value) {
  const std::string text = doc.is_list ? "[" + value + "]" : value;
  try {
    stage.Configure(YAML::Load("{" + Required(type) + doc.key + ": " + text + "}"), "bounds.yaml");
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

bool Numeric(const OptionDoc& doc) { return doc.type == "INT" || doc.type == "NUMBER"; }

const std::set<std::string> kSeeds = {"prior.seed", "refine.match_cap_seed", "splat.seed"};

TEST(OptionBoundsTest, NanInfinityAndHugeValuesAreRefusedByEveryNumericOption) {
  int numeric = 0;
  for (const std::string& type : StageTypes()) {
    std::unique_ptr<Stage> stage = CreateStage(type);
    for (const OptionDoc& doc : stage->OptionDocs()) {
      if (!Numeric(doc)) continue;
      ++numeric;
      const std::string name = type + "." + doc.key;
      SCOPED_TRACE(name + " {" + doc.HelpText() + "}");
      for (const char* value : {".nan", ".inf", "-.inf"}) {
        const std::string error = Configure(*stage, type, doc, value);
        EXPECT_NE(error.find(doc.key), std::string::npos) << value << ": '" << error << "'";
      }
      const std::string huge = doc.type == "INT" ? "2147483647" : "1e300";
      const std::string error = Configure(*stage, type, doc, huge);
      if (kSeeds.count(name) > 0) {
        EXPECT_EQ(error, "") << "a seed takes any integer";
        continue;
      }
      EXPECT_NE(error.find(doc.key), std::string::npos) << huge << " was accepted";
      const std::string help = doc.HelpText();
      EXPECT_TRUE(help.find("at most") != std::string::npos ||
                  help.find("below") != std::string::npos)
          << "the range is not in the help line: " << help;
    }
  }
  EXPECT_GT(numeric, 100);  // every stage's options were visited
}

// The error names the option and its range (the pipeline file and line are added where a
// pipeline's entry is configured).
TEST(OptionBoundsTest, AnOutOfRangeValueIsNamedWithItsRange) {
  std::unique_ptr<Stage> refine = CreateStage("refine");
  std::string error;
  try {
    refine->Configure(YAML::Load("{num_threads: 100000}"), "p.yaml");
  } catch (const InputError& e) {
    error = e.what();
  }
  EXPECT_NE(error.find("num_threads"), std::string::npos) << error;
  EXPECT_NE(error.find("at most 1024"), std::string::npos) << error;
}

}  // namespace
}  // namespace raytime
