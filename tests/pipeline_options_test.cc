// Option conventions of every stage (issue 13): overrides applied in any order and validated
// once, explicit keys beating a preset whatever their value, one description per option, rules
// that name the option and list an enumeration's values, and command lines that mean the same as
// YAML.
#include <gtest/gtest.h>
#include <spdlog/sinks/ostream_sink.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <fstream>
#include <map>
#include <sstream>

#include "core/error.h"
#include "core/options.h"
#include "pipelines/pipeline_spec.h"
#include "pipelines/stage.h"
#include "refine/refine_options.h"
#include "refine/refine_types.h"
#include "temp_dir.h"
#include "tests/input_error_of.h"

namespace raytime {
namespace {

// A pipeline file with a dataset and the given stage entries.
std::string WritePipeline(const TempDir& dir, const std::string& stages) {
  const std::string path = dir / "pipeline.yaml";
  std::ofstream(path) << "name: t\ndataset: {format: strecha, root: " << RAYTIME_SOURCE_DIR
                      << "/data/sample/fountain-P11}\nstages:\n"
                      << stages;
  return path;
}

TEST(PipelineOptionsTest, OverridesApplyInAnyOrderAndAreValidatedOnce) {
  TempDir dir("options");
  const std::string path = WritePipeline(dir, "  - prior: {level_deg: 4}\n");
  const std::vector<std::string> overrides = {"prior.source=file", "prior.format=colmap",
                                              "prior.path=" + dir / "model"};
  // Every order of the three --set values, as in the README's own-prior command.
  std::vector<size_t> order = {0, 1, 2};
  do {
    PipelineSpec spec = LoadPipeline(path);
    for (size_t k : order) ApplyOverride(&spec, overrides[k]);
    EXPECT_NO_THROW(ValidatePipeline(spec)) << order[0] << order[1] << order[2];
  } while (std::next_permutation(order.begin(), order.end()));

  // The same values missing one: refused once everything is in place, naming file and line.
  PipelineSpec spec = LoadPipeline(path);
  ApplyOverride(&spec, "prior.source=file");
  const std::string message = InputErrorOf([&] { ValidatePipeline(spec); });
  EXPECT_NE(message.find(path + ":4:"), std::string::npos) << message;
  EXPECT_NE(message.find("prior.path is not set"), std::string::npos) << message;
}

TEST(PipelineOptionsTest, OverridesCheckKeysAndTypesAsTheyArrive) {
  TempDir dir("options");
  PipelineSpec spec = LoadPipeline(WritePipeline(dir, "  - prior: {}\n"));
  EXPECT_NE(InputErrorOf([&] { ApplyOverride(&spec, "prior.sed=1"); }).find("did you mean 'seed'"),
            std::string::npos);
  EXPECT_NE(InputErrorOf([&] { ApplyOverride(&spec, "prior.level_deg=[1, 2]"); }).find("a number"),
            std::string::npos);
  // A value of the right type but outside its own rule is refused as it arrives, blamed on the
  // override (not on the pipeline's line), naming the rule, the value and what the option means.
  const std::string message = InputErrorOf([&] { ApplyOverride(&spec, "prior.level_deg=-3"); });
  EXPECT_EQ(message.rfind("--set prior.level_deg: ", 0), 0u) << message;
  EXPECT_NE(message.find("option 'level_deg' must be non-negative, got -3.0"), std::string::npos)
      << message;
  EXPECT_NE(message.find("degrees"), std::string::npos) << message;
  EXPECT_EQ(message.find(spec.path), std::string::npos) << message;
  // YAML's .nan and .inf are numbers to yaml-cpp: refused as such, not reported as "got null".
  for (const char* value : {".nan", ".inf", "-.inf"}) {
    const std::string refused =
        InputErrorOf([&] { ApplyOverride(&spec, std::string("prior.level_deg=") + value); });
    EXPECT_NE(refused.find("option 'level_deg' must be a finite number, got '" +
                           std::string(value) + "'"),
              std::string::npos)
        << refused;
    EXPECT_EQ(refused.find("null"), std::string::npos) << refused;
  }
  const std::string in_file = WritePipeline(dir, "  - refine: {gnc_scales: [1e4, .nan]}\n");
  const std::string list_message = InputErrorOf([&] { LoadPipeline(in_file); });
  EXPECT_NE(list_message.find(in_file + ":4:"), std::string::npos) << list_message;
  EXPECT_NE(list_message.find("must be a list of finite numbers"), std::string::npos)
      << list_message;
  // Relations wait until every override is in place: prior.path may come after prior.source.
  ApplyOverride(&spec, "prior.source=file");
  EXPECT_NE(InputErrorOf([&] { ValidatePipeline(spec); }).find("prior.path is not set"),
            std::string::npos);
  ApplyOverride(&spec, "prior.path=poses");
  EXPECT_NO_THROW(ValidatePipeline(spec));
}

TEST(PipelineOptionsTest, SweepCombinationsAreValidatedAsAWhole) {
  TempDir dir("options");
  const std::string path = WritePipeline(
      dir, "  - prior: {source: file, format: colmap}\nsweep:\n  prior.path: [a, b]\n");
  // prior.path is only set by the sweep: the base pipeline alone is incomplete, its runs are not.
  const PipelineSpec spec = LoadPipeline(path);
  const std::vector<SweepRun> runs = ExpandSweep(spec);
  ASSERT_EQ(runs.size(), 2u);
  EXPECT_EQ(runs[1].label, "path=b");
  EXPECT_EQ(runs[1].swept, (std::vector<std::pair<std::string, std::string>>{{"prior.path", "b"}}));
}

// Each run has its own directory: paths that end alike are labelled by as many last components as
// tell them apart (two scenes both named fountain-P11 in different folders shared one run
// directory, the second run read as the first's, done), and a value listed twice is refused.
TEST(PipelineOptionsTest, SweepRunsWithPathsEndingAlikeGetTheirOwnLabels) {
  TempDir dir("options");
  const std::string path = WritePipeline(
      dir,
      "  - prior: {source: file, format: colmap}\nsweep:\n  prior.path: "
      "[../shared/strecha/fountain-P11, data/sample/fountain-P11, other/entry-P10]\n");
  const std::vector<SweepRun> runs = ExpandSweep(LoadPipeline(path));
  ASSERT_EQ(runs.size(), 3u);
  EXPECT_EQ(runs[0].label, "path=strecha_fountain-P11");
  EXPECT_EQ(runs[1].label, "path=sample_fountain-P11");
  EXPECT_EQ(runs[2].label, "path=other_entry-P10");
  const std::string unique = WritePipeline(
      dir, "  - prior: {source: file, format: colmap}\nsweep:\n  prior.path: [a/x, b/y]\n");
  EXPECT_EQ(ExpandSweep(LoadPipeline(unique))[1].label, "path=y");

  const std::string twice = WritePipeline(
      dir, "  - prior: {source: file, format: colmap}\nsweep:\n  prior.path: [a/x, a/x]\n");
  const std::string message = InputErrorOf([&] { ExpandSweep(LoadPipeline(twice)); });
  EXPECT_NE(message.find("runs 1 and 2 are both 'path=a_x'"), std::string::npos) << message;
}

// Options, names and paths end up in JSON (provenance, content hashes, summary.json), which holds
// only UTF-8: other bytes are refused where they are read, naming the file, line and byte.
TEST(PipelineOptionsTest, TextThatIsNotUtf8IsRefusedWhereItIsRead) {
  TempDir dir("options");
  const std::string latin1_option = WritePipeline(dir, "  - prior: {format: colm\xe4p}\n");
  std::string message = InputErrorOf([&] { LoadPipeline(latin1_option); });
  EXPECT_NE(message.find(latin1_option + ":4:"), std::string::npos) << message;
  EXPECT_NE(message.find("option 'format' must be UTF-8 text (byte 0xE4 at offset 4 is not)"),
            std::string::npos)
      << message;

  const std::string list_element =
      WritePipeline(dir, "  - evaluate: {poses: [prior, \xc0\xaf]}\n");  // an overlong '/'
  message = InputErrorOf([&] { LoadPipeline(list_element); });
  EXPECT_NE(message.find("option 'poses' must be UTF-8 text (byte 0xC0 at offset 0"),
            std::string::npos)
      << message;

  std::ofstream(latin1_option) << "name: d\xe9mo\ndataset: {format: strecha, root: r}\n";
  message = InputErrorOf([&] { LoadPipeline(latin1_option); });
  EXPECT_NE(message.find(latin1_option + ":1: 'name' must be UTF-8 text"), std::string::npos)
      << message;

  // Well-formed multi-byte text passes.
  std::ofstream(latin1_option) << "name: d\xc3\xa9mo \xe2\x82\xac \xf0\x9f\x93\xb7\n"
                               << "dataset: {format: strecha, root: r\xc3\xa9}\n";
  EXPECT_EQ(LoadPipeline(latin1_option).name, "d\xc3\xa9mo \xe2\x82\xac \xf0\x9f\x93\xb7");
  EXPECT_EQ(InvalidUtf8Offset("\xed\xa0\x80"), 0u);        // a surrogate
  EXPECT_EQ(InvalidUtf8Offset("ab\xf4\x90\x80\x80"), 2u);  // beyond U+10FFFF
  EXPECT_EQ(InvalidUtf8Offset("abc\xe2\x82"), 3u);         // cut short
}

TEST(PipelineOptionsTest, ExplicitKeysBeatThePresetWhateverTheirValue) {
  // The basin preset turns the trust region off; true is also the built-in default.
  std::unique_ptr<Stage> refine = CreateStage("refine");
  refine->Configure(YAML::Load("{preset: basin}"), "test");
  EXPECT_EQ(refine->OptionsJson()["trust_region"], false);
  EXPECT_EQ(refine->OptionsJson()["max_matches_per_pair"], 100);
  refine->Configure(YAML::Load("{preset: basin, trust_region: true}"), "test");
  EXPECT_EQ(refine->OptionsJson()["trust_region"], true);
  EXPECT_EQ(refine->OptionsJson()["max_matches_per_pair"], 100);  // the rest stays the preset's
  // Configure starts from the defaults every time: nothing leaks from an earlier call.
  refine->Configure(YAML::Load("{}"), "test");
  EXPECT_EQ(refine->OptionsJson()["preset"], "gnc");
  EXPECT_EQ(refine->OptionsJson()["trust_region"], true);
}

TEST(PipelineOptionsTest, CommandLineFlagsAreExplicitKeys) {
  std::unique_ptr<Stage> refine = CreateStage("refine");
  CLI::App app;
  refine->BindCli(&app);
  app.parse(R"(--preset basin --trust_region 1 --gnc_scales "[1e4, 1e3]")", false);
  refine->Configure(refine->CliOptions(), "command line");
  const nlohmann::json options = refine->OptionsJson();
  EXPECT_EQ(options["preset"], "basin");
  EXPECT_EQ(options["trust_region"], true);
  EXPECT_EQ(options["gnc_scales"], (std::vector<double>{1e4, 1e3}));
  EXPECT_EQ(options["max_matches_per_pair"], 100);
}

TEST(PipelineOptionsTest, EveryOptionOfEveryStageIsDocumented) {
  for (const std::string& type : StageTypes()) {
    std::unique_ptr<Stage> stage = CreateStage(type);
    const std::vector<OptionDoc> docs = stage->OptionDocs();
    EXPECT_FALSE(docs.empty()) << type;
    for (const OptionDoc& doc : docs) {
      SCOPED_TRACE(type + "." + doc.key);
      EXPECT_GE(doc.description.size(), 12u) << "'" << doc.description << "'";
      EXPECT_EQ(doc.description.find('\n'), std::string::npos);
      for (const std::string& value : doc.values) {
        EXPECT_NE(doc.HelpText().find(value), std::string::npos) << doc.HelpText();
      }
    }
    // The defaults of every stage pass their own rules, given the options a stage requires.
    const std::map<std::string, std::string> required = {{"dataset", "{root: x}"},
                                                         {"colmap_import", "{path: x}"}};
    EXPECT_NO_THROW(stage->Configure(
        YAML::Load(required.count(type) ? required.at(type) : std::string("{}")), "t"))
        << type;
  }
  // Text options that take one of a fixed set of values say so.
  const auto docs = CreateStage("refine")->OptionDocs();
  const auto it = std::find_if(docs.begin(), docs.end(),
                               [](const OptionDoc& d) { return d.key == "parameterization"; });
  ASSERT_NE(it, docs.end());
  EXPECT_EQ(it->values, (std::vector<std::string>{"per_observation", "anchored"}));
  EXPECT_NE(it->HelpText().find("one of: per_observation, anchored"), std::string::npos);
}

// A shared set of intrinsics exists only to be self-calibrated (refine/refine_options.h): the
// relation is checked once every key is in place, in whatever order they came.
TEST(PipelineOptionsTest, SharedIntrinsicsNeedSelfCalibration) {
  std::unique_ptr<Stage> refine = CreateStage("refine");
  const std::string message = InputErrorOf(
      [&] { refine->Configure(YAML::Load("{intrinsics_sharing: shared}"), "p.yaml"); });
  EXPECT_NE(message.find("intrinsics_sharing 'shared'"), std::string::npos) << message;
  EXPECT_NE(message.find("refine_focal"), std::string::npos) << message;
  EXPECT_NO_THROW(refine->Configure(
      YAML::Load("{intrinsics_sharing: shared, refine_distortion: true}"), "p.yaml"));
  EXPECT_NO_THROW(
      refine->Configure(YAML::Load("{preset: room-staged, intrinsics_sharing: shared}"), "p.yaml"));
}

TEST(PipelineOptionsTest, EnumerationErrorsSuggestTheNearestValue) {
  std::unique_ptr<Stage> matches = CreateStage("matches");
  const std::string message =
      InputErrorOf([&] { matches->Configure(YAML::Load("{pairs: sequentail}"), "p.yaml"); });
  EXPECT_NE(message.find("one of: exhaustive, sequential"), std::string::npos) << message;
  EXPECT_NE(message.find("did you mean 'sequential'"), std::string::npos) << message;
}

// What spdlog logs while `f` runs ("warning: message" per line).
std::string LogOf(const std::function<void()>& f) {
  std::ostringstream log;
  const std::shared_ptr<spdlog::logger> previous = spdlog::default_logger();
  auto capture = std::make_shared<spdlog::logger>(
      "pipeline_options_test", std::make_shared<spdlog::sinks::ostream_sink_st>(log));
  capture->set_pattern("%l: %v");
  spdlog::set_default_logger(capture);
  try {
    f();
  } catch (...) {
    spdlog::set_default_logger(previous);
    throw;
  }
  spdlog::set_default_logger(previous);
  return log.str();
}

// The refine stage's options after Configure of a pipeline's refine entry with `overrides`.
nlohmann::json RefineOptionsWith(const std::string& path,
                                 const std::vector<std::string>& overrides) {
  PipelineSpec spec = LoadPipeline(path);
  for (const std::string& assignment : overrides) ApplyOverride(&spec, assignment);
  std::unique_ptr<Stage> refine = CreateStage("refine");
  refine->Configure(spec.stages.back().options, spec.path);
  return refine->OptionsJson();
}

// `staged` and `basin_first` were booleans before `recipe` (refine/refine_options.h): a YAML file,
// a --set and a command line that give them mean what the recipe says, with a warning naming it.
TEST(PipelineOptionsTest, DeprecatedRecipeKeysMeanTheRecipeWithAWarning) {
  RefineOptions old_key, new_key;
  const std::string log = LogOf(
      [&] { ApplyYaml(YAML::Load("{staged: true}"), old_key, "alias.yaml", "test 'yaml alias'"); });
  ApplyYaml(YAML::Load("{recipe: staged}"), new_key, "recipe.yaml", "test 'yaml alias'");
  EXPECT_EQ(OptionsToJson(old_key), OptionsToJson(new_key));
  EXPECT_EQ(old_key.recipe, RefineRecipe::kStaged);
  EXPECT_NE(log.find("warning: alias.yaml:1: test 'yaml alias': 'staged: true' is deprecated; "
                     "write 'recipe: staged'"),
            std::string::npos)
      << log;

  TempDir dir("options");
  const std::string path = WritePipeline(dir, "  - refine: {}\n");
  nlohmann::json set_old;
  const std::string set_log =
      LogOf([&] { set_old = RefineOptionsWith(path, {"refine.basin_first=true"}); });
  EXPECT_EQ(set_old, RefineOptionsWith(path, {"refine.recipe=basin_first"}));
  EXPECT_EQ(set_old["recipe"], "basin_first");
  EXPECT_FALSE(set_old.contains("basin_first"));
  EXPECT_NE(set_log.find("'basin_first: true' is deprecated; write 'recipe: basin_first'"),
            std::string::npos)
      << set_log;

  std::unique_ptr<Stage> refine = CreateStage("refine");
  CLI::App app;
  refine->BindCli(&app);
  app.parse("--staged true", false);
  refine->Configure(refine->CliOptions(), "command line");
  EXPECT_EQ(refine->OptionsJson()["recipe"], "staged");

  // false turns off only the recipe it names, as the boolean did.
  EXPECT_EQ(RefineOptionsWith(path, {"refine.preset=auto", "refine.staged=false"})["recipe"],
            "basin_first");
  EXPECT_EQ(RefineOptionsWith(path, {"refine.preset=room-staged", "refine.staged=false"})["recipe"],
            "single");
}

TEST(PipelineOptionsTest, TwoRecipesAtOnceAreRefused) {
  std::unique_ptr<Stage> refine = CreateStage("refine");
  std::string message = InputErrorOf(
      [&] { refine->Configure(YAML::Load("{staged: true, basin_first: true}"), "p.yaml"); });
  EXPECT_NE(message.find("p.yaml:1: stage 'refine': 'basin_first: true'"), std::string::npos)
      << message;
  EXPECT_NE(message.find("conflicts with recipe 'staged'"), std::string::npos) << message;
  // The auto preset's recipe is basin_first: staged on top of it was refused before, and is.
  message = InputErrorOf(
      [&] { refine->Configure(YAML::Load("{preset: auto, staged: true}"), "p.yaml"); });
  EXPECT_NE(message.find("conflicts with recipe 'basin_first'"), std::string::npos) << message;
}

TEST(PipelineOptionsTest, AnUnknownRecipeNamesTheFileLineAndTheValidValues) {
  TempDir dir("options");
  const std::string path = WritePipeline(dir, "  - refine: {recipe: basin_frist}\n");
  const std::string message = InputErrorOf([&] { LoadPipeline(path); });
  EXPECT_NE(message.find(path + ":4: stage 'refine': option 'recipe' must be one of: single, "
                                "staged, basin_first, got \"basin_frist\" (did you mean "
                                "'basin_first'?)"),
            std::string::npos)
      << message;
  PipelineSpec spec = LoadPipeline(WritePipeline(dir, "  - refine: {}\n"));
  const std::string set = InputErrorOf([&] { ApplyOverride(&spec, "refine.solver=ceress"); });
  EXPECT_EQ(set.rfind("--set refine.solver: ", 0), 0u) << set;
  EXPECT_NE(set.find("one of: auto, ceres, ray_time_lm, got \"ceress\" (did you mean 'ceres'?)"),
            std::string::npos)
      << set;
}

// An enumeration is its name in JSON (provenance, content hashes, summaries), as the text options
// it replaced were, and reads back from it.
TEST(PipelineOptionsTest, EnumerationsRoundTripThroughJsonAsTheirNames) {
  RefineOptions options;
  options.recipe = RefineRecipe::kBasinFirst;
  options.solver = RefineSolver::kRayTimeLm;
  options.parameterization = RayTimeParameterization::kAnchored;
  options.ray_time_init = RayTimeInitMode::kConstant;
  options.intrinsics_sharing = IntrinsicsSharing::kShared;
  const nlohmann::json json = OptionsToJson(options);
  EXPECT_EQ(json["recipe"], "basin_first");
  EXPECT_EQ(json["solver"], "ray_time_lm");
  EXPECT_EQ(json["parameterization"], "anchored");
  EXPECT_EQ(json["ray_time_init"], "constant");
  EXPECT_EQ(json["intrinsics_sharing"], "shared");
  RefineOptions read;
  OptionsFromJson(json, read);
  EXPECT_EQ(OptionsToJson(read), json);
  RefineOptions defaults;
  EXPECT_EQ(OptionsToJson(defaults)["solver"], "auto");

  GncStageSummary stage;
  stage.termination = GncTermination::kFailure;
  const nlohmann::json stage_json = stage;
  EXPECT_EQ(stage_json["termination"], "FAILURE");
  EXPECT_EQ(stage_json.get<GncStageSummary>().termination, GncTermination::kFailure);
  EXPECT_THROW(nlohmann::json("CONVERGED").get<GncTermination>(), InputError);
}

}  // namespace
}  // namespace raytime
